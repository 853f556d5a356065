"""What every backend shares (bwsd.fieldbus.base)."""

from __future__ import annotations

from itertools import islice

import pytest

from bwsd.fieldbus.base import poll_waits


@pytest.mark.parametrize(
    ("most", "waits"),
    [
        (0.01, [0.002, 0.004, 0.008, 0.01, 0.01, 0.01]),
        (0.05, [0.002, 0.004, 0.008, 0.016, 0.032, 0.05]),
        (0.001, [0.001] * 6),  # a bound under the first wait is the first wait too
    ],
)
def test_the_waits_of_a_move_under_way_double_from_2_ms_up_to_poll_max(most, waits):
    assert list(islice(poll_waits(most), 6)) == pytest.approx(waits)
