"""The CiA 402 side of the CANopen map (docs/fieldbus-canopen.md): the objects of a drive
and of the I/O node, the controlword and statusword bits, the drive states, and the object
dictionaries built from them (pure). bwsd's backend and the mock loom's drives both build
their dictionaries here: the only copy of the map in code.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from enum import IntEnum

import numpy as np
from canopen import ObjectDictionary
from canopen.objectdictionary import ODVariable
from canopen.objectdictionary.datatypes import (
    DOMAIN,
    INTEGER8,
    INTEGER32,
    UNSIGNED8,
    UNSIGNED16,
    UNSIGNED32,
)

from bwsd.fieldbus.canopen_pdo import (
    CONTROLWORD,
    DONE_SEQ,
    ESTOP,
    FAULT_CODE,
    LAST_STROKE,
    POSITION,
    SETPOINT_SEQ,
    STATUSWORD,
    STROKES,
    TARGET,
    add_occupancy_words,
    add_pdo_records,
    drive_pdos,
    io_pdos,
)

MODE, MODE_DISPLAY, ERROR_CODE, HEARTBEAT = 0x6060, 0x6061, 0x603F, 0x1017
OCCUPANCY = 0x2000  # I/O node: the occupancy as one DOMAIN (by SDO; PDOs carry 0x2100)
OWNER, OWNER_PID = 0x2010, 0x2011  # I/O node: the claim (id, pid) of docs/fieldbus-canopen.md

DRIVE_OBJECTS: dict[int, tuple[str, int, str]] = {
    CONTROLWORD: ("controlword", UNSIGNED16, "rw"),
    STATUSWORD: ("statusword", UNSIGNED16, "ro"),
    MODE: ("modes of operation", INTEGER8, "rw"),
    MODE_DISPLAY: ("modes of operation display", INTEGER8, "ro"),
    TARGET: ("target position", INTEGER32, "rw"),
    POSITION: ("position actual value", INTEGER32, "ro"),
    ERROR_CODE: ("error code", UNSIGNED16, "ro"),
    HEARTBEAT: ("producer heartbeat time", UNSIGNED16, "rw"),
    LAST_STROKE: ("last stroke", INTEGER32, "ro"),
    DONE_SEQ: ("done sequence", UNSIGNED16, "ro"),
    SETPOINT_SEQ: ("set-point sequence", UNSIGNED16, "rw"),
    FAULT_CODE: ("fault code", UNSIGNED8, "ro"),
    STROKES: ("stroke count", UNSIGNED16, "ro"),
}
IO_OBJECTS: dict[int, tuple[str, int, str]] = {
    OCCUPANCY: ("occupancy", DOMAIN, "ro"),
    ESTOP: ("emergency stop", UNSIGNED8, "ro"),
    OWNER: ("owner", UNSIGNED32, "rw"),
    OWNER_PID: ("owner pid", UNSIGNED32, "rw"),
    HEARTBEAT: ("producer heartbeat time", UNSIGNED16, "rw"),
}

CW_DISABLE_VOLTAGE, CW_QUICK_STOP, CW_SHUTDOWN, CW_SWITCH_ON = 0x00, 0x02, 0x06, 0x07
CW_ENABLE, CW_NEW_SETPOINT, CW_RELATIVE, CW_FAULT_RESET = 0x0F, 0x10, 0x40, 0x80
SW_TARGET_REACHED, SW_SETPOINT_ACK = 0x0400, 0x1000
MODE_PROFILE_POSITION, MODE_HOMING = 1, 6
NMT_START = 0x01
# CiA 402 error codes (0x603F) of the bus-independent fault codes (0x2004)
ERROR_CODES = {1: 0x7500, 2: 0x8611, 3: 0x5530, 4: 0x8612, 5: 0x5441}


class Cia402(IntEnum):
    """The drive states, each as the value its statusword shows under the state's mask."""

    SWITCH_ON_DISABLED = 0x40
    READY_TO_SWITCH_ON = 0x21
    SWITCHED_ON = 0x23
    OPERATION_ENABLED = 0x27
    QUICK_STOP_ACTIVE = 0x07
    FAULT = 0x08

    @property
    def mask(self) -> int:
        return 0x4F if self in (Cia402.SWITCH_ON_DISABLED, Cia402.FAULT) else 0x6F

    @classmethod
    def of(cls, statusword: int) -> Cia402 | None:
        """The state a statusword shows (None: a transient state)."""
        return next((s for s in cls if statusword & s.mask == s.value), None)


# the controlword that moves a drive one step towards "operation enabled"
WALK = {
    Cia402.FAULT: CW_FAULT_RESET,
    Cia402.SWITCH_ON_DISABLED: CW_SHUTDOWN,
    Cia402.READY_TO_SWITCH_ON: CW_SWITCH_ON,
    Cia402.SWITCHED_ON: CW_ENABLE,
    Cia402.QUICK_STOP_ACTIVE: CW_DISABLE_VOLTAGE,
    None: CW_DISABLE_VOLTAGE,
}


def dictionary(objects: Mapping[int, tuple[str, int, str]], heartbeat: int = 0) -> ObjectDictionary:
    """An object dictionary of ``objects`` (index: name, data type, access); defaults 0."""
    od = ObjectDictionary()  # type: ignore[no-untyped-call]
    for index, (name, data_type, access) in objects.items():
        var = ODVariable(name, index, 0)
        var.data_type, var.access_type = data_type, access
        if data_type != DOMAIN:
            var.default = heartbeat if index == HEARTBEAT else 0
        od.add_object(var)
    return od


def drive_dictionary(node_id: int, heartbeat: int = 0) -> ObjectDictionary:
    """A drive's dictionary: its objects and the records of its PDOs."""
    od = dictionary(DRIVE_OBJECTS, heartbeat)
    add_pdo_records(od, drive_pdos(node_id))
    return od


def io_dictionary(cells: int, heartbeat: int = 0) -> ObjectDictionary:
    """The I/O node's dictionary for ``cells`` occupancy sensors, with its PDO records."""
    od = dictionary(IO_OBJECTS, heartbeat)
    add_occupancy_words(od, cells)
    add_pdo_records(od, io_pdos(cells))
    return od


def occupancy_bytes(occupied: Iterable[Iterable[bool]]) -> bytes:
    """The occupancy bitmap of 0x2000: row-major, least significant bit first."""
    bits = np.array([bool(v) for row in occupied for v in row], dtype=np.bool_)
    return np.packbits(bits, bitorder="little").tobytes()


def occupancy_word_values(occupied: Iterable[Iterable[bool]]) -> list[int]:
    """The occupancy as the words of 0x2100 (sub-index 1 first; cell 0 is bit 0)."""
    data = occupancy_bytes(occupied)
    data += bytes(-len(data) % 4)
    return [int.from_bytes(data[i : i + 4], "little") for i in range(0, len(data), 4)] or [0]
