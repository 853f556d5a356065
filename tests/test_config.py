"""Machine configuration: every key range-checked, unknown keys refused, the place named."""

from __future__ import annotations

from typing import Any

import pytest

from bwsd.config import load_config, parse_config
from bwsd.errors import ConfigError

GOOD = {
    "machine": {"rows": 4, "cols": 4, "pitch_x": 10.0, "pitch_y": 10, "d_mat": 150, "c_mat": 0.4},
    "yarn": {"diameter": 1.5},
}


def _with(table: str, key: str, value) -> dict[str, dict[str, Any]]:
    data = {name: dict(values) for name, values in GOOD.items()}
    data.setdefault(table, {})[key] = value
    return data


def test_a_good_config_gives_the_machine():
    machine = parse_config(GOOD).machine
    assert (machine.rows, machine.cols, machine.pitch_y, machine.yarn_diameter) == (4, 4, 10.0, 1.5)
    assert isinstance(machine.pitch_y, float)


def test_yarn_table_is_optional():
    data = {"machine": GOOD["machine"]}
    assert parse_config(data).machine.yarn_diameter == 0.0


@pytest.mark.parametrize(
    ("table", "key", "value", "message"),
    [
        ("machine", "rows", 0, r"\[machine.rows\]: must lie in"),
        ("machine", "rows", 2.5, r"\[machine.rows\]: must be an integer"),
        ("machine", "cols", True, r"\[machine.cols\]: must be a number"),
        ("machine", "c_mat", 1.5, r"\[machine.c_mat\]: must lie in \[0, 1\]"),
        ("machine", "pitch_x", "10", r"\[machine.pitch_x\]: must be a number"),
        ("machine", "speed", 3, r"\[machine.speed\]: unknown key"),
        ("yarn", "diameter", -1, r"\[yarn.diameter\]: must lie in"),
        ("yarn", "colour", "red", r"\[yarn.colour\]: unknown key"),
        ("journal", "busy_timeout", 0, r"\[journal.busy_timeout\]: must lie in \[0.1, 600\]"),
    ],
)
def test_bad_values_name_table_and_key(table, key, value, message):
    with pytest.raises(ConfigError, match=message):
        parse_config(_with(table, key, value), "m.toml")


def test_missing_key_and_table_and_unknown_table():
    data = {"machine": {k: v for k, v in GOOD["machine"].items() if k != "d_mat"}}
    with pytest.raises(ConfigError, match=r"\[machine.d_mat\]: missing key"):
        parse_config(data)
    with pytest.raises(ConfigError, match=r"\[machine\]: missing table"):
        parse_config({"yarn": {"diameter": 1.0}})
    with pytest.raises(ConfigError, match=r"\[printer\]: unknown table"):
        parse_config({**GOOD, "printer": {}})


