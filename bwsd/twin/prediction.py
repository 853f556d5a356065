"""What the twin hands out: predictions (a change, ready to commit) and snapshots (a state)."""

from __future__ import annotations

import json
import struct
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from functools import cached_property
from typing import Any

import numpy as np

from bwsd.errors import TwinError
from bwsd.twin.instructions import Instruction
from bwsd.twin.machine import Machine
from bwsd.twin.skeleton import ContactData, FloatArray, IntArray

Xyz = tuple[float, float, float]


def mm(grid: np.ndarray[Any, Any]) -> FloatArray:
    """Grid coordinates (int64) in millimetres (exact: a power-of-two scale)."""
    out: FloatArray = np.ldexp(grid.astype(np.float64), -32)
    return out


def _frozen(array: np.ndarray[Any, Any]) -> Any:
    array.flags.writeable = False
    return array


@dataclass(frozen=True)
class NodeInsert:
    """A node added by an instruction: into ``yarn`` right after node ``after``."""

    yarn: int
    node: int
    after: int
    xyz: Xyz


@dataclass(frozen=True, eq=False)
class Prediction:
    """The would-be result of one instruction, made on one state of one twin.

    The tables are read-only arrays; the dict and tuple views are built when first read.
    """

    index: int  # 1-based instruction number
    instruction: Instruction
    takeup: float
    new_yarns: tuple[int, ...]
    occupancy: IntArray  # after the instruction
    contact_table: IntArray  # (k, 5): instruction, moving yarn, X, hit yarn, Y
    node_table: IntArray  # (n, 6): node, yarn, after, x, y, z (grid), in yarn order
    moved_table: IntArray  # (m, 6): warp, x, y, z (grid) of its free node, row, col
    length_table: FloatArray  # (m,): change of each moved warp's path length (mm)
    record: bytes = field(repr=False)
    state: object = field(repr=False)
    takeup_exact: Fraction = field(repr=False)
    angles: tuple[float, ...] = field(repr=False)

    @classmethod
    def build(
        cls,
        index: int,
        instruction: Instruction,
        result: Any,
        takeup: Fraction,
        angles: tuple[float, ...],
        state: object,
        machine: Machine,
    ) -> Prediction:
        """From the kernel's description of a predicted instruction."""
        record, contacts, nodes, (moved, change), occupancy, first_new, yarns = result
        return cls(
            index=index,
            instruction=instruction,
            takeup=float(takeup),
            new_yarns=tuple(range(first_new, yarns)),
            occupancy=_frozen(
                np.frombuffer(occupancy, dtype=np.int32)
                .reshape(machine.rows, machine.cols)
                .astype(np.int64)
            ),
            contact_table=_frozen(
                np.frombuffer(contacts, dtype=np.int32).reshape(-1, 5).astype(np.int64)
            ),
            node_table=np.frombuffer(nodes, dtype=np.int64).reshape(-1, 6),
            moved_table=np.frombuffer(moved, dtype=np.int64).reshape(-1, 6),
            length_table=_frozen(np.frombuffer(change, dtype=np.float64) / 2.0**32),
            record=record,
            state=state,
            takeup_exact=takeup,
            angles=angles,
        )

    @cached_property
    def contacts(self) -> tuple[ContactData, ...]:
        return tuple(ContactData(*row) for row in self.contact_table.tolist())

    @cached_property
    def inserted(self) -> tuple[NodeInsert, ...]:
        """Nodes added to existing yarns, in yarn order (new yarns left out)."""
        first_new = self.new_yarns[0] if self.new_yarns else None
        xyz = mm(self.node_table[:, 3:]).tolist()
        return tuple(
            NodeInsert(yarn, node, after, tuple(p))
            for (node, yarn, after), p in zip(self.node_table[:, :3].tolist(), xyz, strict=True)
            if first_new is None or yarn < first_new
        )

    @cached_property
    def free_nodes(self) -> dict[int, Xyz]:
        """Moved warp -> its free node's new position."""
        xyz = mm(self.moved_table[:, 1:4]).tolist()
        return {w: tuple(p) for w, p in zip(self.moved_table[:, 0].tolist(), xyz, strict=True)}

    @cached_property
    def cases(self) -> dict[int, tuple[int, int]]:
        """Moved warp -> its cell after the instruction."""
        return {w: (r, c) for w, r, c in self.moved_table[:, [0, 4, 5]].tolist()}

    @cached_property
    def length_change(self) -> dict[int, float]:
        """Moved warp -> change of its path length (mm), fixed polyline and free segment."""
        return dict(zip(self.moved_table[:, 0].tolist(), self.length_table.tolist(), strict=True))


MAGIC = b"BWSDTWIN"
FORMAT = 1


@dataclass(frozen=True)
class Snapshot:
    """A committed state of a twin, as bytes: ``MAGIC``, a CRC-32 of the rest, the header's
    length, the header (JSON: machine, diameter, fill, weft angles, take-up, instructions
    done) and the kernel's arrays."""

    data: bytes = field(repr=False)

    @classmethod
    def make(
        cls,
        machine: Machine,
        diameter: float,
        fill: Sequence[tuple[int, int]],
        angles: Sequence[float | None],
        takeup: Fraction,
        done: int,
        kernel: bytes,
    ) -> Snapshot:
        header = {
            "format": FORMAT,
            "machine": machine.as_dict(),
            "diameter": diameter,
            "fill": [list(c) for c in fill],
            "angles": list(angles),
            "takeup": str(takeup),
            "done": done,
        }
        text = json.dumps(header, sort_keys=True).encode()
        body = struct.pack("<I", len(text)) + text + kernel
        return cls(MAGIC + struct.pack("<I", zlib.crc32(body)) + body)

    def to_bytes(self) -> bytes:
        return self.data

    @classmethod
    def from_bytes(cls, data: bytes) -> Snapshot:
        """A snapshot from ``to_bytes``; TwinError if the bytes are not one, or damaged."""
        snap = cls(bytes(data))
        _ = snap.header  # checks magic, checksum and header
        return snap

    @cached_property
    def header(self) -> dict[str, Any]:
        data = self.data
        if len(data) < 16 or data[:8] != MAGIC:
            raise TwinError("not a twin snapshot")
        (crc,) = struct.unpack("<I", data[8:12])
        if zlib.crc32(data[12:]) != crc:
            raise TwinError("twin snapshot damaged (checksum mismatch)")
        (size,) = struct.unpack("<I", data[12:16])
        try:
            header: dict[str, Any] = json.loads(data[16 : 16 + size])
        except ValueError:
            raise TwinError("twin snapshot damaged (header)") from None
        if header.get("format") != FORMAT:
            raise TwinError(f"twin snapshot format {header.get('format')} is not {FORMAT}")
        return header

    @property
    def kernel(self) -> bytes:
        (size,) = struct.unpack("<I", self.data[12:16])
        return self.data[16 + size :]

    @property
    def done(self) -> int:
        """Instructions done in this state."""
        return int(self.header["done"])

    def check(self, machine: Machine, diameter: float) -> None:
        """Refuse a snapshot of another machine or yarn diameter."""
        header = self.header
        if header["machine"] != machine.as_dict() or header["diameter"] != diameter:
            raise TwinError("the snapshot is of another machine or yarn diameter")
