"""The spec: checked whole, errors naming [table.key], the same candidates in every run."""

from __future__ import annotations

import pytest

from bwsd.sweep.errors import SpecError
from bwsd.sweep.spec import Range, load_spec
from tests.sweep.conftest import BRAID_SPEC, WEAVE, WEAVE_CONFIG, WEAVE_SPEC, write

RANDOM = """
[sweep]
generator = "braid4"
sample = "random"
count = 30
seed = 11
[fixed]
cycles = 2
[vary]
takeup = { low = 1.0, high = 5.0 }
rows = { low = 2, high = 3 }
shape = ["rect"]
flange = ["2x6", [3, 7]]
"""


def test_a_grid_is_every_combination_in_order_with_stable_ids(tmp_path):
    spec = load_spec(write(tmp_path, BRAID_SPEC))
    first = spec.candidates()
    assert len(first) == 20
    assert [c.index for c in first] == list(range(20))
    assert first[0].columns == {
        "rows": 3,
        "cols": 3,
        "diameter": 0.5,
        "takeup": 2.0,
        "c_mat": 0.3,
        "cycles": 12,
    }
    assert isinstance(first[0].params["takeup"], float)  # 2 in TOML, a float parameter
    again = load_spec(write(tmp_path, BRAID_SPEC, "again.toml")).candidates()
    assert [c.id for c in again] == [c.id for c in first]
    assert len({c.id for c in first}) == 20


def test_a_random_sample_is_the_same_for_the_same_seed_and_differs_for_another(tmp_path):
    first = load_spec(write(tmp_path, RANDOM)).candidates()
    second = load_spec(write(tmp_path, RANDOM, "b.toml")).candidates()
    other = load_spec(write(tmp_path, RANDOM.replace("seed = 11", "seed = 12"), "c.toml"))
    assert [c.columns for c in first] == [c.columns for c in second]
    assert [c.id for c in first] != [c.id for c in other.candidates()]
    for c in first:
        assert 1.0 <= c.params["takeup"] <= 5.0
        assert c.params["rows"] in (2, 3)
        assert c.params["flange"] in ((2, 6), (3, 7))
        assert c.columns["flange"] in ("2x6", "3x7")


def test_a_random_draw_repeated_is_one_candidate(tmp_path):
    text = RANDOM.replace(
        "takeup = { low = 1.0, high = 5.0 }\nrows = { low = 2, high = 3 }\n",
        "takeup = [1.0, 2.0]\n",
    )
    spec = load_spec(write(tmp_path, text))
    found = spec.candidates()
    assert len(found) == 4  # 2 take-ups x 2 flanges drawn 30 times
    assert [c.index for c in found] == [0, 1, 2, 3]
    assert isinstance(load_spec(write(tmp_path, RANDOM, "r.toml")).vary["takeup"], Range)


def test_a_fixed_program_sweeps_its_config_keys(tmp_path):
    spec = load_spec(write(tmp_path, WEAVE_SPEC))
    assert [c.columns for c in spec.candidates()] == [
        {"rows": 3, "pitch": 10.0},
        {"rows": 3, "pitch": 5.0},
        {"rows": 2, "pitch": 10.0},
        {"rows": 2, "pitch": 5.0},
    ]


def test_file_names_are_relative_to_the_spec(tmp_path):
    (tmp_path / "w.bws").write_bytes(WEAVE.read_bytes())
    (tmp_path / "w.toml").write_bytes(WEAVE_CONFIG.read_bytes())
    text = '[sweep]\nprogram = "w.bws"\nconfig = "w.toml"\n[vary]\nc_mat = [0.4, 0.5]\n'
    assert len(load_spec(write(tmp_path, text)).candidates()) == 2


BAD = [
    ("[fixed]\nrows = 2\n", r"\[sweep\]: missing table"),
    (
        '[sweep]\ngenerator = "braid"\n',
        r"\[sweep\.generator\]: unknown generator 'braid' "
        r"\(known: twist, braid4",
    ),
    ('[sweep]\ngenerator = "braid4"\nsampel = "grid"\n', r"\[sweep\.sampel\]: unknown key"),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\ntake_up = [1.0]\n',
        r"\[vary\.take_up\]: not a parameter here \(known: rows, cols, cycles",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\ntakeup = [1.0, "x"]\n',
        r"\[vary\.takeup\]: must be a number, got 'x'",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\nrows = [2, 2.5]\n',
        r"\[vary\.rows\]: must be an integer, got 2\.5",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\ntakeup = [1.0, 1]\n',
        r"\[vary\.takeup\]: lists a value twice",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\ntakeup = []\n',
        r"\[vary\.takeup\]: must be a non-empty list",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\ntakeup = { low = 1.0, high = 2.0 }\n',
        r"\[vary\.takeup\]: a grid needs a list of values",
    ),
    (
        '[sweep]\ngenerator = "braid4"\nsample = "random"\ncount = 5\n[vary]\n'
        "takeup = { low = 3.0, high = 2.0 }\n",
        r"\[vary\.takeup\]: low \(3\.0\) must not exceed",
    ),
    ('[sweep]\ngenerator = "braid4"\nsample = "random"\n', r"\[sweep\.count\]: must be an integer"),
    ('[sweep]\ngenerator = "braid4"\nseed = 3\n', r"\[sweep\.seed\]: only a random sample"),
    (
        '[sweep]\ngenerator = "braid4"\nrelax = "yes"\n',
        r"\[sweep\.relax\]: must be true or false, got 'yes'",
    ),
    (
        '[sweep]\ngenerator = "braid4"\nrelax = 1\n',
        r"\[sweep\.relax\]: must be true or false, got 1",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[fixed]\nflange = "2by6"\n',
        r"\[fixed\.flange\]: must be a block like \"2x6\"",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[fixed]\ntakeup = 2.0\n[vary]\ntakeup = [1.0]\n',
        r"\[vary\.takeup\]: is also in \[fixed\]",
    ),
    (
        '[sweep]\ngenerator = "braid4"\n[vary]\n'
        + "".join(f"{k} = {list(range(1, 11))}\n" for k in ("rows", "cols", "cycles", "takeup"))
        + f"pitch = {list(range(1, 11))}\nd_mat = {list(range(100, 300))}\n",
        r"\[vary\]: 20000000 candidates: at most 1000000",
    ),
    ('[sweep]\ngenerator = "braid4"\nconfig = "x.toml"\n', r"\[sweep\.config\]: a generator"),
    ('[sweep]\nprogram = "nothing.bws"\nconfig = "nothing.toml"\n', r"\[sweep\]: cannot read"),
    (
        f'[sweep]\nprogram = "{WEAVE}"\nconfig = "{WEAVE_CONFIG}"\n[vary]\ndiameter = [1.0, 2.0]\n',
        r"\[vary\.diameter\]: the program .* sets its own YARN diameter",
    ),
    (
        f'[sweep]\nprogram = "{WEAVE}"\nconfig = "{WEAVE_CONFIG}"\n[vary]\nturns = [1]\n',
        r"\[vary\.turns\]: not a parameter here \(known: rows, cols, pitch",
    ),
    ("[sweep\n", r"not valid TOML"),
]


@pytest.mark.parametrize(("text", "message"), BAD)
def test_a_bad_spec_names_table_and_key(tmp_path, text, message):
    path = write(tmp_path, text)
    with pytest.raises(SpecError, match=message) as caught:
        load_spec(path)
    assert str(caught.value).startswith(str(path))


def test_a_missing_spec_file_is_named(tmp_path):
    with pytest.raises(SpecError, match=r"nothing\.toml: cannot read"):
        load_spec(tmp_path / "nothing.toml")
