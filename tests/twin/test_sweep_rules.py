"""The rules of the sweep on hand-built geometry (docs/twin.md, "The sweep, exactly")."""

from __future__ import annotations

import pytest

from bwsd.twin import Machine, Shift, Twin, Weft

# One warp in cell (0, 0) of a 1 x 3 matrix, fell right below the guide (c_mat = 1), d = 0.
# ROW 0:+1 sweeps the triangle B=(0,0,0), A1=(0,0,100), A2=(10,0,100), all in the plane y = 0:
# a point's side is the sign of its y.
LINE = Machine(rows=1, cols=3, pitch_x=10, pitch_y=10, d_mat=100, c_mat=1.0)
RIGHT = Shift("row", ((0, 1),))


def _twin_with_weft(weft: Weft) -> Twin:
    twin = Twin(LINE, [(0, 0)], diameter=0.0)
    twin.apply(weft)
    return twin


def test_endpoint_on_the_plane_counts_as_positive_so_a_crossing_from_below_is_a_contact():
    twin = _twin_with_weft(Weft(x=2, y=-2.5, z=50, angle=90, length=5))  # y from -5 to 0
    pred = twin.apply(RIGHT)
    assert len(pred.contacts) == 1
    hit = twin.skeleton().node_positions()[pred.contacts[0].hit_node]
    assert hit.tolist() == [2.0, 0.0, 50.0]  # exactly the weft's endpoint


def test_endpoint_on_the_plane_with_the_other_above_is_no_crossing():
    twin = _twin_with_weft(Weft(x=2, y=2.5, z=50, angle=90, length=5))  # y from 0 to 5
    assert twin.apply(RIGHT).contacts == ()


def test_coplanar_segment_is_never_a_contact():
    twin = _twin_with_weft(Weft(x=3, y=0, z=50, angle=0, length=2))  # in the plane y = 0
    assert twin.apply(RIGHT).contacts == ()


def test_crossing_outside_the_triangle_is_no_contact():
    # x = 8 at z = 50 lies beyond the final edge B-A2 (x = z / 10 there is 5).
    twin = _twin_with_weft(Weft(x=8, y=0, z=50, angle=90, length=4))
    assert twin.apply(RIGHT).contacts == ()


def test_touch_of_the_final_edge_counts_once_and_the_next_move_does_not_count_it_again():
    # The weft crosses y = 0 at (5, 0, 50), on the final moving segment B-A2: t = 1.
    twin = _twin_with_weft(Weft(x=5, y=0, z=50, angle=90, length=2))
    first = twin.apply(RIGHT)
    assert len(first.contacts) == 1
    sk = twin.skeleton()
    assert sk.node_positions()[first.contacts[0].hit_node].tolist() == [5.0, 0.0, 50.0]
    assert sk.yarns[0].nodes[-1].tolist() == [10.0, 0.0, 100.0]
    back = twin.apply(Shift("row", ((0, -1),)))
    assert back.contacts == ()


def test_crossing_in_the_middle_of_the_move_restarts_from_the_contact_time():
    # Crossing at (2, 0, 50): the moving segment passes there when the guide is at x = 4.
    twin = _twin_with_weft(Weft(x=2, y=-1, z=50, angle=90, length=4))
    pred = twin.apply(RIGHT)
    assert len(pred.contacts) == 1
    warp = twin.skeleton().yarns[0]
    # fell, X (= Y since d = 0), free node at the new guide
    assert warp.nodes.tolist() == [[0.0, 0.0, 0.0], [2.0, 0.0, 50.0], [10.0, 0.0, 100.0]]


def test_contact_node_rests_one_diameter_back_against_the_move():
    twin = Twin(LINE, [(0, 0)], diameter=1.0)
    twin.apply(Weft(x=2, y=-1, z=50, angle=90, length=4))  # 2 mm clear of the warp at x = 0
    pred = twin.apply(RIGHT)
    nodes = twin.skeleton().node_positions()
    x, y = nodes[pred.contacts[0].moving_node], nodes[pred.contacts[0].hit_node]
    # the move is along +x, the weft along y: n = (1, 0, 0), X = Y - d n
    assert y.tolist() == [2.0, 0.0, 50.0]
    assert x.tolist() == [1.0, 0.0, 50.0]  # cos 90 degrees is exactly 0 on the grid


def test_yarn_never_hits_itself():
    twin = Twin(LINE, [(0, 0)], diameter=0.0)
    for _ in range(3):
        twin.apply(RIGHT)
        twin.apply(Shift("row", ((0, -1),)))
    assert twin.contact_count == 0


@pytest.mark.parametrize(("offset", "expected"), [(-(2**-32), 0), (2**-32, 1), (0.0, 1)])
def test_a_hair_off_the_plane_is_decided_exactly(offset, expected):
    """The weft's upper end one grid step (2^-32 mm) below, above or on the plane y = 0."""
    twin = _twin_with_weft(Weft(x=2, y=-2.5 + offset, z=50, angle=90, length=5))
    upper_y = twin.skeleton().yarns[1].nodes[1][1]
    assert (upper_y > 0, upper_y == 0, upper_y < 0) == (offset > 0, offset == 0, offset < 0)
    assert len(twin.apply(RIGHT).contacts) == expected
