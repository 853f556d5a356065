"""The compiled kernel's calls: every refusal leaves the kernel free for the next caller and
the state as it was; a call refuses a second caller while it runs, and an instruction lets
other threads run meanwhile (bwsd/twin/csrc/module.c, KERNEL_BEGIN and KERNEL_END)."""

from __future__ import annotations

import re
import sys
import threading
from array import array
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from bwsd.config import load_config
from bwsd.program import load_program
from bwsd.twin import Shift, Twin, _kernel
from tests.twin.conftest import WORKED_CYCLE, WORKED_FILL, WORKED_MACHINE

ROOT = Path(__file__).resolve().parents[2]
MODULE_C = ROOT / "bwsd" / "twin" / "csrc" / "module.c"
FAR = 1 << 53  # beyond the grid's limit, 2^52
# The calls that release the interpreter lock: the instructions and dump. The others are
# short and keep it (the daemon's event loop reads the twin: a thread that gives the lock
# away may wait a switch interval to take it back).
RELEASING = {"shift", "takeup", "weft", "replay", "dump"}


def _kernel_of_worked_twin() -> Any:
    twin = Twin(WORKED_MACHINE, WORKED_FILL, 1.0)
    for ins in WORKED_CYCLE:
        twin.apply(ins)
    return twin._kernel


def _weft_row(kernel: Any) -> tuple[int, ...]:
    """A weft above the fabric, below the guides: (x0, y0, z0, x1, y1, z1)."""
    points = array("q", kernel.positions())
    z = max(points[2::3]) + (1 << 32)
    return (-(1 << 34), 0, z, 1 << 34, 0, z)


def _empty_kernel(cells: int) -> Any:
    """A kernel of cells x cells guides 1 mm apart, without yarns."""
    guides = array("q", [i << 32 for i in range(cells)]).tobytes()
    return _kernel.Kernel(guides, guides, 1 << 40, 33, 1.0, b"\x01", b"\x01")


def _filled(kernel: Any) -> tuple[int, int]:
    """The cell of warp 0."""
    row, col = array("i", kernel.warps()[0])[:2]
    return row, col


