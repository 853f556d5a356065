"""One owner of the bus: the daemon's lock in its state folder and the claim on the loom."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from bwsd.fieldbus import open_bus
from bwsd.fieldbus.base import BusHeld, owner_id
from bwsd.fieldbus.owner import LOCK_NAME, BusLock, StateFolderError, holder, refuse_if_held
from tests.fieldbus.test_backends import run, stroke
from tests.support.fieldbus import client_config


def test_the_lock_names_its_holder_and_is_free_once_released(tmp_path: Path):
    config = tmp_path / "loom.toml"
    config.write_text("")
    assert holder(tmp_path) is None
    lock = BusLock.take(tmp_path, str(config))
    found = holder(tmp_path)
    assert found is not None and found.pid == os.getpid() and found.config == str(config)
    with pytest.raises(
        BusHeld,
        match=rf"held by bwsd serve \(pid {os.getpid()}, config "
        rf"{config}, since",
    ):
        BusLock.take(tmp_path, str(config))
    with pytest.raises(BusHeld, match=f"pid {os.getpid()}.*stop it, or command the machine"):
        refuse_if_held(tmp_path)
    lock.release()
    assert holder(tmp_path) is None and (tmp_path / LOCK_NAME).exists()
    refuse_if_held(tmp_path)  # free: no error
    BusLock.take(tmp_path, str(config)).release()


def test_a_missing_state_folder_holds_nothing(tmp_path: Path):
    assert holder(tmp_path / "none") is None


@pytest.mark.slow
def test_a_second_client_cannot_move_while_the_first_holds_the_loom(mock, backend):
    """The loom's own check: it works whatever state folder the second client uses."""

    async def scenario() -> None:
        first = open_bus(client_config(backend, mock.ports))
        second = open_bus(client_config(backend, mock.ports))
        first.holds = True
        second.owner_id = owner_id("another client")  # one process: ids told apart by hand
        await first.connect()
        await second.connect()

        try:
            held = rf"held by another client: pid {os.getpid()} \(claim id {first.owner_id:08x};"
            with pytest.raises(BusHeld, match=held + ".*nothing was moved"):
                await second.execute([stroke(second, "row1", 1)])
            with pytest.raises(BusHeld):
                await second.reset_faults()
            assert (await second.state()).occupancy[1].tolist() == [False, True, True, False]
            await first.close()  # lets the claim go: the second moves at once
            state = await second.execute([stroke(second, "row1", 1)])
            assert state.occupancy[1].tolist() == [False, False, True, True]
            first = open_bus(client_config(backend, mock.ports))
            with pytest.raises(BusHeld):  # now the second holds it
                await first.execute([stroke(first, "row1", -1)])
        finally:
            await first.close()
            await second.close()

    run(scenario())


@pytest.fixture(params=["modbus", "canopen"])
def backend(request: pytest.FixtureRequest) -> str:
    return str(request.param)


def test_a_full_disk_is_a_clear_error_naming_the_lock_not_a_crash(tmp_path: Path):
    (tmp_path / LOCK_NAME).symlink_to("/dev/full")  # every write: "No space left on device"
    with pytest.raises(StateFolderError, match=r"bus.lock: cannot write who holds the bus: "):
        BusLock.take(tmp_path, "loom.toml")
    assert holder(tmp_path) is None  # nothing is held
