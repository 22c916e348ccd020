"""facewrap.report.cameras: views are rotations and point where they say."""

import numpy as np
import pytest

from facewrap.report import frame_from_axes, render_mesh, view_rotation


def test_view_rotations_are_rotations_and_views_point_right():
    for v in ("front", "side", "three_quarter", (20.0, -30.0)):
        R = view_rotation(v)
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1)
    assert np.allclose(view_rotation("front"), np.eye(3))
    assert np.allclose(view_rotation("top") @ [0, 1, 0], [0, 0.017452, 0.999848], atol=1e-5)
    with pytest.raises(ValueError, match="view"):
        view_rotation("diagonal")
    F = frame_from_axes(up=(0, 0, 1), front=(1, 0, 0))
    assert np.allclose(F @ [1, 0, 0], [0, 0, 1]) and np.allclose(F @ [0, 0, 1], [0, 1, 0])
    with pytest.raises(ValueError, match="parallel"):
        frame_from_axes(up=(0, 0, 1), front=(0, 0, 2))


def pointer():
    """A triangle pointing up (+y) and lying toward +x, in the z = 0 plane."""
    return np.array([[0, 0, 0], [4, 0, 0], [0, 8, 0.]]), np.array([[0, 1, 2]])


def test_front_view_has_y_up_and_x_right():
    V, T = pointer()
    img = render_mesh((V, T), size=(40, 40), supersample=1)
    covered = (img != 255).any(2)
    rows, cols = np.nonzero(covered)
    # the tip (0, 8) is at the top left; the wide end at the bottom
    top = rows.min()
    assert cols[rows == top].mean() < 20 and covered[rows.max()].sum() > covered[top].sum()
    assert covered[:, :20].sum() > covered[:, 20:].sum()


def test_side_view_sees_the_face_toward_the_left():
    # a nose sticking out toward +z on a plane: from the side it points left
    V = np.array([[0, -5, 0], [0, 5, 0], [0, 0, 8.], [0.1, 0, 0]])
    T = [[0, 1, 2], [0, 1, 3]]
    img = render_mesh((V, T), view="side", size=(40, 40), supersample=1)
    cols = np.nonzero((img != 255).any(2))[1]
    assert cols.min() < 8 and cols.max() > 30   # spans width: tip at left, base right
    covered = (img != 255).any(2)
    tip_rows = np.nonzero(covered[:, cols.min()])[0]
    assert abs(tip_rows.mean() - 19.5) < 3
