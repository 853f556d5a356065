"""The daemon's log under attack: what a client can repeat at will stays a line a minute."""

from __future__ import annotations

import contextlib
import logging
import socket
import time

import pytest
from websockets.exceptions import InvalidStatus
from websockets.sync.client import connect

from bwsd.logs import FirstLine
from tests.test_daemon import Served, rig
from tests.timing import scaled

__all__ = ["rig"]


@pytest.mark.slow
def test_garbage_on_the_plc_port_and_refused_logins_are_summarised(rig):
    """Garbage on the PLC port logged about 200 B per 13-byte frame; each refused WebSocket
    login wrote an ERROR line."""
    config, state, token, _ = rig
    served = Served(config, state, token)
    try:
        urls = served.urls
        plc_port = int(urls["plc"].rsplit(":", 1)[1])
        time.sleep(scaled(0.5))  # the start-up's lines are written
        before = served.log.stat().st_size
        for number in range(100):
            with socket.create_connection(("127.0.0.1", plc_port), timeout=5) as sock:
                frame = bytes([0, number, 0, 0, 0, 7, 1, 0x99]) + bytes(5)  # function 0x99
                sock.sendall(frame if number % 2 else b"garbage-frame")
                sock.settimeout(0.2)
                with contextlib.suppress(TimeoutError):
                    sock.recv(64)
        ws = urls["api"].replace("http://", "ws://") + "/api/v1/events"
        wrong = {"Authorization": "Bearer " + "x" * 43}
        for _ in range(20):
            with contextlib.suppress(InvalidStatus):
                connect(ws, additional_headers=wrong, open_timeout=5).close()
        time.sleep(scaled(0.5))  # the refusals' lines are written
        state_now = served.state()  # the daemon is fine
        assert state_now["name"] == "Stopped"
    finally:
        served.stop()
    added = served.log.read_text()[before:]
    lines = added.splitlines()
    assert len(added) < 1500, added
    assert not [line for line in lines if " ERROR " in line and "refused" in line], added
    assert sum("refused an event stream" in line for line in lines) == 1, added


def test_a_library_record_of_one_kind_is_logged_once_a_minute_with_a_count():
    records: list[str] = []

    class Keep(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            records.append(record.getMessage())

    handler = Keep()
    quiet = FirstLine(every=0.2)
    handler.addFilter(quiet)
    logger = logging.getLogger("pymodbus.logging.test")
    logger.addHandler(handler)
    logger.propagate = False
    try:
        for n in range(50):
            logger.error("Invalid Modbus protocol id: %d\nframe: %s", n, "00" * 100)
        logger.error("Another kind\nmore")
        time.sleep(0.25)
        logger.error("Invalid Modbus protocol id: 7")
        logging.getLogger("bwsd.test").addHandler(handler)
        logging.getLogger("bwsd.test").error("ours, always\nwhole")
    finally:
        logger.removeHandler(handler)
        logging.getLogger("bwsd.test").removeHandler(handler)
    assert records == [
        "Invalid Modbus protocol id: 0",
        "Another kind",
        "Invalid Modbus protocol id: 7 (and 49 more like it in the last 0 s)",
        "ours, always\nwhole",
    ]