# Every method that reads or changes the state, called so that it succeeds.
CALLS: dict[str, Callable[[Any], object]] = {
    "add_warp": lambda k: k.add_warp(0, 1, 0, 0, 0),
    "shift": lambda k: k.shift(0, array("i", [0, 1, 0, 1]).tobytes(), 9, True),
    "takeup": lambda k: k.takeup(k.counts()[4] + (1 << 32), 9, True),
    "weft": lambda k: k.weft(*_weft_row(k), True),
    "replay": lambda k: k.replay(b""),
    "counts": lambda k: k.counts(),
    "positions": lambda k: k.positions(),
    "points": lambda k: k.points(array("i", [0, 1]).tobytes()),
    "chains": lambda k: k.chains(0, 2),
    "contacts": lambda k: k.contacts(),
    "warps": lambda k: k.warps(),
    "lengths": lambda k: k.lengths(),
    "near": lambda k: k.near(-FAR // 4, -FAR // 4, -FAR // 4, FAR // 4, FAR // 4, FAR // 4),
    "dump": lambda k: k.dump(),
}


def test_every_method_that_touches_the_state_is_listed_here_and_uses_the_kernel_pair() -> None:
    """A method added to the kernel without KERNEL_BEGIN and KERNEL_END would escape the
    tests below: the method table and CALLS must agree, and each such method must use them,
    releasing the interpreter lock exactly when it is one of RELEASING."""
    source = MODULE_C.read_text()
    table = re.findall(r'\{"(\w+)", \(PyCFunction\)Kernel_(\w+),', source)
    assert table and all(name == function for name, function in table)
    assert {name for name, _ in table} == set(CALLS) | {"load"}
    for name in CALLS:
        body = re.search(rf"\nstatic PyObject \*Kernel_{name}\(.*?\n}}\n", source, re.DOTALL)
        assert body, name
        mode = "RELEASE_LOCK" if name in RELEASING else "KEEP_LOCK"
        assert re.findall(r"KERNEL_BEGIN\(k, err, (\w+)\)", body[0]) == [mode], name
        assert body[0].count("KERNEL_END(k, err)") == 1, name


def test_the_c_part_between_the_pair_touches_no_python_and_never_leaves_early() -> None:
    """Between KERNEL_BEGIN and KERNEL_END the interpreter lock may be released: no Python
    object or function there, and no return or goto that would skip giving the kernel back."""
    source = MODULE_C.read_text()
    parts = re.findall(
        r"^ +KERNEL_BEGIN\(k, err, \w+\)\n(.*?)KERNEL_END", source, re.DOTALL | re.MULTILINE
    )
    assert len(parts) == len(CALLS)
    for part in parts:
        assert not re.search(r"\b(return|goto)\b", part), part
        assert not set(re.findall(r"\bPy\w*", part)) - {"Py_ssize_t"}, part


@pytest.mark.parametrize("name", sorted(CALLS))
def test_an_uninitialised_kernel_refuses_every_call(name: str) -> None:
    kernel = _kernel.Kernel.__new__(_kernel.Kernel)
    with pytest.raises(RuntimeError, match="the twin kernel is not initialised"):
        CALLS[name](kernel)


def test_a_kernel_whose_initialisation_failed_refuses_every_call() -> None:
    """A bad diameter leaves no half-made kernel behind (whose dump would read a diameter
    that was never kept)."""
    gx = array("q", [0, 1 << 32]).tobytes()
    kernel = _kernel.Kernel.__new__(_kernel.Kernel)
    with pytest.raises(ValueError, match="bad diameter"):
        _kernel.Kernel.__init__(kernel, gx, gx, 1 << 40, 33, 1.0, b"\x01", b"\x00")
    for name in sorted(CALLS):
        with pytest.raises(RuntimeError, match="not initialised"):
            CALLS[name](kernel)
    # now it may be made, once
    _kernel.Kernel.__init__(kernel, gx, gx, 1 << 40, 33, 1.0, b"\x01", b"\x01")
    assert kernel.counts() == (0, 0, 0, 0, 1 << 40)
    with pytest.raises(ValueError, match="bad kernel geometry"):
        _kernel.Kernel.__init__(kernel, gx, gx, 1 << 40, 33, 1.0, b"\x01", b"\x01")


# Calls the kernel refuses, each with its exception.
REFUSED: dict[str, tuple[Callable[[Any], object], type[Exception], str]] = {
    "add_warp on a filled cell": (
        lambda k: k.add_warp(*_filled(k), 0, 0, 0),
        ValueError,
        "bad fill cell",
    ),
    "add_warp outside": (lambda k: k.add_warp(2, 0, 0, 0, 0), ValueError, "bad fill cell"),
    "add_warp before": (lambda k: k.add_warp(0, -1, 0, 0, 0), ValueError, "bad fill cell"),
    "add_warp after a weft": (lambda k: k.add_warp(0, 1, 0, 0, 0), ValueError, "bad fill cell"),
    "shift of a line outside": (
        lambda k: k.shift(0, array("i", [5, 1, 0, 1]).tobytes(), 9, True),
        _kernel.KernelError,
        rf"\({_kernel.E_LINE},",
    ),
    "shift kept, out of the matrix": (
        lambda k: k.shift(0, array("i", [0, 1, 0, 1, 0, 1, 0, 1]).tobytes(), 9, False),
        _kernel.KernelError,
        rf"\({_kernel.E_MOVE_OUT},",
    ),
    "takeup into the fabric": (
        lambda k: k.takeup(0, 9, True),
        _kernel.KernelError,
        rf"\({_kernel.E_JAM},",
    ),
    "weft beyond the grid": (
        lambda k: k.weft(0, 0, 0, FAR, 0, 0, False),
        _kernel.KernelError,
        rf"\({_kernel.E_LIMIT},",
    ),
    "replay of a bad record": (
        lambda k: k.replay(bytes(_kernel.OP_SIZE)),
        _kernel.KernelError,
        rf"\({_kernel.E_ARITH},",
    ),
    "points of a missing node": (
        lambda k: k.points(array("i", [0, 10**6]).tobytes()),
        IndexError,
        "node id out of range",
    ),
    "chains past the last yarn": (lambda k: k.chains(0, 99), IndexError, "yarn out of range"),
    "chains backwards": (lambda k: k.chains(1, 0), IndexError, "yarn out of range"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_a_refused_call_leaves_the_kernel_free_and_the_state_as_it_was(case: str) -> None:
    call, error, message = REFUSED[case]
    kernel = _kernel_of_worked_twin()
    if case == "add_warp after a weft":
        kernel.weft(*_weft_row(kernel), False)
    before = kernel.dump()
    with pytest.raises(error, match=message):
        call(kernel)
    assert kernel.dump() == before  # and so the kernel was given back
    for name in sorted(set(CALLS) - {"add_warp"}):
        CALLS[name](kernel)
    assert kernel.dump() == before  # predictions roll back, an empty replay does nothing


@pytest.fixture(scope="module")
def braided() -> tuple[Any, dict[str, Callable[[Any], object]]]:
    """The kernel of the 24x24 braid after its program, and the calls that release the
    interpreter lock, with arguments that make them take the kernel long enough for another
    thread to be scheduled while one runs, and leave the state as it was."""
    machine = load_config(ROOT / "config" / "braid-24x24.toml").machine
    program = load_program(ROOT / "examples" / "braid-24x24.bws", machine)
    twin = Twin.from_program(machine, program)
    for ins in program.instructions:
        twin.apply(ins)
    kernel = twin._kernel
    first = program.instructions[0]
    assert isinstance(first, Shift)
    moves = array("i", twin._quads(first)).tobytes()
    gz = kernel.counts()[4]
    # A take-up that leaves the guides where they are meets no yarn: its record sets every
    # free node where it is, and replays as often as asked, to the same state.
    record, contacts, *_ = kernel.takeup(gz, 9, True)
    assert contacts == b"" and len(record) > 600 * _kernel.OP_SIZE
    calls: dict[str, Callable[[Any], object]] = {
        "shift": lambda k: k.shift(0 if first.axis == "row" else 1, moves, 9, True),
        "takeup": lambda k: k.takeup(gz + (1 << 32), 9, True),
        "weft": CALLS["weft"],
        "replay": lambda k: k.replay(record),
        "dump": CALLS["dump"],
    }
    assert set(calls) == RELEASING
    return kernel, calls


@pytest.mark.parametrize("name", sorted(RELEASING))
def test_a_call_lets_other_threads_run_and_refuses_them_the_kernel(
    braided: tuple[Any, dict[str, Callable[[Any], object]]], name: str
) -> None:
    """With a switch interval far beyond the test, the main thread gets the interpreter lock
    only when the worker releases it, which it does only inside the kernel: there, the main
    thread's call must be refused."""
    kernel, calls = braided
    call = calls[name]
    before = kernel.dump()
    refused: list[str] = []
    done = threading.Event()

    def work() -> None:
        try:
            for _ in range(2000):
                call(kernel)
                if refused:
                    return
        finally:
            done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        worker = threading.Thread(target=work)
        worker.start()
        while not done.wait(0.0002):  # waits without the lock
            try:
                kernel.counts()
            except RuntimeError as exc:
                refused.append(str(exc))
        worker.join()
    finally:
        sys.setswitchinterval(old)
    assert refused and set(refused) == {"the twin kernel is in use by another thread"}
    assert kernel.dump() == before  # given back, and the predictions rolled back
