"""Benchmark of start-up times: prints the markdown table of docs/benchmarks.md.

    python bench/startup.py [--runs 20] [--serve-runs 5]

Each command runs in a process of its own, the runs interleaved (one of each in turn), so
that a load on the machine weighs on every row alike. The baseline is `python -c pass` by
the same interpreter, measured in the same run; the ratio is a row's median over the
baseline's. `bwsd serve` runs against the mock loom (in a process of its own, on
loopback, every port chosen by the system) until `/healthz` answers 200, and on until it
prints `ready` (every door listening, OPC UA's too), once with OPC UA off and once on;
each mode's first start (a new journal, and with OPC UA a new certificate) is a row of its
own, the runs after it reuse that state folder as a restarted daemon does.
"""

from __future__ import annotations

import argparse
import http.client
import math
import queue
import resource
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import IO

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.api.auth import TokenStore  # noqa: E402
from tests.support.fieldbus import BUS, MACHINE, start_mock, toml  # noqa: E402

BWSD = Path(sys.executable).with_name("bwsd")
PROGRAM = "`bwsd program braid4 --rows 4 --cols 4`"
COMMANDS = {
    "`python -c pass` (baseline)": [sys.executable, "-c", "pass"],
    "`python -c 'import numpy'`": [sys.executable, "-c", "import numpy"],
    "`bwsd --help`": [str(BWSD), "--help"],
    PROGRAM: [str(BWSD), "program", "braid4", "--rows", "4", "--cols", "4"],
}
TARGETS = {"`bwsd --help`": 0.3, PROGRAM: 0.3}
API_LINE = "REST API and the page on "
MODES = (False, True)  # `bwsd serve` with OPC UA off, and on
LIMIT = 120.0  # s: a bound for waiting, never an expected duration


