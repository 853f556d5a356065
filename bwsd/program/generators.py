"""Program generators: pure functions returning a program and the machine it is written for.

Every generator returns a :class:`Generated` whose ``program`` passes ``validate`` on its
``machine`` and brings every case back to its cell at the end of each cycle.
"""

from __future__ import annotations

from collections.abc import Callable

from bwsd.program.braid import braid4, section, twist
from bwsd.program.braidweave import braid_weave
from bwsd.program.render import Generated, config_toml
from bwsd.program.weave import warp_cells, weave_3d, weave_plain

GENERATORS: dict[str, Callable[..., Generated]] = {
    "twist": twist,
    "braid4": braid4,
    "braid-weave": braid_weave,
    "weave-plain": weave_plain,
    "weave-3d": weave_3d,
}

# The shipped examples: file stem -> the generator call that prints them.
EXAMPLES: dict[str, Callable[[], Generated]] = {
    "twist": lambda: twist(turns=4),
    "braid-2x2": lambda: braid4(2, 2, cycles=10, takeup=3.0, diameter=1.5),
    "braid-L": lambda: braid4(cycles=11, shape="L", flange=(2, 6), web=(4, 2)),
    # 8 mm a cycle and a 0.5 mm yarn keep this braid's contacts clear of the guides for
    # 1000 cycles (bench/twin.py)
    "braid-24x24": lambda: braid4(
        24, 24, cycles=10, takeup=8.0, d_mat=300.0, c_mat=0.3, diameter=0.5
    ),
    "weave-plain": lambda: weave_plain(warps=10, cycles=10),
    "weave-U": lambda: weave_3d(5, 6, cycles=10, shape="U", leg=2, base=2),
    # The seed paper's case studies on one machine (docs/paper.md): 5 cycles of the 8-step L
    # rule are the paper's 10 cycles of 4 steps; take-up 6 mm per four steps (less jams),
    # 3 mm per pick.
    "paper-L": lambda: braid4(
        cycles=5,
        shape="L",
        flange=(3, 8),
        web=(7, 3),
        takeup=6.0,
        d_mat=100.0,
        c_mat=0.4,
        diameter=1.0,
    ),
    "paper-U": lambda: weave_3d(
        3, 6, cycles=10, shape="U", leg=2, base=2, takeup=3.0, d_mat=100.0, c_mat=0.4, diameter=1.0
    ),
}

__all__ = [
    "EXAMPLES",
    "GENERATORS",
    "Generated",
    "braid4",
    "braid_weave",
    "config_toml",
    "section",
    "twist",
    "warp_cells",
    "weave_3d",
    "weave_plain",
]
