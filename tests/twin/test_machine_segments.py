"""A machine's line segments: each inside the matrix, no two sharing a cell of one line."""

from __future__ import annotations

import itertools
import random

import pytest

from bwsd.twin.machine import Machine, Segment, first_overlap


def machine(*segments: Segment, rows: int = 8, cols: int = 8) -> Machine:
    return Machine(
        rows=rows, cols=cols, pitch_x=1.0, pitch_y=1.0, d_mat=10.0, c_mat=0.5, segments=segments
    )


def row(line: int, lo: int, hi: int) -> Segment:
    return Segment("row", line, lo, hi)


def col(line: int, lo: int, hi: int) -> Segment:
    return Segment("col", line, lo, hi)


def test_adjacent_segments_of_a_line_are_accepted():
    """Cells 0..3 and 4..7 of a row touch without sharing a cell; so do 0..1, 2..3 in reverse."""
    m = machine(row(3, 4, 7), row(3, 0, 3), row(2, 2, 3), row(2, 0, 1))
    assert len(m.segments) == 4


def test_segments_of_other_lines_or_the_other_axis_may_cover_the_same_cells():
    machine(row(3, 0, 3), row(4, 0, 3), col(3, 0, 3), col(0, 3, 7))


@pytest.mark.parametrize(
    ("segments", "message"),
    [
        ((row(3, 0, 3), row(3, 3, 5)), r"segment ROW 3\[3..5\] overlaps ROW 3\[0..3\]"),
        ((row(3, 3, 5), row(3, 0, 3)), r"segment ROW 3\[0..3\] overlaps ROW 3\[3..5\]"),
        ((col(1, 0, 7), col(1, 2, 3)), r"segment COL 1\[2..3\] overlaps COL 1\[0..7\]"),
        ((col(1, 2, 3), col(1, 0, 7)), r"segment COL 1\[0..7\] overlaps COL 1\[2..3\]"),
        ((row(0, 1, 2), row(0, 1, 2)), r"segment ROW 0\[1..2\] overlaps ROW 0\[1..2\]"),
    ],
)
def test_an_overlap_is_refused_naming_both_segments(segments, message):
    with pytest.raises(ValueError, match=message):
        machine(*segments)


def test_an_overlap_is_found_however_far_apart_the_two_lie_in_the_sorted_order():
    """A long segment overlaps one that starts several segments after it along the line."""
    long = row(5, 0, 6)
    between = [row(6, 0, 1), col(5, 0, 1), row(4, 0, 7)]
    with pytest.raises(ValueError, match=r"ROW 5\[6..7\] overlaps ROW 5\[0..6\]"):
        machine(long, *between, row(5, 6, 7))
    with pytest.raises(ValueError, match=r"ROW 5\[0..6\] overlaps ROW 5\[6..7\]"):
        machine(row(5, 6, 7), *between, long)


def test_of_several_overlaps_the_pair_declared_earliest_is_named():
    segments = (row(0, 0, 3), row(1, 0, 3), row(1, 3, 4), row(0, 2, 5))
    with pytest.raises(ValueError, match=r"segment ROW 1\[3..4\] overlaps ROW 1\[0..3\]"):
        machine(*segments)


def test_a_segment_outside_the_matrix_is_named_before_any_overlap():
    with pytest.raises(ValueError, match=r"segment ROW 8\[0..1\]: row 8 is outside the matrix"):
        machine(row(0, 0, 3), row(0, 1, 2), row(8, 0, 1))
    with pytest.raises(ValueError, match=r"segment COL 0\[3..3\]: needs 0 <= first < last <= 7"):
        machine(col(0, 3, 3))


def _brute_force_overlaps(segments: list[Segment]) -> bool:
    return any(a.overlaps(b) for a, b in itertools.combinations(segments, 2))


@pytest.mark.parametrize("seed", range(40))
def test_neighbours_in_sorted_order_find_exactly_the_overlaps_every_pair_finds(seed):
    """Random segments on a few short lines, in random order: against comparing every pair."""
    rng = random.Random(seed)
    segments = []
    for _ in range(rng.randint(2, 9)):
        lo = rng.randint(0, 10)
        segments.append(
            Segment(rng.choice(("row", "col")), rng.randint(0, 2), lo, rng.randint(lo + 1, 12))
        )
    pair = first_overlap(segments)
    assert (pair is not None) == _brute_force_overlaps(segments)
    if pair is not None:
        later, earlier = pair
        assert later.overlaps(earlier)
        assert segments.index(earlier) <= segments.index(later)


def test_a_full_tiling_of_every_line_is_accepted():
    """Every row and column of a 12x12 matrix cut into pairs of cells: 144 segments, none
    overlapping, declared in shuffled order."""
    tiles = [
        Segment(axis, line, lo, lo + 1)
        for axis in ("row", "col")
        for line in range(12)
        for lo in range(0, 12, 2)
    ]
    random.Random(7).shuffle(tiles)
    assert len(machine(*tiles, rows=12, cols=12).segments) == 144
    with pytest.raises(ValueError, match=r"overlaps"):
        machine(*tiles, col(11, 1, 2), rows=12, cols=12)
