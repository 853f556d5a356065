"""The register codec of the PackML tags (pure), against the map docs/plc.md writes."""

from __future__ import annotations

from dataclasses import fields

import pytest

from bwsd.plc import MAP_VERSION, REG_COUNT, Tags, decode, encode, registers
from bwsd.plc.registers import u32_words, words_u32
from tests.doc_tables import addresses, doc_table


def test_32_bit_values_are_high_word_first_and_unsigned():
    assert u32_words(0x12345678) == (0x1234, 0x5678)
    assert u32_words(70_000) == (1, 70_000 - 65_536)
    assert words_u32(0xFFFF, 0xFFFF) == 0xFFFFFFFF
    assert u32_words(1 << 32) == (0, 0)  # a counter wraps


# Each tag of docs/plc.md's map: the field of Tags that holds it and the code's constant for
# its address. The addresses themselves are read from the doc.
TAG_FIELDS: dict[str, tuple[str | None, int]] = {
    "Admin.MapVersion": (None, registers.REG_MAP_VERSION),
    "Command.CntrlCmd": ("cntrl_cmd", registers.REG_CNTRL_CMD),
    "Command.CmdChangeRequest": ("cmd_change_request", registers.REG_CMD_CHANGE_REQUEST),
    "Command.UnitMode": ("unit_mode", registers.REG_UNIT_MODE),
    "Command.UnitModeChangeRequest": (
        "unit_mode_change_request",
        registers.REG_UNIT_MODE_CHANGE_REQUEST,
    ),
    "Status.StateCurrent": ("state_current", registers.REG_STATE_CURRENT),
    "Status.UnitModeCurrent": ("unit_mode_current", registers.REG_UNIT_MODE_CURRENT),
    "Status.CmdInvalid": ("cmd_invalid", registers.REG_CMD_INVALID),
    "Status.InstructionIndex": ("instruction_index", registers.REG_INSTRUCTION_INDEX),
    "Status.InstructionCount": ("instruction_count", registers.REG_INSTRUCTION_COUNT),
    "Admin.ProdGoodCount": ("good_count", registers.REG_GOOD_COUNT),
    "Admin.StopReason": ("stop_reason", registers.REG_STOP_REASON),
    "Status.Heartbeat": ("heartbeat", registers.REG_HEARTBEAT),
    "Status.EStop (bwsd)": ("estop", registers.REG_ESTOP),
    "Command.Resume (bwsd)": ("resume", registers.REG_RESUME),
    "Status.Resumable (bwsd)": ("resumable", registers.REG_RESUMABLE),
    "Command.ProgramId (bwsd)": ("program", registers.REG_PROGRAM),
    "Command.LoadRequest (bwsd)": ("load_request", registers.REG_LOAD_REQUEST),
    "Status.ProgramId (bwsd)": ("program_id", registers.REG_PROGRAM_ID),
}
MAP = doc_table("plc.md", "address", "tag", "type", "access", after="## The map")


def test_the_documented_map_is_the_codes_map():
    assert [row["tag"] for row in MAP] == list(TAG_FIELDS), "a tag added, removed or moved"
    assert [f.name for f in fields(Tags)] == [f for f, _ in TAG_FIELDS.values() if f]
    taken: list[int] = []
    for row in MAP:
        at = addresses(row["address"])
        assert len(at) == {"uint16": 1, "uint32": 2}[row["type"]], row
        assert at == list(range(at[0], at[0] + len(at))), row
        assert at[0] == TAG_FIELDS[row["tag"]][1], row
        assert (row["access"] == "RW") == (at[0] in registers.WRITABLE), row
        taken += at
    assert taken == list(range(REG_COUNT)), "the map has a gap or an overlap"
    assert MAP[0]["meaning"].startswith(f"{MAP_VERSION};")


def test_encode_puts_each_tag_at_its_documented_address():
    values = {field: 1000 + 7 * i for i, (field, _) in enumerate(TAG_FIELDS.values()) if field}
    values["instruction_index"], values["program_id"] = 70_000, 0x12345678  # two words each
    tags = Tags(**values)
    words = encode(tags)
    assert len(words) == REG_COUNT and words[0] == MAP_VERSION
    for row in MAP[1:]:
        field, _ = TAG_FIELDS[row["tag"]]
        at = addresses(row["address"])
        got = words[at[0]] if len(at) == 1 else (words[at[0]] << 16) | words[at[1]]
        assert got == values[str(field)], row
    assert decode(words) == tags


def test_decode_refuses_a_short_read_or_another_map_version():
    words = encode(Tags())
    with pytest.raises(ValueError, match=f"{REG_COUNT} registers, got {REG_COUNT - 1}"):
        decode(words[:-1])
    with pytest.raises(ValueError, match=f"map version 1, expected {MAP_VERSION}"):
        decode([1, *words[1:]])  # the map before the e-stop register
