"""facewrap.geometry.adjacency: edges, neighbours, boundaries, components."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp

import facewrap.geometry as geo
from facewrap.geometry.edge_runs import counting_sort_order, edge_runs
from facewrap.geometry.arrays import stable_sort_order
from facewrap.mesh import Mesh

from geometry_meshes import grid, icosphere


def test_edges_of_closed_sphere():
    V, T = icosphere(2)
    E = geo.edges(T)
    assert len(E) == 3 * len(T) // 2
    assert len(V) - len(E) + len(T) == 2          # Euler characteristic
    assert np.all(E[:, 0] < E[:, 1])
    assert len(np.unique(E, axis=0)) == len(E)
    assert geo.edges([[0, 0, 1]]).tolist() == [[0, 1]]


def test_edges_of_polygons_skips_diagonals():
    nx, ny = 5, 4
    quads = [[i * ny + j, (i + 1) * ny + j, (i + 1) * ny + j + 1, i * ny + j + 1]
             for i in range(nx - 1) for j in range(ny - 1)]
    mesh = Mesh(np.zeros((nx * ny, 3)), quads)
    E = geo.edges_of_polygons(mesh.face_offsets, mesh.face_indices)
    assert len(E) == (nx - 1) * ny + nx * (ny - 1)
    assert len(geo.edges(mesh.triangles)) == len(E) + len(quads)
    diagonals = {tuple(sorted((q[0], q[2]))) for q in quads}
    assert not diagonals & set(map(tuple, E.tolist()))
    mixed = geo.edges_of_polygons([0, 3, 3, 8], [0, 1, 2, 2, 1, 3, 4, 5])
    assert mixed.tolist() == [[0, 1], [0, 2], [1, 2], [1, 3], [2, 5], [3, 4], [4, 5]]
    with pytest.raises(ValueError, match="offsets"):
        geo.edges_of_polygons([0, 5], [0, 1, 2])


def test_vertex_adjacency():
    V, T = icosphere(1)
    A = geo.vertex_adjacency(T, len(V) + 1)
    assert isinstance(A, sp.csr_matrix) and A.shape == (len(V) + 1,) * 2
    assert (A != A.T).nnz == 0
    assert A.diagonal().sum() == 0
    assert A.sum() == 2 * len(geo.edges(T))
    degree = np.asarray(A.sum(axis=1)).ravel()
    assert set(degree[:-1]) == {5, 6} and degree[-1] == 0
    B = geo.vertex_adjacency(np.vstack([geo.edges(T), geo.edges(T)[:, ::-1]]),
                             len(V) + 1)
    assert (A != B).nnz == 0
    with pytest.raises(ValueError, match="T_or_edges"):
        geo.vertex_adjacency(np.zeros((3, 4), int), 5)
    with pytest.raises(ValueError, match="n"):
        geo.vertex_adjacency(T, -1)


def _shares_edge(T, i, j, k):
    a, b = T[i, j], T[i, (j + 1) % 3]
    return {a, b} <= set(T[k])


def test_triangle_adjacency_closed_and_open():
    _, T = icosphere(2)
    TT = geo.triangle_adjacency(T)
    assert TT.shape == T.shape and TT.dtype == np.int64 and np.all(TT >= 0)
    i, j = np.indices(T.shape).reshape(2, -1)
    assert all(_shares_edge(T, a, b, TT[a, b]) for a, b in zip(i, j))
    assert all(a in TT[TT[a, b]] for a, b in zip(i, j))       # symmetric
    assert np.all(TT != np.arange(len(T))[:, None])
    _, Tg = grid(5, 4)
    TTg = geo.triangle_adjacency(Tg)
    assert np.count_nonzero(TTg == -1) == len(geo.boundary_edges(Tg))


def test_triangle_adjacency_non_manifold():
    T = np.array([[0, 1, 2], [1, 0, 3], [0, 1, 4], [2, 1, 5]])   # edge 0-1 thrice
    TT = geo.triangle_adjacency(T)
    fan = [TT[0, 0], TT[1, 0], TT[2, 0]]
    assert sorted(fan) == [0, 1, 2] and all(f != k for k, f in enumerate(fan))
    assert TT[0, 1] == 3 and TT[3, 0] == 0


def test_boundary_edges_and_vertices():
    nx, ny = 6, 5
    V, T = grid(nx, ny)
    B = geo.boundary_edges(T)
    assert len(B) == 2 * (nx - 1 + ny - 1)
    directed = set(map(tuple, np.concatenate([T[:, [0, 1]], T[:, [1, 2]],
                                              T[:, [2, 0]]]).tolist()))
    assert set(map(tuple, B.tolist())) <= directed
    mask = geo.boundary_vertices(T, len(V) + 1)
    x, y = V[:, 0], V[:, 1]
    expected = (x == 0) | (y == 0) | (x == nx - 1) | (y == ny - 1)
    np.testing.assert_array_equal(mask[:-1], expected)
    assert not mask[-1]
    assert len(geo.boundary_edges(icosphere(1)[1])) == 0


def _check_loop(loop, B):
    pairs = set(zip(loop.tolist(), np.roll(loop, -1).tolist()))
    assert pairs <= set(map(tuple, B.tolist()))
    return pairs


def test_boundary_loops_with_hole():
    V, T = grid(8, 8)
    centroid = V[T].mean(axis=1)
    hole = (np.abs(centroid[:, 0] - 3.5) < 1.5) & (np.abs(centroid[:, 1] - 3.5) < 1.5)
    T = T[~hole]
    loops = geo.boundary_loops(T)
    B = geo.boundary_edges(T)
    assert [len(loop) for loop in loops] == [28, 12]
    used = set()
    for loop in loops:
        used |= _check_loop(loop, B)
        assert len(set(loop.tolist())) == len(loop)
    assert len(used) == len(B)
    assert geo.boundary_loops(icosphere(1)[1]) == []
    assert geo.boundary_loops(np.zeros((0, 3), int)) == []


def test_boundary_loops_touching_at_a_vertex():
    T = np.array([[0, 1, 2], [0, 3, 4]])       # bow tie around vertex 0
    loops = geo.boundary_loops(T)
    B = geo.boundary_edges(T)
    assert sum(len(loop) for loop in loops) == 6
    used = set().union(*(_check_loop(loop, B) for loop in loops))
    assert len(used) == 6


def test_boundary_loops_of_a_large_grid():
    _, T = grid(300, 300)
    loops = geo.boundary_loops(T)
    assert [len(loop) for loop in loops] == [4 * 299]


def test_connected_components():
    V1, T1 = icosphere(1)
    T = np.vstack([T1, T1 + len(V1)])
    labels = geo.connected_components(T, 2 * len(V1) + 1)
    assert labels.dtype == np.int64
    np.testing.assert_array_equal(labels, np.repeat([0, 1, 2], [len(V1), len(V1), 1]))


def test_counting_sort_order_is_the_stable_argsort():
    keys = np.random.default_rng(1).integers(0, 40, 3000)
    np.testing.assert_array_equal(counting_sort_order(keys, 40),
                                  np.argsort(keys, kind="stable"))
    assert counting_sort_order(np.zeros(0, np.int64), 5).dtype == np.int64


def _edge_runs_by_one_sort(T):
    """edge_runs as one stable sort of packed edge keys (self-loops first, last
    one first): the order the counting passes must reproduce."""
    a, b = T.reshape(-1), T[:, [1, 2, 0]].reshape(-1)
    n = int(T.max()) + 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    key[a == b] = -1 - np.arange(np.count_nonzero(a == b))
    order, s = stable_sort_order(key)
    return order, np.r_[True, s[1:] != s[:-1]]


@pytest.mark.parametrize("seed", range(20))
def test_edge_runs_counted_match_one_sort(seed):
    # small vertex ranges: repeated, non-manifold and self-loop edges are common
    rng = np.random.default_rng(seed)
    T = rng.integers(0, int(rng.integers(2, 30)), (int(rng.integers(1, 80)), 3))
    runs, (order, starts) = edge_runs(T), _edge_runs_by_one_sort(T)
    np.testing.assert_array_equal(runs.order, order)
    np.testing.assert_array_equal(runs.starts, starts)
    assert runs.order.dtype == np.int64


def _check_run_edges(T, runs):
    """Every run's ``ends`` are its half-edges' two vertices, smaller first, and
    ``sizes``/``crowded`` count its half-edges, as read from the triangles."""
    tail, head = T.reshape(-1), T[:, [1, 2, 0]].reshape(-1)
    run = np.cumsum(runs.starts) - 1
    lo, hi = np.minimum(tail, head)[runs.order], np.maximum(tail, head)[runs.order]
    np.testing.assert_array_equal(runs.ends[run, 0], lo)
    np.testing.assert_array_equal(runs.ends[run, 1], hi)
    np.testing.assert_array_equal(runs.sizes(), np.bincount(run))
    assert runs.crowded() == bool((np.bincount(run) > 2).any())


@pytest.mark.parametrize("seed", range(20))
def test_edge_runs_name_each_edge_and_count_it(seed):
    rng = np.random.default_rng(100 + seed)
    T = rng.integers(0, int(rng.integers(2, 30)), (int(rng.integers(1, 80)), 3))
    _check_run_edges(T, edge_runs(T))


def test_edge_runs_name_the_edges_of_sparse_vertex_ids_and_self_loops():
    T = np.array([[0, 10**7, 5], [5, 10**7, 0], [3, 3, 10**7], [7, 7, 7]])
    _check_run_edges(T, edge_runs(T))
    T = np.array([[0, 1, 2], [2, 2, 1], [1, 0, 3]])     # the counting passes
    _check_run_edges(T, edge_runs(T))
    assert edge_runs(T).crowded()          # edge 1-2: triangle 0, and twice in 1
    assert not edge_runs([[0, 1, 2], [1, 0, 3]]).crowded()
    assert edge_runs([[0, 1, 2], [1, 0, 3], [0, 1, 4]]).crowded()


def test_edge_runs_with_sparse_vertex_ids_sort_the_keys():
    # ids far beyond the edge count take the sort, with the same answer
    T = np.array([[0, 10**7, 5], [5, 10**7, 0], [3, 3, 10**7]])
    runs, (order, starts) = edge_runs(T), _edge_runs_by_one_sort(T)
    np.testing.assert_array_equal(runs.order, order)
    np.testing.assert_array_equal(runs.starts, starts)
