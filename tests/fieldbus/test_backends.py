"""One contract, run against every backend, over the mock loom in its own process."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Awaitable, Callable
from typing import Any

import numpy as np
import pytest

from bwsd.fieldbus import (
    AxisMove,
    DriveFault,
    EStopError,
    Fieldbus,
    FieldbusConnectionError,
    FieldbusError,
    FieldbusTimeout,
    open_bus,
)
from bwsd.fieldbus.axes import axis_by_name, shift_stroke_um
from bwsd.fieldbus.base import FAULT_DRIVE, FAULT_JAM, FAULT_POSITION, FAULT_STALL
from bwsd.twin import Shift, Twin
from bwsd.twin.instructions import Axis
from simulator_hw.control import request
from tests.support.fieldbus import MACHINE, Mock, client_config, start_mock, wants_canopen

FILL = [(1, 1), (1, 2), (2, 1), (2, 2)]


def run(scenario: Awaitable[Any]) -> Any:
    return asyncio.run(asyncio.wait_for(scenario, 60))


async def control(mock: Mock, message: dict[str, Any]) -> dict[str, Any]:
    answer = await request("127.0.0.1", mock.ports["control"], message)
    assert answer["ok"], answer
    return answer


async def with_bus(mock: Mock, backend: str, body: Callable[[Fieldbus], Awaitable[Any]]) -> Any:
    bus = open_bus(client_config(backend, mock.ports))
    await bus.connect()
    try:
        return await body(bus)
    finally:
        await bus.close()


def stroke(bus: Fieldbus, name: str, cells: int) -> AxisMove:
    axis = axis_by_name(bus.machine, name)
    return AxisMove(axis.index, shift_stroke_um(bus.machine, axis, cells))


@pytest.fixture(params=["modbus", "canopen"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


class TestBackendContract:
    @pytest.mark.slow
    def test_shifts_move_the_cases_as_the_twin_predicts(self, mock, backend):
        twin = Twin(client_config(backend, mock.ports).machine, FILL)
        moves: list[tuple[Axis, int, int]] = [
            ("row", 1, 1),
            ("col", 1, -1),
            ("row", 2, -1),
            ("col", 3, 1),
        ]

        async def body(bus: Fieldbus) -> None:
            state = await bus.state()
            assert np.array_equal(state.occupancy, twin.occupancy >= 0)
            for axis, line, k in moves:
                twin.apply(Shift(axis, ((line, k),)))
                state = await bus.execute([stroke(bus, f"{axis}{line}", k)])
                assert np.array_equal(state.occupancy, twin.occupancy >= 0)
                index = axis_by_name(bus.machine, f"{axis}{line}").index
                assert state.axes[index].position == 0  # home again
                assert state.axes[index].last_stroke == shift_stroke_um(
                    bus.machine, axis_by_name(bus.machine, f"{axis}{line}"), k
                )

        run(with_bus(mock, backend, body))

    @pytest.mark.slow
    def test_absolute_axes_read_back_their_targets(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            takeup = axis_by_name(bus.machine, "takeup").index
            angle = axis_by_name(bus.machine, "weft_angle").index
            insert = axis_by_name(bus.machine, "weft_insert").index
            state = await bus.execute([AxisMove(takeup, 4_000), AxisMove(angle, 45_000)])
            assert (state.axes[takeup].position, state.axes[angle].position) == (4_000, 45_000)
            state = await bus.execute([AxisMove(insert, 60_000)])
            assert state.axes[insert].last_stroke == 60_000 and state.axes[insert].position == 0
            positions = await bus.state()
            assert positions.axes[takeup].position == 4_000

        run(with_bus(mock, backend, body))

    @pytest.mark.slow
    def test_a_case_pushed_off_the_matrix_is_a_jam(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await bus.execute([stroke(bus, "row1", 1)])  # cols 1, 2 -> 2, 3
            with pytest.raises(DriveFault) as err:
                await bus.execute([stroke(bus, "row1", 1)])  # col 3 would leave
            assert err.value.code == FAULT_JAM and err.value.axis.name == "row1"
            await bus.reset_faults()
            await bus.execute([stroke(bus, "row1", -1)])

        run(with_bus(mock, backend, body))

    @pytest.mark.slow
    def test_a_long_stroke_is_read_every_poll_max_not_every_2_ms(self, slow_mock, backend):
        """A stroke out and back (0.2 s at the slow mock loom's 100 mm/s): the reads of
        the wait come at once, after 2 ms, then doubling up to ``poll_max`` (10 ms)."""
        reads = 0

        async def body(bus: Fieldbus) -> None:
            nonlocal reads
            read = bus._read_state

            async def counted(axes: Any = None) -> Any:
                nonlocal reads
                reads += 1
                return await read(axes)

            bus._read_state = counted  # type: ignore[method-assign]
            began = time.monotonic()
            await bus.execute([stroke(bus, "row1", 1)])
            took = time.monotonic() - began
            assert took > 0.1, took  # the stroke did travel
            # At most: the first read, the 3 of the doubling, one every 10 ms after them.
            assert reads <= 4 + math.ceil(took / bus.settings.poll_max) + 1, (reads, took)

        run(with_bus(slow_mock, backend, body))

    @pytest.mark.slow
    @pytest.mark.parametrize(
        ("kind", "code"),
        [("stall", FAULT_STALL), ("drive", FAULT_DRIVE), ("wrong_position", FAULT_POSITION)],
    )
    def test_injected_axis_faults_are_drive_faults(self, slow_mock, backend, kind, code):
        async def body(bus: Fieldbus) -> None:
            await control(slow_mock, {"cmd": "fault", "kind": kind, "axis": "col2"})
            with pytest.raises(DriveFault) as err:
                await bus.execute([stroke(bus, "col2", 1)])
            assert err.value.code == code and err.value.axis.name == "col2"

        run(with_bus(slow_mock, backend, body))

    @pytest.mark.slow
    def test_emergency_stop(self, slow_mock, backend):
        async def body(bus: Fieldbus) -> None:
            await control(slow_mock, {"cmd": "estop", "pressed": True})
            with pytest.raises(EStopError):
                await bus.execute([stroke(bus, "row1", 1)])
            state = await bus.state()
            assert state.estop and not state.axes[1].busy
            await control(slow_mock, {"cmd": "estop", "pressed": False})
            await bus.reset_faults()
            await bus.execute([stroke(bus, "row1", 1)])

        run(with_bus(slow_mock, backend, body))

    @pytest.mark.slow
    def test_rest_waits_for_a_stroke_under_way_and_names_one_that_goes_on(self, slow_mock, backend):
        """A stroke takes 0.2 s out and back (10 mm at 100 mm/s): ``rest`` returns once it
        ended; with less time than it takes, FieldbusTimeout names the axis still moving."""

        async def body(bus: Fieldbus) -> None:
            await bus.move([stroke(bus, "row1", 1)])
            with pytest.raises(FieldbusTimeout, match="axes row1 still move"):
                await bus.rest(timeout=0.0)
            state = await bus.rest()
            assert not any(axis.busy for axis in state.axes)
            assert state.occupancy[1].tolist() == [False, False, True, True]

        run(with_bus(slow_mock, backend, body))

    @pytest.mark.slow
    def test_a_mute_loom_is_a_timeout_or_a_lost_node(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await control(mock, {"cmd": "fault", "kind": "mute"})
            with pytest.raises((FieldbusTimeout, FieldbusConnectionError)):
                await bus.execute([stroke(bus, "row1", 1)])
            await control(mock, {"cmd": "clear"})

        run(with_bus(mock, backend, body))

    @pytest.mark.slow
    def test_a_dropped_connection_is_reported_then_reconnected(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await bus.state()
            await control(mock, {"cmd": "fault", "kind": "drop"})
            await asyncio.sleep(0.2)
            with pytest.raises(FieldbusConnectionError):
                await bus.state()
            await bus.connect()
            state = await bus.execute([stroke(bus, "row1", 1)])
            assert state.occupancy[1].tolist() == [False, False, True, True]

        run(with_bus(mock, backend, body))

    @pytest.mark.slow
    def test_reconnects_after_the_mock_loom_restarts(self, tmp_path, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await bus.state()
            mock.stop()
            with pytest.raises(FieldbusError):
                await bus.state()
            restarted = start_mock(tmp_path, {}, mock.ports)
            try:
                await bus.connect()
                state = await bus.execute([stroke(bus, "col1", 1)])
                assert state.occupancy[:, 1].tolist() == [False, False, True, True]
            finally:
                restarted.stop()

        run(with_bus(mock, backend, body))

    def test_an_unreachable_loom_is_a_connection_error(self, tmp_path, backend):
        closed = {"modbus": 1, "socketcand": 1, "control": 1}  # nothing listens on port 1
        bus = open_bus(client_config(backend, closed, reconnect_attempts=2))
        with pytest.raises(FieldbusConnectionError, match="cannot reach the bus"):
            run(bus.connect())


# A 4 x 5 loom with a segment of row 1 (cells 0..2) and one of column 2 (cells 0..2); each
# line also has a case outside its segment, (1, 4) and (3, 2), that a segment never moves.
SEGMENTED = {**MACHINE, "cols": 5, "segments": ["ROW 1[0..2]", "COL 2[0..2]"]}
SEGMENT_FILL = [(0, 2), (1, 0), (1, 1), (1, 4), (3, 2)]
SEGMENT_PROGRAM = "FILL row=0 col=0\n..X..\nXX..X\n.....\n..X..\nEND\n"


@pytest.fixture
def segment_mock(tmp_path, request) -> Any:
    canopen = wants_canopen(request)
    running = start_mock(tmp_path, {}, machine=SEGMENTED, program=SEGMENT_PROGRAM, canopen=canopen)
    yield running
    running.stop()


async def with_segment_bus(
    mock: Mock, backend: str, body: Callable[[Fieldbus], Awaitable[Any]]
) -> Any:
    bus = open_bus(client_config(backend, mock.ports, machine=SEGMENTED))
    await bus.connect()
    try:
        return await body(bus)
    finally:
        await bus.close()


async def loom_cells(mock: Mock) -> set[tuple[int, int]]:
    occupancy = (await control(mock, {"cmd": "state"}))["occupancy"]
    return {(r, c) for r, row in enumerate(occupancy) for c, v in enumerate(row) if v}


class TestSegmentAxes:
    @pytest.mark.slow
    def test_the_segment_axes_follow_the_take_up_on_the_bus(self, segment_mock, backend):
        async def body(bus: Fieldbus) -> None:
            names = [axis.name for axis in bus.axes]
            assert names[9:] == [
                "weft_angle",
                "weft_insert",
                "takeup",
                "row1[0..2]",
                "col2[0..2]",
                "weft_x",
                "weft_y",
                "weft_z",
            ]
            state = await bus.state()
            assert len(state.axes) == 17 and not any(a.fault for a in state.axes)

        run(with_segment_bus(segment_mock, backend, body))

    @pytest.mark.slow
    def test_a_segment_stroke_moves_only_the_cases_on_the_segment(self, segment_mock, backend):
        twin = Twin(
            client_config(backend, segment_mock.ports, machine=SEGMENTED).machine, SEGMENT_FILL
        )
        strokes: list[tuple[Axis, int, int]] = [
            ("row", 1, 1),
            ("col", 2, 1),
            ("row", 1, -1),
            ("col", 2, -2),
        ]

        async def body(bus: Fieldbus) -> None:
            for kind, line, k in strokes:
                name = f"{kind}{line}[0..2]"
                twin.apply(Shift(kind, ((line, k, (0, 2)),)))
                state = await bus.execute([stroke(bus, name, k)])
                assert np.array_equal(state.occupancy, twin.occupancy >= 0), name
                assert state.occupancy[1, 4] and state.occupancy[3, 2]  # outside: never moved
                axis = axis_by_name(bus.machine, name)
                assert state.axes[axis.index].position == 0
                assert state.axes[axis.index].last_stroke == shift_stroke_um(bus.machine, axis, k)
            assert await loom_cells(segment_mock) == set(SEGMENT_FILL)  # round trip

        run(with_segment_bus(segment_mock, backend, body))

    @pytest.mark.slow
    @pytest.mark.parametrize(
        ("name", "k"),
        [
            ("row1[0..2]", 2),  # (1, 1) would leave the segment for the empty cell (1, 3)
            ("col2[0..2]", 3),  # (0, 2) would leave it for (3, 2), where a case sits
            ("col2[0..2]", -1),
        ],  # (0, 2) would leave the matrix
    )
    def test_a_stroke_off_the_segment_is_a_jam_and_nothing_moves(
        self, segment_mock, backend, name, k
    ):
        async def body(bus: Fieldbus) -> None:
            with pytest.raises(DriveFault) as err:
                await bus.execute([stroke(bus, name, k)])
            assert err.value.code == FAULT_JAM and err.value.axis.name == name
            assert await loom_cells(segment_mock) == set(SEGMENT_FILL)
            await bus.reset_faults()
            state = await bus.execute([stroke(bus, name, 1)])  # a stroke that fits still moves
            assert np.count_nonzero(state.occupancy) == len(SEGMENT_FILL)
            assert set(map(tuple, np.argwhere(state.occupancy).tolist())) != set(SEGMENT_FILL)

        run(with_segment_bus(segment_mock, backend, body))


WIDE = {**MACHINE, "rows": 24, "cols": 4}  # 24 row axes: a shift of every row is 24 set-points
WIDE_FILL = "FILL row=0 col=1\n" + "XX\n" * 24 + "END\n"


@pytest.mark.slow
@pytest.mark.parametrize("when", ["moving", "at rest"])
def test_a_killed_loom_is_seen_at_once_not_after_each_requests_timeout(tmp_path, backend, when):
    """With a 30 s I/O timeout, a loom killed during a 24-line shift (or between moves) is
    seen as lost at once: the request on the wire and every request queued behind it fail
    when the connection closes, instead of waiting out their timeouts one after another."""
    mock = start_mock(
        tmp_path,
        {"stroke_speed": 20.0},
        machine=WIDE,
        program=WIDE_FILL,
        canopen=backend == "canopen",
    )
    config = client_config(backend, mock.ports, machine=WIDE, io_timeout=30.0, timeout=60.0)

    async def body() -> None:
        bus = open_bus(config)
        await bus.connect()
        try:
            moves = [stroke(bus, f"row{r}", 1 if r % 2 else -1) for r in range(24)]
            if when == "moving":
                moving = asyncio.ensure_future(bus.execute(moves))
                await asyncio.sleep(0.2)  # the strokes take 0.5 s out
            mock.proc.kill()
            mock.proc.wait(10)
            with pytest.raises(FieldbusConnectionError) as lost:
                await asyncio.wait_for(moving if when == "moving" else bus.state(), 10)
            assert lost.value.lost
        finally:
            await bus.close()
            mock.stop()

    run(body())
