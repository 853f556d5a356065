"""The stroke counter each axis reports, the same on both buses."""

from __future__ import annotations

import pytest

from bwsd.fieldbus import AxisMove, DriveFault, Fieldbus
from bwsd.fieldbus.axes import axis_by_name
from tests.fieldbus.test_backends import run, stroke, with_bus

pytestmark = pytest.mark.slow  # every test here is in the slow tier


@pytest.fixture(params=["modbus", "canopen"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_completed_set_points_count_and_homing_keeps_the_count(mock, backend):
    async def body(bus: Fieldbus) -> None:
        insert = axis_by_name(bus.machine, "weft_insert").index
        row1 = axis_by_name(bus.machine, "row1").index
        assert (await bus.state()).axes[insert].strokes == 0
        await bus.execute([AxisMove(insert, 20_000)])
        state = await bus.execute([AxisMove(insert, 20_000)])
        assert state.axes[insert].strokes == 2 and bus.known(insert).strokes == 2
        state = await bus.home()
        assert (state.axes[insert].done_seq, state.axes[insert].strokes) == (0, 2)
        await bus.execute([stroke(bus, "row1", 1)])
        with pytest.raises(DriveFault):  # a jam: the stroke never ran, it does not count
            await bus.execute([stroke(bus, "row1", 1)])
        assert (await bus.state()).axes[row1].strokes == 1

    run(with_bus(mock, backend, body))