def timed(argv: list[str]) -> tuple[float, float]:
    """(wall, CPU) seconds of ``argv`` from its start to its end (its output dropped; it must
    succeed). CPU time is user plus system, of the process and the children it waited for."""
    used = resource.getrusage(resource.RUSAGE_CHILDREN)
    began = time.perf_counter()
    subprocess.run(argv, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - began
    now = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, now.ru_utime - used.ru_utime + now.ru_stime - used.ru_stime


def _lines(stream: IO[str], into: queue.Queue[tuple[float, str]]) -> None:
    for line in stream:
        into.put((time.perf_counter(), line))


def _healthy(url: str) -> bool:
    host, port = url.removeprefix("http://").rsplit(":", 1)
    conn = http.client.HTTPConnection(host, int(port), timeout=5)
    try:
        conn.request("GET", "/healthz")
        return conn.getresponse().status == 200
    except OSError:
        return False
    finally:
        conn.close()


def _until(
    lines: queue.Queue[tuple[float, str]],
    began: float,
    found: Callable[[str], bool],
    proc: subprocess.Popen[str],
) -> tuple[float, str]:
    while True:
        try:
            at, line = lines.get(timeout=max(0.0, began + LIMIT - time.perf_counter()))
        except queue.Empty:
            raise RuntimeError(f"bwsd serve said nothing for {LIMIT:g} s") from None
        if found(line):
            return at, line
        if proc.poll() is not None and lines.empty():
            raise RuntimeError(f"bwsd serve ended ({proc.returncode}): {line!r}")


def served(config: Path, state: Path) -> tuple[float, float]:
    """(seconds to `/healthz` 200, seconds to `ready`) of one `bwsd serve`, then SIGTERM."""
    began = time.perf_counter()
    proc = subprocess.Popen(
        [str(BWSD), "serve", "--config", str(config), "--state-dir", str(state)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        stdin=subprocess.DEVNULL,
        text=True,
    )
    assert proc.stdout is not None and proc.stderr is not None
    errors: queue.Queue[tuple[float, str]] = queue.Queue()
    out: queue.Queue[tuple[float, str]] = queue.Queue()
    for stream, into in ((proc.stderr, errors), (proc.stdout, out)):
        threading.Thread(target=_lines, args=(stream, into), daemon=True).start()
    try:
        _, line = _until(errors, began, lambda text: API_LINE in text, proc)
        url = line.split(API_LINE, 1)[1].strip()
        while not _healthy(url):
            if time.perf_counter() > began + LIMIT:
                raise RuntimeError(f"/healthz did not answer 200 within {LIMIT:g} s")
            time.sleep(0.002)
        healthy = time.perf_counter() - began
        ready, _ = _until(out, began, lambda text: text.startswith("ready "), proc)
        return healthy, ready - began
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=60)


def p99(values: list[float]) -> float:
    """The 99th percentile by nearest rank (the slowest run when there are 100 or fewer)."""
    ordered = sorted(values)
    return ordered[math.ceil(0.99 * len(ordered)) - 1]


def serve_config(tmp: Path, modbus: int, opcua: bool) -> tuple[Path, Path]:
    """A daemon config on the mock loom, every door on a port the system chooses."""
    name = "opcua-on" if opcua else "opcua-off"
    config = tmp / f"{name}.toml"
    config.write_text(
        toml(
            {
                "machine": MACHINE,
                "fieldbus": {"backend": "modbus", **BUS},
                "fieldbus.modbus": {"port": modbus},
                "api": {"port": 0},
                "plc": {"port": 0},
                "opcua": {"enabled": opcua, "port": 0},
            }
        )
    )
    state = tmp / f"{name}-state"
    state.mkdir()
    TokenStore.load(state / "tokens.json").add("bench", "operator")
    return config, state


def measure(runs: int, serve_runs: int) -> tuple[dict[str, list[float]], dict[str, list[float]]]:
    """Wall times of every row, CPU times of the commands' rows."""
    times: dict[str, list[float]] = {name: [] for name in COMMANDS}
    cpu: dict[str, list[float]] = {name: [] for name in COMMANDS}
    for argv in COMMANDS.values():
        timed(argv)  # warm the file cache
    for _ in range(runs):
        for name, argv in COMMANDS.items():
            wall, used = timed(argv)
            times[name].append(wall)
            cpu[name].append(used)
    with tempfile.TemporaryDirectory() as where:
        tmp = Path(where)
        mock = start_mock(tmp, {})
        try:
            modes = {opcua: serve_config(tmp, mock.ports["modbus"], opcua) for opcua in MODES}
            first = {opcua: served(*modes[opcua]) for opcua in MODES}
            again: dict[bool, list[tuple[float, float]]] = {opcua: [] for opcua in MODES}
            for _ in range(serve_runs):  # the modes' restarts interleaved, as the commands'
                for opcua in MODES:
                    again[opcua].append(served(*modes[opcua]))
        finally:
            mock.stop()
    for opcua in MODES:
        label = "OPC UA on" if opcua else "OPC UA off"
        times[f"`bwsd serve`, {label}, first start: to `/healthz` 200"] = [first[opcua][0]]
        times[f"`bwsd serve`, {label}, first start: to `ready`"] = [first[opcua][1]]
        times[f"`bwsd serve`, {label}: to `/healthz` 200"] = [h for h, _ in again[opcua]]
        times[f"`bwsd serve`, {label}: to `ready`"] = [r for _, r in again[opcua]]
    return times, cpu


def table(times: dict[str, list[float]], cpu: dict[str, list[float]]) -> str:
    baseline = statistics.median(next(iter(times.values())))
    rows = [
        "| what | runs | median (s) | p99 (s) | x baseline | CPU, median (s) | target |",
        "|---|---:|---:|---:|---:|---:|---|",
    ]
    for name, values in times.items():
        used = f"{statistics.median(cpu[name]):.3f}" if name in cpu else ""
        median = statistics.median(values)
        target = TARGETS.get(name)
        if target is None and "OPC UA on" in name and "healthz" in name and "first" not in name:
            target = 1.0
        goal = "" if target is None else f"< {target:g} s: {'met' if median < target else 'missed'}"
        rows.append(
            f"| {name} | {len(values)} | {median:.3f} | {p99(values):.3f} | "
            f"{median / baseline:.1f} | {used} | {goal} |"
        )
    return "\n".join(rows)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="runs of each command (20)")
    parser.add_argument(
        "--serve-runs",
        type=int,
        default=5,
        help="`bwsd serve` restarts per mode after its first start (5)",
    )
    args = parser.parse_args()
    print(table(*measure(args.runs, args.serve_runs)))


if __name__ == "__main__":
    main()
