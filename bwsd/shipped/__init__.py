"""The machine configs and example programs shipped with the package.

They are ``config/`` and ``examples/`` of the source tree, which ``bwsd/shipped/config`` and
``bwsd/shipped/examples`` link to; a wheel carries them here as package data. Found through
``importlib.resources``, so ``bwsd demo`` runs them from any folder, installed or editable.
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path

from bwsd.errors import BwsdError

__all__ = ["DEMO_CONFIG", "DEMO_PROGRAM", "config_file", "example_file"]

DEMO_CONFIG = "loom.toml"  # the 8-carrier braiding machine and its mock loom
DEMO_PROGRAM = "braid-2x2.bws"  # the 8-carrier 4-step braid


def _shipped(folder: str, name: str) -> Path:
    resource = files(__name__) / folder / name
    # Installed packages are plain files (pip unpacks wheels): the path can be handed on.
    if not isinstance(resource, Path) or not resource.is_file():
        raise BwsdError(f"{folder}/{name} is not shipped with this installation of bwsd")
    return resource


def config_file(name: str = DEMO_CONFIG) -> Path:
    """A shipped machine config: ``config_file("braid-24x24.toml")``."""
    return _shipped("config", name)


def example_file(name: str = DEMO_PROGRAM) -> Path:
    """A shipped example program: ``example_file("weave-U.bws")``."""
    return _shipped("examples", name)
