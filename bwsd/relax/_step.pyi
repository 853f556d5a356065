"""Types of the relaxation's compiled step (bwsd/relax/csrc/step.c)."""

from typing import Any as Buffer

def step(
    pos: Buffer,
    out: Buffer,
    a: Buffer,
    b: Buffer,
    tension: Buffer,
    free: Buffer,
    pi: Buffer,
    pj: Buffer,
    room: Buffer,
    d: float,
    alpha: float,
    passes: int,
    /,
) -> tuple[float, float]: ...
