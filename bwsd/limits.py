"""Limits of the wire formats, checked when a config is loaded and when a bus is built (pure).

Kept apart from ``bwsd.fieldbus`` so that ``bwsd.config`` can check them without importing
the bus package (which imports the config).
"""

from __future__ import annotations

MODBUS_AXIS_BASE = 100  # holding register of axis 0's block (docs/fieldbus-modbus.md)
MODBUS_AXIS_STRIDE = 16  # holding registers per axis block
MODBUS_MAX_CELLS = 0xFFFF  # discrete inputs 0 .. 65535 hold the cells and the e-stop
MODBUS_MAX_AXES = (0x10000 - MODBUS_AXIS_BASE) // MODBUS_AXIS_STRIDE  # registers end at 65535
