"""The whole mock loom: which buses it serves for a machine's axes."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from bwsd.config import parse_config
from bwsd.errors import ConfigError
from simulator_hw.app import MockLoom, canopen_ids_problem, canopen_installed
from tests.support.fieldbus import ROOT, toml

pytestmark = pytest.mark.skipif(not canopen_installed(), reason="needs the canopen extra")
MACHINE = {"rows": 20, "cols": 20, "pitch_x": 1, "pitch_y": 1, "d_mat": 10, "c_mat": 0.5}


def segmented(count: int) -> dict[str, object]:
    """The machine with ``count`` two-cell segments: 46 + count axes (the weft's positioning
    axes included)."""
    segments = [f"ROW {r}[{2 * j}..{2 * j + 1}]" for r in range(20) for j in range(10)]
    return {**MACHINE, "segments": segments[:count]}


def test_a_drive_per_axis_while_the_node_ids_last():
    fits = parse_config({"machine": segmented(80)})  # drives 1..126, the I/O node 127
    assert canopen_ids_problem(fits) == ""
    assert MockLoom(fits, []).hub is not None


def test_a_machine_with_more_axes_than_node_ids_is_served_over_modbus_only():
    over = parse_config({"machine": segmented(82)})  # Modbus drives it: CANopen cannot
    assert canopen_ids_problem(over) == (
        "the drives of its 128 axes (nodes 1..128) and the I/O node 127 do not fit CANopen "
        "node ids 1..127"
    )
    assert MockLoom(over, []).hub is None
    with pytest.raises(
        ConfigError,
        match=r"\[fieldbus\.canopen\.node_base\]: the drives of "
        r"its 128 axes",
    ):
        MockLoom(over, [], canopen=True)


@pytest.mark.slow
def test_the_mock_loom_says_when_it_serves_modbus_only(tmp_path: Path):
    config = tmp_path / "mock.toml"
    config.write_text(
        toml(
            {
                "machine": segmented(82),
                "simulator": {"modbus_port": 0, "socketcand_port": 0, "control_port": 0},
            }
        )
    )
    mock = subprocess.Popen(
        [sys.executable, "-m", "simulator_hw", "--config", str(config)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        stdin=subprocess.DEVNULL,
    )
    try:
        assert mock.stdout is not None and mock.stderr is not None
        line = mock.stdout.readline()
        assert line.startswith("ready "), line + mock.stderr.read()
        assert [p.split("=")[0] for p in line.split()[1:]] == ["modbus", "control"]
        assert mock.stderr.readline() == (
            "simulator_hw: serving Modbus only: the drives of its "
            "128 axes (nodes 1..128) and the I/O node 127 do not "
            "fit CANopen node ids 1..127\n"
        )
    finally:
        mock.terminate()
        mock.communicate(timeout=20)


def test_canopen_off_serves_modbus_only_and_refuses_a_canopen_backend():
    """``[simulator] canopen = "off"``: no hub, without a word; an error naming the key when
    the config's backend is CANopen, which the drives would then be missing for."""
    machine = {"rows": 4, "cols": 4, "pitch_x": 10.0, "pitch_y": 10.0, "d_mat": 100.0, "c_mat": 0.5}
    off = parse_config({"machine": machine, "simulator": {"canopen": "off"}})
    assert MockLoom(off, []).hub is None
    backend = {"backend": "canopen"}
    wrong = parse_config({"machine": machine, "simulator": {"canopen": "off"}, "fieldbus": backend})
    with pytest.raises(ConfigError, match=r"\[simulator\.canopen\]: is \"off\", but"):
        MockLoom(wrong, [])
    with pytest.raises(ConfigError, match=r"\[simulator\.canopen\]: must be one of"):
        parse_config({"machine": machine, "simulator": {"canopen": "maybe"}})
