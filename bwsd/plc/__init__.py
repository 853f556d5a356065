"""The PackML tags for the plant PLC, served over Modbus TCP (docs/plc.md)."""

from __future__ import annotations

from bwsd.plc.reasons import StopReason
from bwsd.plc.registers import MAP_VERSION, REG_COUNT, Tags, decode, encode
from bwsd.plc.tags import PlcError, PlcTags, plc_tags

__all__ = [
    "MAP_VERSION",
    "REG_COUNT",
    "PlcError",
    "PlcTags",
    "StopReason",
    "Tags",
    "decode",
    "encode",
    "plc_tags",
]
