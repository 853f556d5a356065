"""sd_notify over a real datagram socket, as systemd would receive it."""

from __future__ import annotations

import os
import socket
import uuid

from bwsd.notify import notify, watchdog_interval


def test_messages_reach_a_path_socket(tmp_path):
    path = str(tmp_path / "notify")
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind(path)
        assert notify("READY=1", "STATUS=running", env={"NOTIFY_SOCKET": path})
        assert server.recv(4096) == b"READY=1\nSTATUS=running"


def test_messages_reach_an_abstract_socket():
    name = f"bwsd-test-{uuid.uuid4().hex}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as server:
        server.bind("\0" + name)
        assert notify("WATCHDOG=1", env={"NOTIFY_SOCKET": "@" + name})
        assert server.recv(4096) == b"WATCHDOG=1"


def test_nothing_outside_systemd():
    assert notify("READY=1", env={}) is False
    assert watchdog_interval(env={}) is None


def test_watchdog_interval_is_half_and_for_this_process_only():
    assert watchdog_interval(env={"WATCHDOG_USEC": "10000000"}) == 5.0
    mine = {"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": str(os.getpid())}
    assert watchdog_interval(env=mine) == 2.0
    assert watchdog_interval(env={"WATCHDOG_USEC": "4000000", "WATCHDOG_PID": "1"}) is None
