"""From a predicted instruction to the actuators' set-points, and back to a verdict (pure).

The controller asks the twin for a prediction, refuses it here if it breaks a configured
limit, turns it into axis set-points (in steps: a weft first places and turns the
inserter, then inserts), and after the move compares what the machine reports with what
was predicted.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bwsd.errors import BwsdError
from bwsd.fieldbus.axes import (
    MDEG_PER_DEG,
    UM_PER_MM,
    axis_by_name,
    machine_axes,
    shift_stroke_um,
)
from bwsd.fieldbus.base import AxisMove, MachineState
from bwsd.twin import Machine, Prediction, Shift, TakeUp, Weft
from bwsd.twin.instructions import Instruction
from bwsd.twin.machine import WEFT_AXES


class RefusedMove(BwsdError):
    """The prediction breaks a limit: the move must not run (PackML Abort with this reason)."""


class Mismatch(BwsdError):
    """The machine's read-back differs from the prediction (PackML Hold with this reason)."""


@dataclass(frozen=True)
class Limits:
    """Validation limits of the ``[controller]`` table (0 disables a limit)."""

    max_contacts: int = 0  # contacts one instruction may make
    tensioner_stroke: float = 0.0  # mm a warp's path may lengthen or shorten in one move


def check_limits(prediction: Prediction, limits: Limits) -> None:
    """Refuse a prediction that breaks a limit, naming it."""
    n = len(prediction.contacts)
    if limits.max_contacts and n > limits.max_contacts:
        raise RefusedMove(
            f"instruction {prediction.index}: {n} contacts, more than the "
            f"limit of {limits.max_contacts}"
        )
    if limits.tensioner_stroke:
        for yarn, change in sorted(prediction.length_change.items()):
            if abs(change) > limits.tensioner_stroke:
                raise RefusedMove(
                    f"instruction {prediction.index}: yarn {yarn} path changes by "
                    f"{change:+.2f} mm, beyond the tensioner's stroke of "
                    f"{limits.tensioner_stroke:g} mm"
                )


def setpoints(
    machine: Machine, instruction: Instruction, takeup_before: float, origin_um: int = 0
) -> list[list[AxisMove]]:
    """The set-points of one instruction, as steps run one after the other.

    A shift is one step (every listed line at once); a take-up one step to the new absolute
    position (``origin_um``: where the take-up stood when the program started); a weft two
    steps: place the inserter (x, y, z on the axes the machine has) and turn it to the
    angle, then an insert stroke of the weft's length.
    """
    if isinstance(instruction, Shift):
        step = []
        for line, k, span in instruction.moves:
            where = "" if span is None else f"[{span[0]}..{span[1]}]"  # a segment's own axis
            axis = axis_by_name(machine, f"{instruction.axis}{line}{where}")
            step.append(AxisMove(axis.index, shift_stroke_um(machine, axis, k)))
        return [step]
    if isinstance(instruction, TakeUp):
        target = origin_um + round((takeup_before + instruction.length) * UM_PER_MM)
        return [[AxisMove(axis_by_name(machine, "takeup").index, target)]]
    assert isinstance(instruction, Weft)
    insert = axis_by_name(machine, "weft_insert").index
    stroke = round(instruction.length * UM_PER_MM)
    return [placing(machine, instruction), [AxisMove(insert, stroke)]]


def placing(machine: Machine, weft: Weft) -> list[AxisMove]:
    """The set-points that place the inserter for ``weft``: x and y in the guide plane and
    z above the fell (absolute um, on the axes the machine has), the angle (absolute mdeg)."""
    moves = [
        AxisMove(axis_by_name(machine, f"weft_{name}").index, round(value * UM_PER_MM))
        for name, value in zip(WEFT_AXES, (weft.x, weft.y, weft.z), strict=True)
        if name in machine.weft_axes
    ]
    angle = axis_by_name(machine, "weft_angle").index
    return [*moves, AxisMove(angle, round(weft.angle * MDEG_PER_DEG))]


def misplaced(machine: Machine, weft: Weft, state: MachineState, tolerance: int) -> str:
    """Where the inserter's read-back differs from ``weft``'s place ("" where it does not)."""
    off = [
        f"{machine_axes(machine)[m.axis].name} at {state.axes[m.axis].position}, the weft's "
        f"{m.target}"
        for m in placing(machine, weft)
        if abs(state.axes[m.axis].position - m.target) > tolerance
    ]
    return "; ".join(off)


def verify(prediction: Prediction, state: MachineState, takeup_um: int, tolerance: int) -> None:
    """Compare the machine's read-back with the prediction; Mismatch names the difference."""
    expected = prediction.occupancy >= 0
    if state.occupancy.shape != expected.shape:
        raise Mismatch(
            f"instruction {prediction.index}: the occupancy grid has shape "
            f"{state.occupancy.shape}, the machine {expected.shape}"
        )
    wrong = np.argwhere(state.occupancy != expected)
    if len(wrong):
        cells = ", ".join(f"({r}, {c})" for r, c in wrong[:5].tolist())
        raise Mismatch(
            f"instruction {prediction.index}: occupancy differs from the prediction at {cells}"
        )
    want = round(prediction.takeup * UM_PER_MM)
    if abs(takeup_um - want) > tolerance:
        raise Mismatch(
            f"instruction {prediction.index}: take-up at {takeup_um} um, predicted {want} um"
        )