def test_load_config_reports_file_errors(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[machine\nrows = 2\n")
    with pytest.raises(ConfigError, match=r"bad.toml: not valid TOML"):
        load_config(bad)
    good = tmp_path / "good.toml"
    good.write_text(
        "[machine]\nrows = 2\ncols = 2\npitch_x = 10\npitch_y = 10\nd_mat = 100\nc_mat = 0.5\n"
        "[yarn]\ndiameter = 1\n"
    )
    assert load_config(good).machine.d_mat == 100.0


def test_bus_and_simulator_tables_have_defaults_and_are_checked():
    cfg = parse_config(GOOD)
    assert cfg.table("fieldbus")["backend"] == "modbus"
    assert cfg.table("fieldbus.modbus")["port"] == 15020
    assert cfg.table("simulator")["stroke_speed"] == 0.0
    bus = {**GOOD, "fieldbus": {"backend": "canopen", "canopen": {"interface": "virtual"}}}
    assert parse_config(bus).table("fieldbus.canopen")["interface"] == "virtual"
    with pytest.raises(ConfigError, match=r"\[fieldbus.backend\]: must be one of modbus, canopen"):
        parse_config({**GOOD, "fieldbus": {"backend": "profibus"}})
    with pytest.raises(ConfigError, match=r"\[fieldbus.modbus.port\]: must lie in"):
        parse_config({**GOOD, "fieldbus": {"modbus": {"port": 70000}}})
    with pytest.raises(ConfigError, match=r"\[fieldbus.canopen.bitrate\]: unknown key"):
        parse_config({**GOOD, "fieldbus": {"canopen": {"bitrate": 500000}}})


def test_canopen_node_ids_must_fit_and_not_collide():
    big = {**GOOD, "machine": {**GOOD["machine"], "rows": 70, "cols": 70}}
    parse_config(big)  # fine on Modbus
    with pytest.raises(ConfigError, match=r"\[fieldbus.canopen.node_base\]: 146 axes"):
        parse_config({**big, "fieldbus": {"backend": "canopen"}})
    clash = {"backend": "canopen", "canopen": {"io_node": 5}}
    with pytest.raises(ConfigError, match=r"\[fieldbus.canopen.io_node\]: collides"):
        parse_config({**GOOD, "fieldbus": clash})


def test_modbus_map_limits_the_matrix():
    huge = {**GOOD, "machine": {**GOOD["machine"], "rows": 300, "cols": 300}}
    with pytest.raises(ConfigError, match=r"\[fieldbus.backend\]: 90000 cells"):
        parse_config(huge)


def _row_segments(rows: int, per_row: int) -> list[str]:
    return [f"ROW {r}[{2 * j}..{2 * j + 1}]" for r in range(rows) for j in range(per_row)]


def test_modbus_map_limits_the_axes_segments_included():
    """An axis block per row, column, weft and take-up axis and segment: at most 4089."""
    square = {**GOOD["machine"], "rows": 100, "cols": 100}
    fits = parse_config({"machine": {**square, "segments": _row_segments(100, 39)[:3883]}})
    assert len(fits.machine.segments) == 3883  # 100 + 100 + 3 + 3883 + 3 = 4089 axes
    over = {"machine": {**square, "segments": _row_segments(100, 39)[:3884]}}
    with pytest.raises(
        ConfigError,
        match=r"\[machine\.segments\]: the Modbus map addresses at "
        r"most 4089 axes, the machine has 4090 \(100 rows, 100 cols, 6 weft and "
        r"take-up axes, 3884 segments\)",
    ):
        parse_config(over)
    with pytest.raises(ConfigError, match=r"\[fieldbus.canopen.node_base\]: 4090 axes \(3884 of"):
        parse_config({**over, "fieldbus": {"backend": "canopen"}})  # the bus's own limit


def test_weft_axes_default_to_all_three_and_none_on_modbus_map_2():
    assert parse_config(GOOD).machine.weft_axes == ("x", "y", "z")
    picked = {**GOOD["machine"], "weft_axes": ["z", "x"], "weft_fixed": [1, 2.54, 3]}
    machine = parse_config({"machine": picked}).machine
    assert machine.weft_axes == ("x", "z") and machine.fixed_weft() == (1.0, 2.54, 3.0)
    map2 = {"fieldbus": {"modbus": {"map": 2}}}
    assert parse_config({**GOOD, **map2}).machine.weft_axes == ()
    none = {**GOOD["machine"], "weft_axes": []}
    assert parse_config({"machine": none, **map2}).machine.weft_axes == ()
    refused = r"\[machine\.weft_axes\]: Modbus map 2 has no weft positioning axes"
    with pytest.raises(ConfigError, match=refused):
        parse_config({"machine": picked, **map2})
    canopen = {"fieldbus": {"backend": "canopen", "modbus": {"map": 2}}}  # map 2 is Modbus's
    assert parse_config({**GOOD, **canopen}).machine.weft_axes == ("x", "y", "z")
    bad_lists = [
        (["w"], "entry 1: 'w' is not one of"),
        (["x", "x"], "entry 2: .x. is named twice"),
        ("xyz", "must be a list of names"),
    ]
    for bad, said in bad_lists:
        with pytest.raises(ConfigError, match=rf"\[machine\.weft_axes\]: {said}"):
            parse_config({"machine": {**GOOD["machine"], "weft_axes": bad}})
    with pytest.raises(ConfigError, match=r"\[machine\.weft_fixed\]: must be a list of three"):
        parse_config({"machine": {**GOOD["machine"], "weft_fixed": [1, 2]}})


def test_the_fixed_weft_position_defaults_to_the_convergence_point_half_way_up():
    machine = parse_config(GOOD).machine
    ox, oy = machine.convergence_xy()
    assert machine.fixed_weft() == (ox, oy, machine.d_mat / 2)


def test_daemon_tables_defaults_and_flags():
    cfg = parse_config(GOOD)
    assert cfg.table("api")["open_reads"] is False and cfg.table("plc")["enabled"] is True
    assert cfg.table("controller") == {
        "max_contacts": 10_000,
        "tensioner_stroke": 0.0,
        "max_instructions": 1_000_000,
        "snapshot_every": 200,
    }
    assert cfg.table("journal") == {"path": "journal.db", "busy_timeout": 5.0}
    with pytest.raises(ConfigError, match=r"\[api.open_reads\]: must be true or false"):
        parse_config({**GOOD, "api": {"open_reads": 1}})


def test_numbers_are_the_exact_decimals_written(tmp_path):
    """A pitch of 1.0000180559 is that decimal: its guide lies on the grid point of the decimal,
    not of the nearest float (docs/twin.md)."""
    from bwsd.twin.geometry import Geometry

    path = tmp_path / "m.toml"
    path.write_text(
        "[machine]\nrows = 1\ncols = 2\npitch_x = 1.0000180559\npitch_y = 1\n"
        "d_mat = 10\nc_mat = 0.5\n"
    )
    assert Geometry(load_config(path).machine).gx[1] == 4295044845


@pytest.mark.parametrize(
    ("line", "message"),
    [
        ("pitch_x = 2.54000000000000000001", r"\[machine.pitch_x\]: .* cannot be kept exactly"),
        ("d_mat = 1e999", r"\[machine.d_mat\]: .* cannot be kept exactly"),
        ("d_mat = inf", r"\[machine.d_mat\]: .*not a finite number"),
        ("pitch_x = 5000", r"\[machine\]: a guide of .* beyond the twin's range of 2\^20 mm"),
    ],
)
def test_numbers_the_twin_cannot_keep_are_refused_with_their_key(tmp_path, line, message):
    base = {
        "rows": "300",
        "cols": "300",
        "pitch_x": "1",
        "pitch_y": "1",
        "d_mat": "10",
        "c_mat": "0.5",
    }
    key = line.split(" = ")[0]
    body = "".join(f"{k} = {v}\n" for k, v in base.items() if k != key)
    path = tmp_path / "m.toml"
    path.write_text(f'[machine]\n{body}{line}\n[fieldbus]\nbackend = "canopen"\n')
    with pytest.raises(ConfigError, match=message):
        load_config(path)


def test_a_yarn_diameter_too_fine_for_the_grid_is_refused():
    with pytest.raises(ConfigError, match=r"\[yarn.diameter\]: must be 0 or at least 1e-06 mm"):
        parse_config(_with("yarn", "diameter", 1e-9))


def test_a_yarn_too_thick_for_the_gap_at_the_fell_is_refused_at_its_key():
    """Warps start c_mat x the smaller pitch apart at the fell (0.4 x 10 mm here): d = 20 mm
    on a 10 mm pitch put contacts 19 mm outside the matrix, d = 1023 mm a metre out."""
    for diameter in (4, 20.0, 1000):
        with pytest.raises(
            ConfigError,
            match=r"\[yarn.diameter\]: a yarn diameter of [\d.]+ mm "
            r"does not fit: it must be less than c_mat x the smaller pitch "
            r"\(4 mm\)",
        ):
            parse_config(_with("yarn", "diameter", diameter))
    assert parse_config(_with("yarn", "diameter", 3.999)).machine.yarn_diameter == 3.999
    narrow = _with("machine", "pitch_y", 2.5)  # the smaller pitch decides: 0.4 x 2.5 = 1 mm
    with pytest.raises(ConfigError, match=r"\[yarn.diameter\]: .* \(1 mm\)"):
        parse_config(narrow)
