"""Benchmark of the stops: prints the markdown tables of docs/benchmarks.md.

    python bench/stops.py [--aborts 50] [--locked 10] [--kills 20]

`bwsd serve` and the mock loom run in their own processes on loopback.

- **Abort and Stop mid-stroke.** A slow loom (a stroke 1 s out, 1 s back); the command is
  sent a random 0.1 to 0.6 s into a stroke, over REST. Measured: from the moment the
  request is sent to the moment the mock loom took the quick stop (its `time.monotonic()`,
  the same clock on one machine), and to the answer (the state is Aborted or Stopped then).
  The baseline, in the same run: a Hold sent the same way, which waits for the stroke.
- **Abort with the journal locked.** Another process holds the journal's write lock (an
  sqlite3 shell left in a transaction); from the Abort's request to its answer, Aborted.
- **Loss of the loom.** The mock loom is killed (SIGKILL) mid-run; from the kill to the
  moment `/state` says Held, polled every 5 ms, on each bus. The mock loom keeps its
  mechanics in a state file, so each kill is followed by a restart and an Unhold.
"""

from __future__ import annotations

import argparse
import asyncio
import random
import sqlite3
import statistics
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bwsd.api.auth import TokenStore  # noqa: E402
from bwsd.config import load_config  # noqa: E402
from bwsd.paths import state_folder, tokens_file  # noqa: E402
from simulator_hw.control import request  # noqa: E402
from tests.support.fieldbus import BUS, MACHINE, Mock, start_mock, toml  # noqa: E402
from tests.test_daemon import Served  # noqa: E402

CYCLE = "ROW 1:+1 2:-1\nCOL 1:+1 2:-1\nROW 1:-1 2:+1\nCOL 1:-1 2:+1\nTAKEUP 2\n"
LONG = f"YARN diameter=1\nFILL row=1 col=0\n.XX.\n.XX.\nEND\nREPEAT 2000\n{CYCLE}END\n"
SLOW = {"stroke_speed": 10.0, "takeup_speed": 10.0}  # 10 mm: 1 s out, 1 s back
QUICK = {"stroke_speed": 200.0, "takeup_speed": 200.0}


def config_file(tmp: Path, mock: Mock, backend: str = "modbus") -> Path:
    path = tmp / "bwsd.toml"
    path.write_text(
        toml(
            {
                "machine": MACHINE,
                "fieldbus": {"backend": backend, **BUS, "timeout": 30.0},
                "fieldbus.modbus": {"port": mock.ports["modbus"]},
                "fieldbus.canopen": {
                    "interface": "socketcand",
                    "port": mock.ports["socketcand"],
                    "heartbeat_ms": 50,
                },
                "api": {"port": 0},
                "plc": {"port": 0, "enabled": False},
            }
        )
    )
    return path


@contextmanager
def serving(speeds: dict[str, Any], backend: str = "modbus") -> Iterator[tuple[list[Mock], Served]]:
    """The mock loom (in a list: a restarted one takes its place, and is stopped at the
    end) and `bwsd serve` with the long program loaded and reset."""
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        looms = [start_mock(folder, {**speeds, "state_file": "loom.json"})]
        config = config_file(folder, looms[0], backend)
        state = state_folder(load_config(config), folder / "state")
        token = TokenStore.load(tokens_file(load_config(config), state)).add("bench", "operator")
        served = Served(config, state, token)
        try:
            served.http.post("/programs", json={"name": "long.bws", "text": LONG})
            served.command("reset")
            yield looms, served
        finally:
            served.stop()
            looms[0].stop()


def loom(mock: Mock) -> dict[str, Any]:
    answer: dict[str, Any] = asyncio.run(
        request("127.0.0.1", mock.ports["control"], {"cmd": "state"})
    )
    return answer


def moving(mock: Mock) -> bool:
    return any(axis["busy"] for axis in loom(mock)["axes"].values())


def resume(served: Served) -> None:
    """From Aborted, Stopped or Held back to Execute (Clear, Reset, Start with resume)."""
    for _ in range(200):
        state = served.state()
        if state["name"] == "Execute":
            return
        step = {
            "Aborted": ("clear", {}),
            "Stopped": ("reset", {}),
            "Held": ("unhold", {}),
            "Idle": ("start", {"resume": state["resumable"]}),
        }.get(state["name"])
        if step is not None:
            served.http.post(f"/commands/{step[0]}", json=step[1])
        time.sleep(0.02)
    raise RuntimeError(f"cannot resume: {served.state()}")


def cut(served: Served, mock: Mock, command: str, rng: random.Random) -> tuple[float, float]:
    """Seconds from sending ``command`` mid-stroke to the loom's quick stop and to its answer."""
    resume(served)
    while not moving(mock):
        time.sleep(0.005)
    time.sleep(rng.uniform(0.1, 0.6))
    sent = time.monotonic()
    answer = served.http.post(f"/commands/{command}", json={"reason": "bench"})
    answered = time.monotonic() - sent
    answer.raise_for_status()
    stopped = loom(mock)["quick_stopped"]
    return (stopped - sent if stopped is not None and stopped >= sent else float("nan")), answered


