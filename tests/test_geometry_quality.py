"""facewrap.geometry.quality: flipped triangles, area change, stretch, angles."""

import numpy as np
import pytest

from facewrap.geometry import triangle_quality, triangle_to_vertex

from geometry_meshes import flat_square


def test_flipped_triangle_is_counted():
    V, T = flat_square(5)
    W = V.copy()
    # push one interior vertex across a neighbour in-plane: its triangles fold over
    v = 12
    W[v, 0] += 4.0
    q = triangle_quality(W, T, V)
    assert q.flipped.sum() > 0
    assert q.flipped.tolist() == (np.einsum(
        "ij,ij->i", np.cross(W[T[:, 1]] - W[T[:, 0]], W[T[:, 2]] - W[T[:, 0]]),
        np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]])) < 0).tolist()
    assert triangle_quality(V, T, V).flipped.sum() == 0


def test_similarity_of_reference_is_no_change():
    V, T = flat_square(6)
    V = V + np.random.default_rng(0).normal(0, 0.3, V.shape)   # not planar
    a = 0.7
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    W = 2.5 * V @ R.T + [10, -3, 4]
    q = triangle_quality(W, T, V)
    assert not q.flipped.any()
    assert np.allclose(q.area_ratio, 1.0) and np.allclose(q.stretch, 1.0)
    # without alignment, the global scale shows as area change but not as stretch
    raw = triangle_quality(W, T, V, align=False)
    assert np.allclose(raw.area_ratio, 2.5 ** 2) and np.allclose(raw.stretch, 1.0)


def test_known_stretch_and_angles():
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]])
    q = triangle_quality(V, [[0, 1, 2]], V * [2.0, 1.0, 1.0], align=False)
    assert q.min_angle[0] == pytest.approx(60.0)
    assert q.stretch[0] == pytest.approx(2.0) and q.area_ratio[0] == pytest.approx(0.5)
    deg = triangle_quality(np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0.]]), [[0, 1, 2]])
    assert deg.degenerate.tolist() == [True] and deg.min_angle.tolist() == [0.0]
    s = triangle_quality(V, [[0, 1, 2]], V).summary()
    assert s["triangles_flipped"] == 0 and s["triangles_stretch_max"] == pytest.approx(1.0)


def test_triangle_to_vertex_reductions():
    T = np.array([[0, 1, 2], [0, 2, 3]])
    assert triangle_to_vertex([1.0, 3.0], T, 4, "max").tolist() == [3.0, 1.0, 3.0, 3.0]
    assert triangle_to_vertex([1.0, np.nan], T, 4).tolist()[:3] == [1.0, 1.0, 1.0]
    with pytest.raises(ValueError, match="reduce"):
        triangle_to_vertex([1.0, 3.0], T, 4, "sum")
