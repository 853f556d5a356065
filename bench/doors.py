"""Benchmark of the API's doors under hostile clients: prints the table of docs/benchmarks.md.

    python bench/doors.py [--uploads 50] [--chunk 1048576]

`bwsd serve` and the mock loom run in their own processes on loopback (the 24x24 machine,
program loaded, idle). Measured, in the same run:

- the daemon's resident memory after ``--uploads`` clients (one loopback address each)
  open a chunked upload of `POST /api/v1/programs`, send ``--chunk`` bytes of it and go
  idle: without a token (the attack), and with an operator token (the baseline: a body the
  daemon must read);
- how long a refused upload holds its connection;
- `GET /api/v1/state` latency on one kept-alive connection (baseline) and while the
  uploads are held.
"""

from __future__ import annotations

import argparse
import socket
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from daemon import braid_24x24, serving  # noqa: E402

from tests.test_daemon import Served  # noqa: E402


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def address(served: Served) -> tuple[str, int]:
    host, port = served.urls["api"].removeprefix("http://").rsplit(":", 1)
    return host, int(port)


def upload(
    where: tuple[str, int], token: str | None, chunk: int, client: int
) -> tuple[socket.socket, float]:
    """Open a chunked upload from 127.0.1.``client``, send ``chunk`` bytes of it; (the
    socket, seconds until the server closed it, or inf while it stays open)."""
    sock = socket.create_connection(where, timeout=10, source_address=(f"127.0.1.{client}", 0))
    auth = f"Authorization: Bearer {token}\r\n" if token else ""
    head = (
        "POST /api/v1/programs HTTP/1.1\r\nHost: 127.0.0.1\r\n"
        f"{auth}Content-Type: application/json\r\nTransfer-Encoding: chunked\r\n\r\n"
    ).encode()
    start = time.perf_counter()
    try:
        sock.sendall(head + f"{chunk:x}\r\n".encode() + b"x" * chunk + b"\r\n")
    except OSError:
        return sock, time.perf_counter() - start
    sock.settimeout(0.5)
    try:
        while sock.recv(65536):
            pass
    except TimeoutError:
        return sock, float("inf")
    except OSError:
        pass  # reset: the server closed it with the body unread
    return sock, time.perf_counter() - start


def state_latency(where: tuple[str, int], token: str, n: int) -> list[float]:
    request = (
        f"GET /api/v1/state HTTP/1.1\r\nHost: 127.0.0.1\r\nAuthorization: Bearer {token}\r\n\r\n"
    ).encode()
    times = []
    with socket.create_connection(where, timeout=10) as sock:
        sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        for _ in range(n):
            start = time.perf_counter()
            sock.sendall(request)
            data = b""
            while b"\r\n\r\n" not in data:
                data += sock.recv(65536)
            head, _, body = data.partition(b"\r\n\r\n")
            length = int(head.lower().split(b"content-length:")[1].split(b"\r\n")[0])
            while len(body) < length:
                body += sock.recv(65536)
            times.append(time.perf_counter() - start)
    return times


def held(served: Served, token: str | None, uploads: int, chunk: int) -> tuple[float, float, int]:
    """(RSS growth MB, median seconds until closed, connections still open)."""
    where = address(served)
    before = rss_mb(served.proc.pid)
    pairs = [upload(where, token, chunk, 1 + i) for i in range(uploads)]
    time.sleep(1.0)
    grown = rss_mb(served.proc.pid) - before
    closed = [s for _, s in pairs if s != float("inf")]
    for sock, _ in pairs:
        sock.close()
    time.sleep(12.0)  # past the body deadline: every held body is dropped
    return grown, statistics.median(closed) if closed else float("inf"), uploads - len(closed)


def ms(values: list[float]) -> str:
    a = 1e3 * np.array(values)
    p50, p99 = np.percentile(a, [50, 99])
    return f"{p50:.2f} | {p99:.2f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--uploads", type=int, default=50)
    parser.add_argument("--chunk", type=int, default=1 << 20)
    args = parser.parse_args()
    program = braid_24x24(10)
    with serving(program) as served:
        token = served.http.headers["authorization"].split()[1]
        served.http.post("/programs", json={"name": "b.bws", "text": program}).raise_for_status()
        where = address(served)
        state_latency(where, token, 200)  # warm up
        idle = state_latency(where, token, 2000)
        start_rss = rss_mb(served.proc.pid)
        rows = []
        for name, who in (("no token (the attack)", None), ("operator token (baseline)", token)):
            grown, closed, still = held(served, who, args.uploads, args.chunk)
            rows.append(
                f"| {name} | {args.uploads} | {args.chunk >> 10} | {grown:.1f} | "
                f"{closed * 1e3:.1f} | {still} |"
            )
        pairs = [upload(where, None, args.chunk, 1 + i) for i in range(args.uploads)]
        during = state_latency(where, token, 2000)
        for sock, _ in pairs:
            sock.close()
        end_rss = rss_mb(served.proc.pid)
    print(f"daemon RSS at start of the measure: {start_rss:.1f} MB; at the end: {end_rss:.1f} MB")
    print()
    print(
        "| uploads held | n | KiB sent each | RSS growth MB | median ms until closed | "
        "still open after 1 s |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    print("\n".join(rows))
    print()
    print("| GET /api/v1/state, one connection | n | p50 ms | p99 ms |")
    print("|---|---:|---:|---:|")
    print(f"| idle (baseline) | {len(idle)} | {ms(idle)} |")
    print(f"| after {args.uploads} unauthenticated uploads | {len(during)} | {ms(during)} |")
    ratio = np.percentile(during, 99) / np.percentile(idle, 99)
    print(f"\nduring over idle at p99: {ratio:.2f}x")


if __name__ == "__main__":
    main()
