"""The CAN link under the CANopen backend: python-can's socketcand client made to notice a
closed connection, a listener that keeps a receive error, and a quiet shutdown."""

from __future__ import annotations

import contextlib
import logging
import select
import socket
import threading
from collections.abc import Callable

import can
from can.interfaces.socketcand import SocketCanDaemonBus
from canopen import Network


class QuietPartials(logging.Filter):
    """python-can's socketcand client warns whenever one read ends inside a frame, which a
    SYNC's burst of PDOs does all the time: the frame is read whole at the next read."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not record.getMessage().startswith("Got incomplete message")


logging.getLogger(SocketCanDaemonBus.__module__).addFilter(QuietPartials())


class Socketcand(SocketCanDaemonBus):
    """python-can's socketcand client, raising when the server closes the connection.

    python-can 4.6 reads an empty string at the end of the stream and returns no message,
    so its receive thread would spin at full speed on a closed connection.
    """

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        msg, filtered = super()._recv_internal(timeout)  # type: ignore[no-untyped-call]
        sock = getattr(self, "_SocketCanDaemonBus__socket", None)  # its private socket
        if msg is None and isinstance(sock, socket.socket) and at_end(sock):
            raise can.CanOperationError("socketcand closed the connection")
        return msg, filtered


def at_end(sock: socket.socket) -> bool:
    """True when the peer has closed ``sock`` (readable, yet nothing to read)."""
    try:
        readable, _, _ = select.select([sock], [], [], 0)
        return bool(readable) and not sock.recv(1, socket.MSG_PEEK)
    except OSError:
        return True


class LinkWatch(can.Listener):
    """Keeps a receive error of the bus (a lost TCP link) and stops the receive thread."""

    def __init__(self, network: Network) -> None:
        self.network = network
        self.error: Exception | None = None
        self.on_lost: Callable[[Exception], None] | None = None  # told at once (any thread)

    def on_message_received(self, msg: can.Message) -> None:
        pass

    def on_error(self, exc: Exception) -> None:
        self.error = exc
        if self.on_lost is not None:
            self.on_lost(exc)
        notifier = self.network.notifier
        if notifier is not None:
            # a thread cannot join itself; left running, it would spin on the dead socket
            threading.Thread(target=notifier.stop, args=(1.0,), daemon=True).start()


def shutdown(network: Network) -> None:
    """Disconnect; never raises (disconnect re-raises the receive thread's error last)."""
    with contextlib.suppress(Exception):
        network.disconnect()