def aborts(count: int) -> dict[str, list[float]]:
    rng = random.Random(27)
    out: dict[str, list[float]] = {
        k: [] for k in ("abort", "abort answer", "stop", "stop answer", "hold answer")
    }
    with serving(SLOW) as ([mock], served):
        served.command("start")
        for n in range(count):
            command = "abort" if n % 2 == 0 else "stop"
            to_stop, answered = cut(served, mock, command, rng)
            out[command].append(to_stop)
            out[f"{command} answer"].append(answered)
        for _ in range(max(3, count // 10)):  # the baseline: a Hold waits for the stroke
            resume(served)
            while not moving(mock):
                time.sleep(0.005)
            time.sleep(rng.uniform(0.1, 0.6))
            sent = time.monotonic()
            served.http.post("/commands/hold", json={}).raise_for_status()
            out["hold answer"].append(time.monotonic() - sent)
    return out


def locked_aborts(count: int) -> list[float]:
    took = []
    with serving(QUICK) as (_mock, served):
        path = Path(served.log).parent / "state" / "journal.db"
        for _ in range(count):
            resume(served)
            time.sleep(0.2)
            other = sqlite3.connect(path, isolation_level=None)
            other.execute("BEGIN IMMEDIATE")
            time.sleep(0.3)
            sent = time.monotonic()
            answer = served.http.post("/commands/abort", json={})
            took.append(time.monotonic() - sent)
            other.execute("ROLLBACK")
            other.close()
            assert answer.json()["name"] == "Aborted", answer.text
    return took


def losses(count: int, backend: str, how: str = "kill") -> list[float]:
    """Seconds from the loom's loss (killed, or muted: it stops answering but keeps the
    connection open) to Held."""
    rng = random.Random(13)
    took = []
    with serving(QUICK, backend) as (looms, served):
        mock = looms[0]
        served.command("start")
        for _ in range(count):
            time.sleep(rng.uniform(0.2, 0.8))
            assert served.state()["name"] == "Execute"
            lost = time.monotonic()
            if how == "kill":
                mock.proc.kill()
            else:
                asyncio.run(
                    request("127.0.0.1", mock.ports["control"], {"cmd": "fault", "kind": "mute"})
                )
            while served.state()["name"] == "Execute":
                time.sleep(0.005)
            took.append(time.monotonic() - lost)
            if how == "kill":
                mock.proc.wait(10)
                mock.stop()
                mock = start_mock(
                    Path(served.log).parent, {**QUICK, "state_file": "loom.json"}, mock.ports
                )
                looms[0] = mock
            else:
                asyncio.run(request("127.0.0.1", mock.ports["control"], {"cmd": "clear"}))
            resume(served)
    return took


def row(name: str, values: list[float], target: str = "") -> str:
    ms = [v * 1e3 for v in values if v == v]
    if not ms:
        return f"| {name} | 0 | | | | {target} |"
    return (
        f"| {name} | {len(ms)} | {statistics.median(ms):.1f} | {np.percentile(ms, 99):.1f} "
        f"| {max(ms):.1f} | {target} |"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--aborts", type=int, default=100, help="Abort and Stop tries in all")
    parser.add_argument("--locked", type=int, default=10)
    parser.add_argument("--kills", type=int, default=20, help="kills of the loom per bus")
    args = parser.parse_args()
    cuts = aborts(args.aborts)
    locked = locked_aborts(args.locked)
    lost = {backend: losses(args.kills, backend) for backend in ("modbus", "canopen")}
    muted = losses(max(5, args.kills // 4), "modbus", "mute")
    print("| measure | n | p50 ms | p99 ms | max ms | target |\n|---|---:|---:|---:|---:|---|")
    print(row("Abort mid-stroke to the loom's quick stop", cuts["abort"], "< 100 ms at p99"))
    print(row("Stop mid-stroke to the loom's quick stop", cuts["stop"], "< 100 ms at p99"))
    print(row("Abort mid-stroke to its answer (Aborted)", cuts["abort answer"]))
    print(row("Stop mid-stroke to its answer (Stopped)", cuts["stop answer"]))
    print(row("Hold mid-stroke to its answer (baseline: waits)", cuts["hold answer"]))
    print(row("Abort with the journal locked, to Aborted", locked, "< 2 s"))
    for backend, took in lost.items():
        print(row(f"loom killed to Held, {backend}", took, "< 1.5 s at p99"))
    print(row(f"loom muted to Held, modbus (baseline: io_timeout {BUS['io_timeout']:g} s)", muted))


if __name__ == "__main__":
    main()
