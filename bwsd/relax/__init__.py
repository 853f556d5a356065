"""The relaxed preform: the twin's skeleton under yarn tension, tight, without
interpenetration, its topology kept (docs/relax.md). Beside the twin, never in the control
path: the twin's contacts decide every refusal.

The names below live in ``bwsd.relax.relaxed`` and are imported on first use, so that
``bwsd relax --help`` (which imports ``bwsd.relax.cli``) loads neither numpy nor scipy.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from bwsd.relax.relaxed import Options, Relaxed, crimp, relax

__all__ = ["Options", "Relaxed", "crimp", "relax"]


def __getattr__(name: str) -> Any:
    if name in __all__:
        from bwsd.relax import relaxed

        return getattr(relaxed, name)
    raise AttributeError(f"module 'bwsd.relax' has no attribute {name!r}")
