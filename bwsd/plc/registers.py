"""The PackML tags as holding registers (map: docs/plc.md): addresses and the codec (pure).

Twenty-four holding registers from address 0, no gaps, so a PLC reads them all in one request.
32-bit values take two registers, high word first, unsigned.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import astuple, dataclass

MAP_VERSION = 3  # 2: the e-stop register (16), stop reason 8; 3: resume, load (17 .. 23), reason 9

REG_MAP_VERSION = 0
REG_CNTRL_CMD = 1  # Command.CntrlCmd
REG_CMD_CHANGE_REQUEST = 2  # Command.CmdChangeRequest
REG_UNIT_MODE = 3  # Command.UnitMode
REG_UNIT_MODE_CHANGE_REQUEST = 4  # Command.UnitModeChangeRequest
REG_STATE_CURRENT = 5  # Status.StateCurrent
REG_UNIT_MODE_CURRENT = 6  # Status.UnitModeCurrent
REG_CMD_INVALID = 7  # Status.CmdInvalid
REG_INSTRUCTION_INDEX = 8  # 8, 9
REG_INSTRUCTION_COUNT = 10  # 10, 11
REG_GOOD_COUNT = 12  # 12, 13
REG_STOP_REASON = 14
REG_HEARTBEAT = 15
REG_ESTOP = 16  # 1 while the emergency stop is pressed (as last read)
REG_RESUME = 17  # Command.Resume (bwsd): 1: a Start request resumes the loaded program
REG_RESUMABLE = 18  # Status.Resumable (bwsd): 1 while a Start with resume is accepted
REG_PROGRAM = 19  # 19, 20: Command.ProgramId (bwsd): a stored program to load
REG_LOAD_REQUEST = 21  # Command.LoadRequest (bwsd): 1 loads Command.ProgramId
REG_PROGRAM_ID = 22  # 22, 23: Status.ProgramId (bwsd): the loaded program's id
REG_COUNT = 24

WRITABLE = (
    *range(REG_CNTRL_CMD, REG_UNIT_MODE_CHANGE_REQUEST + 1),
    REG_RESUME,
    *range(REG_PROGRAM, REG_LOAD_REQUEST + 1),
)
"""The command registers the PLC writes; every other register is read-only."""

REQUEST_REGISTERS = (REG_CMD_CHANGE_REQUEST, REG_UNIT_MODE_CHANGE_REQUEST, REG_LOAD_REQUEST)
"""The handshake registers: 1 asks, the daemon writes 0 back once it has taken the request."""

U16 = 0xFFFF
U32 = 0xFFFFFFFF

# The fields of Tags in register order, with the number of registers each takes.
_WIDTHS = (1, 1, 1, 1, 1, 1, 1, 2, 2, 2, 1, 1, 1, 1, 1, 2, 1, 2)


@dataclass(frozen=True)
class Tags:
    """Every tag's value, in register order after the map version."""

    cntrl_cmd: int = 0
    cmd_change_request: int = 0
    unit_mode: int = 0
    unit_mode_change_request: int = 0
    state_current: int = 0
    unit_mode_current: int = 0
    cmd_invalid: int = 0
    instruction_index: int = 0
    instruction_count: int = 0
    good_count: int = 0
    stop_reason: int = 0
    heartbeat: int = 0
    estop: int = 0
    resume: int = 0
    resumable: int = 0
    program: int = 0  # Command.ProgramId as the PLC wrote it
    load_request: int = 0
    program_id: int = 0  # the loaded program's


def u32_words(value: int) -> tuple[int, int]:
    """An unsigned 32-bit value (wrapped modulo 2**32) as two registers, high word first."""
    raw = value & U32
    return raw >> 16, raw & U16


def words_u32(high: int, low: int) -> int:
    """Two registers, high word first, as an unsigned 32-bit value."""
    return ((high & U16) << 16) | (low & U16)


def encode(tags: Tags) -> list[int]:
    """All REG_COUNT registers from address 0."""
    words = [MAP_VERSION]
    for value, width in zip(astuple(tags), _WIDTHS, strict=True):
        words.extend(u32_words(value) if width == 2 else (value & U16,))
    return words


def decode(words: Sequence[int]) -> Tags:
    """REG_COUNT registers read from address 0, as Tags (the PLC's view)."""
    if len(words) != REG_COUNT:
        raise ValueError(f"the PackML tags are {REG_COUNT} registers, got {len(words)}")
    if words[REG_MAP_VERSION] != MAP_VERSION:
        raise ValueError(f"map version {words[REG_MAP_VERSION]}, expected {MAP_VERSION}")
    values: list[int] = []
    at = REG_MAP_VERSION + 1
    for width in _WIDTHS:
        values.append(words_u32(words[at], words[at + 1]) if width == 2 else words[at])
        at += width
    return Tags(*values)
