"""Types of the relaxation's compiled steps (bwsd/relax/csrc/step.c)."""

from typing import Any as Buffer

def steps(
    pos: Buffer,
    a: Buffer,
    b: Buffer,
    tension: Buffer,
    free: Buffer,
    pi: Buffer,
    pj: Buffer,
    room: Buffer,
    energies: Buffer,
    d: float,
    target: float,
    limit: float,
    stall: float,
    relist: float,
    passes: int,
    pull: bool,
    alpha: float,
    /,
) -> tuple[int, int, float, float, int, float]: ...
