"""One contract, run against every backend, over the mock loom in its own process."""

from __future__ import annotations

import asyncio
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
from simulator_hw.control import request
from tests.fieldbus.conftest import Mock, client_config, start_mock

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
    def test_shifts_move_the_cases_as_the_twin_predicts(self, mock, backend):
        twin = Twin(client_config(backend, mock.ports).machine, FILL)
        moves = [("row", 1, 1), ("col", 1, -1), ("row", 2, -1), ("col", 3, 1)]

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

    def test_a_case_pushed_off_the_matrix_is_a_jam(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await bus.execute([stroke(bus, "row1", 1)])  # cols 1, 2 -> 2, 3
            with pytest.raises(DriveFault) as err:
                await bus.execute([stroke(bus, "row1", 1)])  # col 3 would leave
            assert err.value.code == FAULT_JAM and err.value.axis.name == "row1"
            await bus.reset_faults()
            await bus.execute([stroke(bus, "row1", -1)])

        run(with_bus(mock, backend, body))

    @pytest.mark.parametrize(
        ("kind", "code"), [("stall", FAULT_STALL), ("drive", FAULT_DRIVE),
                           ("wrong_position", FAULT_POSITION)],
    )  # fmt: skip
    def test_injected_axis_faults_are_drive_faults(self, slow_mock, backend, kind, code):
        async def body(bus: Fieldbus) -> None:
            await control(slow_mock, {"cmd": "fault", "kind": kind, "axis": "col2"})
            with pytest.raises(DriveFault) as err:
                await bus.execute([stroke(bus, "col2", 1)])
            assert err.value.code == code and err.value.axis.name == "col2"

        run(with_bus(slow_mock, backend, body))

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

    def test_a_mute_loom_is_a_timeout_or_a_lost_node(self, mock, backend):
        async def body(bus: Fieldbus) -> None:
            await control(mock, {"cmd": "fault", "kind": "mute"})
            with pytest.raises((FieldbusTimeout, FieldbusConnectionError)):
                await bus.execute([stroke(bus, "row1", 1)])
            await control(mock, {"cmd": "clear"})

        run(with_bus(mock, backend, body))

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
