"""The axes and their wire numbering: one more shift axis per declared segment, then the weft
inserter's positioning axes, at the end."""

from __future__ import annotations

import dataclasses

import pytest

from bwsd.config import parse_config
from bwsd.errors import ConfigError
from bwsd.fieldbus.axes import Axis, axis_by_name, machine_axes, moved_cells
from bwsd.fieldbus.modbus import MAX_AXES, ModbusBus, axis_shape, map_problem
from bwsd.twin.machine import Machine, Segment

PLAIN = Machine(rows=8, cols=8, pitch_x=10, pitch_y=12, d_mat=100, c_mat=0.5)
SEGMENTED = Machine(
    rows=8,
    cols=8,
    pitch_x=10,
    pitch_y=12,
    d_mat=100,
    c_mat=0.5,
    segments=(Segment("row", 3, 0, 3), Segment("col", 3, 0, 3), Segment("row", 3, 5, 7)),
)


def test_segment_axes_follow_the_take_up_in_the_order_declared():
    plain, axes = machine_axes(PLAIN), machine_axes(SEGMENTED)
    assert axes[:19] == plain[:19]  # rows, cols, weft and take-up keep their numbers
    names = ["weft_angle", "weft_insert", "takeup", "weft_x", "weft_y", "weft_z"]
    assert [a.name for a in plain[16:]] == names
    assert axes[19:22] == (
        Axis(19, "row3[0..3]", "row", 3, (0, 3)),
        Axis(20, "col3[0..3]", "col", 3, (0, 3)),
        Axis(21, "row3[5..7]", "row", 3, (5, 7)),
    )
    assert all(a.relative for a in axes[19:22])  # strokes, home at rest
    assert [a.index for a in axes] == list(range(len(axes)))


def test_the_weft_positioning_axes_come_last_and_only_those_the_machine_has():
    axes = machine_axes(SEGMENTED)
    weft = [
        Axis(22, "weft_x", "weft_x"),
        Axis(23, "weft_y", "weft_y"),
        Axis(24, "weft_z", "weft_z"),
    ]
    assert axes[22:] == tuple(weft)
    assert not any(a.relative for a in axes[22:])  # absolute um
    without = machine_axes(dataclasses.replace(SEGMENTED, weft_axes=()))
    assert without == axes[:22]  # a loom without them keeps every number it had
    only_z = machine_axes(dataclasses.replace(SEGMENTED, weft_axes=("z",)))
    assert only_z[22:] == (Axis(22, "weft_z", "weft_z"),)
    turned = Machine(2, 2, 1, 1, 10, 0.5, weft_axes=("z", "x"))
    assert [a.name for a in machine_axes(turned)[-2:]] == ["weft_x", "weft_z"]  # wire order


def test_every_segment_axis_is_found_by_the_name_plan_gives_it():
    for seg in SEGMENTED.segments:
        axis = axis_by_name(SEGMENTED, f"{seg.axis}{seg.line}[{seg.lo}..{seg.hi}]")
        assert (axis.kind, axis.line, axis.span) == (seg.axis, seg.line, (seg.lo, seg.hi))
    assert axis_by_name(SEGMENTED, "row3").span is None  # the whole row is its own axis


def test_an_unknown_axis_names_the_rows_cols_and_segments():
    with pytest.raises(
        ValueError,
        match=r"no axis 'row3\[0\.\.4\]' \(rows 0\.\.7, cols 0\.\.7, "
        r"segments: row3\[0\.\.3\], col3\[0\.\.3\], row3\[5\.\.7\]\)",
    ):
        axis_by_name(SEGMENTED, "row3[0..4]")
    with pytest.raises(ValueError, match=r"segments: none declared in \[machine\] segments"):
        axis_by_name(PLAIN, "row3[0..3]")


def test_the_cells_a_shift_axis_moves_and_its_modbus_shape():
    row3, col2 = axis_by_name(SEGMENTED, "row3"), axis_by_name(SEGMENTED, "col2")
    segment = axis_by_name(SEGMENTED, "col3[0..3]")
    assert [moved_cells(SEGMENTED, a) for a in (row3, col2, segment)] == [(0, 7), (0, 7), (0, 3)]
    assert axis_shape(SEGMENTED, row3) == [1, 3, 0, 7]
    assert axis_shape(SEGMENTED, segment) == [2, 3, 0, 3]
    assert axis_shape(SEGMENTED, axis_by_name(SEGMENTED, "takeup")) == [0, 0, 0, 0]


def many_segments(rows: int, cols: int, per_row: int) -> list[str]:
    return [f"ROW {r}[{2 * j}..{2 * j + 1}]" for r in range(rows) for j in range(per_row)]


def test_a_machine_with_more_axes_than_modbus_blocks_is_refused_when_the_bus_is_built():
    machine = {"rows": 100, "cols": 100, "pitch_x": 1, "pitch_y": 1, "d_mat": 10, "c_mat": 0.5}
    fits = parse_config({"machine": {**machine, "segments": many_segments(100, 100, 39)[:3883]}})
    assert len(machine_axes(fits.machine)) == MAX_AXES == 4089 and map_problem(fits.machine) == ""
    ModbusBus.from_config(fits)  # the last block ends at register 65535
    extra = Segment("row", 99, 50, 51)  # a config with it is refused at load (test_config)
    over = dataclasses.replace(
        fits, machine=dataclasses.replace(fits.machine, segments=(*fits.machine.segments, extra))
    )
    assert "at most 4089 axes, the machine has 4090" in map_problem(over.machine)
    with pytest.raises(
        ConfigError,
        match=r"\[machine\.segments\]: the Modbus map addresses at "
        r"most 4089 axes, the machine has 4090 \(100 rows, 100 cols, 6 weft and "
        r"take-up axes, 3884 segments\)",
    ):
        ModbusBus.from_config(over)


def test_the_canopen_node_ids_count_the_segments():
    machine = {"rows": 20, "cols": 20, "pitch_x": 1, "pitch_y": 1, "d_mat": 10, "c_mat": 0.5}
    bus = {"backend": "canopen", "canopen": {"node_base": 1, "io_node": 127}}

    def config(segments: int) -> None:
        parse_config(
            {
                "machine": {**machine, "segments": many_segments(20, 20, 10)[:segments]},
                "fieldbus": bus,
            }
        )

    config(80)  # 20 + 20 + 3 + 80 + 3 = 126 drives: nodes 1..126
    with pytest.raises(
        ConfigError,
        match=r"\[fieldbus\.canopen\.io_node\]: collides with the "
        r"drives' node ids 1\.\.127",
    ):
        config(81)
    with pytest.raises(
        ConfigError,
        match=r"\[fieldbus\.canopen\.node_base\]: 128 axes \(82 of "
        r"them segments\) from node 1 pass node id 127",
    ):
        config(82)
