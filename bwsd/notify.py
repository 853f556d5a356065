"""sd_notify: tell systemd the daemon is ready, what it does, that it is alive, that it stops.

The protocol is one datagram of ``KEY=value`` lines to the socket named by
``$NOTIFY_SOCKET`` (a leading ``@`` names the abstract namespace). Outside systemd there is
no such variable and every call does nothing. With ``WatchdogSec=`` systemd sets
``$WATCHDOG_USEC``; the daemon pings at half that interval.
"""

from __future__ import annotations

import os
import socket


def notify(*lines: str, env: dict[str, str] | None = None) -> bool:
    """Send ``lines`` (e.g. "READY=1", "STATUS=running") to systemd; False outside systemd."""
    address = (env if env is not None else os.environ).get("NOTIFY_SOCKET", "")
    if not address:
        return False
    target = "\0" + address[1:] if address.startswith("@") else address
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.connect(target)
        sock.sendall("\n".join(lines).encode())
    return True


def watchdog_interval(env: dict[str, str] | None = None) -> float | None:
    """Seconds between watchdog pings (half of $WATCHDOG_USEC), or None when not asked."""
    values = env if env is not None else os.environ
    usec = values.get("WATCHDOG_USEC", "")
    pid = values.get("WATCHDOG_PID", "")
    if not usec.isdigit() or (pid and pid != str(os.getpid())):
        return None
    return int(usec) / 2e6
