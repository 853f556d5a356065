"""The register codec of the PackML tags (pure)."""

from __future__ import annotations

import pytest

from bwsd.plc import MAP_VERSION, REG_COUNT, Tags, decode, encode
from bwsd.plc.registers import (
    REG_CMD_CHANGE_REQUEST,
    REG_ESTOP,
    REG_GOOD_COUNT,
    REG_HEARTBEAT,
    REG_INSTRUCTION_COUNT,
    REG_INSTRUCTION_INDEX,
    REG_STATE_CURRENT,
    REG_STOP_REASON,
    u32_words,
    words_u32,
)


def test_32_bit_values_are_high_word_first_and_unsigned():
    assert u32_words(0x12345678) == (0x1234, 0x5678)
    assert u32_words(70_000) == (1, 70_000 - 65_536)
    assert words_u32(0xFFFF, 0xFFFF) == 0xFFFFFFFF
    assert u32_words(1 << 32) == (0, 0)  # a counter wraps


def test_encode_puts_each_tag_at_its_documented_address():
    tags = Tags(cmd_change_request=1, state_current=6, instruction_index=70_000,
                instruction_count=80_000, good_count=3, stop_reason=2,
                heartbeat=65_535, estop=1)  # fmt: skip
    words = encode(tags)
    assert len(words) == REG_COUNT and words[0] == MAP_VERSION
    assert words[REG_CMD_CHANGE_REQUEST] == 1 and words[REG_STATE_CURRENT] == 6
    assert words[REG_INSTRUCTION_INDEX : REG_INSTRUCTION_INDEX + 2] == [1, 70_000 - 65_536]
    assert words[REG_INSTRUCTION_COUNT : REG_INSTRUCTION_COUNT + 2] == [1, 80_000 - 65_536]
    assert words[REG_GOOD_COUNT : REG_GOOD_COUNT + 2] == [0, 3]
    assert words[REG_STOP_REASON] == 2 and words[REG_HEARTBEAT] == 65_535
    assert words[REG_ESTOP] == 1
    assert decode(words) == tags


def test_decode_refuses_a_short_read_or_another_map_version():
    words = encode(Tags())
    with pytest.raises(ValueError, match=f"{REG_COUNT} registers, got {REG_COUNT - 1}"):
        decode(words[:-1])
    with pytest.raises(ValueError, match=f"map version 1, expected {MAP_VERSION}"):
        decode([1, *words[1:]])  # the map before the e-stop register
