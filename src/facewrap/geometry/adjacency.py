"""Connectivity of meshes: edges, neighbours, boundaries and components.

This module owns everything that depends on the mesh's topology only (triangle or
polygon indices, never positions): unique edges of triangles and of polygons, vertex
and triangle adjacency, boundary edges, vertices and loops, and connected
components.  Everything is vectorised over edges and triangles.

Edges are undirected and returned as sorted pairs ``(i, j)`` with ``i < j`` unless
said otherwise; self-loops (an edge from a vertex to itself, found only in
degenerate triangles such as ``(0, 0, 1)``) are dropped.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from facewrap.geometry.arrays import stable_sort_order, unique_integers
from facewrap.geometry.checks import as_count, as_index_vector, as_triangles, as_triangles_or_edges
from facewrap.geometry.edge_runs import EdgeRuns, edge_runs, half_edges

__all__ = [
    "adjacency_matrix", "unique_edges", "edges", "edges_of_polygons", "vertex_adjacency",
    "triangle_adjacency", "boundary_edges", "boundary_vertices", "boundary_loops",
    "connected_components",
]


def _unique_undirected(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(e, 2) sorted unique pairs of the undirected edges ``a - b``, no self-loops."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    keep = lo != hi
    lo, hi = lo[keep], hi[keep]
    if len(lo) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    n = int(hi.max()) + 1
    key = unique_integers(lo * n + hi)   # one sort of int64 keys, not unique(axis=0)
    return np.stack([key // n, key % n], axis=1)


def _edges(T: np.ndarray) -> np.ndarray:
    return _unique_undirected(*half_edges(T))


def adjacency_matrix(E: np.ndarray, n: int) -> sp.csr_matrix:
    """Adjacency matrix of unique edges, without input checks.

    Parameters
    ----------
    E : (e, 2) int64
        Unique undirected edges (each once, no self-loops), indices in ``[0, n)``;
        for example from :func:`unique_edges`.
    n : int
        Number of vertices.

    Returns
    -------
    A : (n, n) scipy.sparse.csr_matrix
        Symmetric, 1.0 at each edge.
    """
    rows = np.concatenate([E[:, 0], E[:, 1]])
    cols = np.concatenate([E[:, 1], E[:, 0]])
    return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))


def unique_edges(T_or_edges: np.ndarray, columns: int) -> np.ndarray:
    """Unique undirected edges of triangles or of an edge list, without input checks.

    Parameters
    ----------
    T_or_edges : (t, 3) int64 or (e, 2) int64
        As returned by :func:`~facewrap.geometry.checks.as_triangles_or_edges`.
    columns : {3, 2}
        Its number of columns (3: triangles, 2: edges).

    Returns
    -------
    E : (u, 2) int64
        Sorted pairs ``i < j``, each once, no self-loops.
    """
    if columns == 3:
        return _edges(T_or_edges)
    return _unique_undirected(T_or_edges[:, 0], T_or_edges[:, 1])


def _boundary_mask(T: np.ndarray) -> np.ndarray:
    """(3 t,) bool: half-edges whose undirected edge belongs to one triangle only."""
    a, b = half_edges(T)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(T.max()) + 1
    _, inverse, counts = unique_integers(lo * n + hi, return_inverse=True,
                                        return_counts=True)
    return (counts[inverse] == 1) & (a != b)


def edges(T) -> np.ndarray:
    """Unique undirected edges of triangles.

    Parameters
    ----------
    T : (t, 3) int64
        Triangles; an edge shared by several of them is returned once.

    Returns
    -------
    E : (e, 2) int64
        Sorted pairs ``i < j`` in lexicographic order; self-loops dropped.

    Examples
    --------
    >>> edges([[0, 1, 2], [0, 2, 3]]).tolist()
    [[0, 1], [0, 2], [0, 3], [1, 2], [2, 3]]
    """
    return _edges(as_triangles(T))


def edges_of_polygons(offsets, indices) -> np.ndarray:
    """Unique undirected edges of polygons: the sides only, no diagonals.

    On a quad mesh these are the artist's edges, unlike :func:`edges` of its
    triangulation, which adds one diagonal per quad.

    Parameters
    ----------
    offsets : (m + 1,) int64
        Polygon ``f`` is ``indices[offsets[f]:offsets[f + 1]]`` (as
        :attr:`facewrap.mesh.Mesh.face_offsets`).
    indices : (offsets[-1],) int64
        Polygon corners (as :attr:`facewrap.mesh.Mesh.face_indices`).

    Returns
    -------
    E : (e, 2) int64
        Sorted pairs ``i < j`` in lexicographic order.

    Examples
    --------
    >>> edges_of_polygons([0, 4], [0, 1, 2, 3]).tolist()
    [[0, 1], [0, 3], [1, 2], [2, 3]]
    """
    offsets = as_index_vector(offsets, "offsets")
    indices = as_index_vector(indices, "indices")
    if len(offsets) == 0 or offsets[0] != 0 or offsets[-1] != len(indices) \
            or np.any(np.diff(offsets) < 0):
        raise ValueError("offsets must start at 0, not decrease, and end at "
                         "len(indices)")
    sizes = np.diff(offsets)
    nonempty = sizes > 0
    nxt = np.arange(1, len(indices) + 1)
    # the last corner of each polygon wraps to the first
    nxt[offsets[1:][nonempty] - 1] = offsets[:-1][nonempty]
    return _unique_undirected(indices, indices[nxt])


def vertex_adjacency(T_or_edges, n) -> sp.csr_matrix:
    """Vertex adjacency matrix.

    Parameters
    ----------
    T_or_edges : (t, 3) int64 or (e, 2) int64
        Triangles, or edges (for example :func:`edges_of_polygons`); repeated and
        reversed edges count once.
    n : int
        Number of vertices.

    Returns
    -------
    A : (n, n) scipy.sparse.csr_matrix
        Symmetric, 1.0 where two vertices share an edge, empty diagonal.

    Examples
    --------
    >>> vertex_adjacency([[0, 1, 2]], 4).toarray().tolist()
    [[0.0, 1.0, 1.0, 0.0], [1.0, 0.0, 1.0, 0.0], [1.0, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]]
    """
    n = as_count(n)
    arr, columns = as_triangles_or_edges(T_or_edges, n)
    return adjacency_matrix(unique_edges(arr, columns), n)


def triangle_adjacency(T, runs: EdgeRuns | None = None) -> np.ndarray:
    """Neighbouring triangle across each edge.

    Parameters
    ----------
    T : (t, 3) int64
        Triangles; edge ``j`` of triangle ``i`` runs from corner ``j`` to ``j + 1``.
    runs : EdgeRuns, optional
        :func:`edge_runs` of ``T``, when the caller has them.

    Returns
    -------
    TT : (t, 3) int64
        ``TT[i, j]`` is a triangle sharing the edge ``(T[i, j], T[i, (j + 1) % 3])``
        with triangle ``i``, or -1 on a boundary.  On a non-manifold edge (three or
        more triangles) it is one of the others: the triangles around the edge point
        to each other in a cycle, so every one is reachable.  Self-loop edges of
        degenerate triangles get -1.

    Examples
    --------
    >>> triangle_adjacency([[0, 1, 2], [0, 2, 3]]).tolist()
    [[-1, -1, 1], [0, -1, -1]]
    """
    T = as_triangles(T)
    t = len(T)
    if t == 0:
        return np.zeros((0, 3), dtype=np.int64)
    runs = edge_runs(T) if runs is None else runs
    order, start = runs.order, runs.starts
    group_start = np.maximum.accumulate(np.where(start, np.arange(3 * t), 0))
    last = np.r_[start[1:], True]
    # next half-edge in the same group, cyclically
    partner_pos = np.where(last, group_start, np.arange(3 * t) + 1)
    partner = np.empty(3 * t, dtype=np.int64)
    partner[order] = order[partner_pos]
    neighbour = partner // 3
    neighbour[partner == np.arange(3 * t)] = -1
    return neighbour.reshape(t, 3)


def boundary_edges(T) -> np.ndarray:
    """Directed edges used by exactly one triangle.

    Parameters
    ----------
    T : (t, 3) int64

    Returns
    -------
    B : (b, 2) int64
        ``(T[i, j], T[i, (j + 1) % 3])`` in the triangle's winding, in triangle
        order, so boundaries of a consistently oriented mesh are oriented too.

    Examples
    --------
    >>> boundary_edges([[0, 1, 2], [0, 2, 3]]).tolist()
    [[0, 1], [1, 2], [2, 3], [3, 0]]
    """
    T = as_triangles(T)
    if len(T) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    return _boundary_edges(T)


def boundary_vertices(T, n) -> np.ndarray:
    """Mask of vertices on a boundary edge.

    Parameters
    ----------
    T : (t, 3) int64
        Triangles; an edge used by one of them only is a boundary edge.
    n : int
        Number of vertices (the mask's length).

    Returns
    -------
    mask : (n,) bool

    Examples
    --------
    >>> boundary_vertices([[0, 1, 2]], 4).tolist()
    [True, True, True, False]
    """
    n = as_count(n)
    T = as_triangles(T, n)
    mask = np.zeros(n, dtype=bool)
    if len(T):
        mask[_boundary_edges(T).reshape(-1)] = True
    return mask


def _boundary_edges(T: np.ndarray) -> np.ndarray:
    a, b = half_edges(T)
    mask = _boundary_mask(T)
    return np.stack([a[mask], b[mask]], axis=1)


def boundary_loops(T) -> list[np.ndarray]:
    """Boundary loops as ordered vertex lists.

    Parameters
    ----------
    T : (t, 3) int64

    Returns
    -------
    loops : list of (k_i,) int64
        Each loop follows the triangles' winding and starts at its boundary edge of
        lowest index in :func:`boundary_edges`; the first vertex is not repeated at
        the end.  Longest loop first (for a face scan: the outer rim, then holes).
        At a vertex where two loops touch, the pairing of incoming and outgoing
        edges is arbitrary; if inconsistent winding leaves a chain that does not
        close, it is returned open, with its last vertex included.

    Notes
    -----
    Vectorised, O(b log b) for b boundary edges: successors by sorting, loops as
    connected components, order within loops by pointer jumping.

    Examples
    --------
    >>> T = [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]   # a fan around vertex 4
    >>> [loop.tolist() for loop in boundary_loops(T)]
    [[0, 1, 2, 3]]
    """
    T = as_triangles(T)
    if len(T) == 0:
        return []
    B = _boundary_edges(T)
    m = len(B)
    if m == 0:
        return []
    succ = _successor_edges(B)
    has_succ = succ >= 0
    graph = sp.csr_matrix((np.ones(np.count_nonzero(has_succ)),
                           (np.flatnonzero(has_succ), succ[has_succ])), shape=(m, m))
    count, label = csgraph.connected_components(graph, directed=True,
                                                connection="weak")
    # close cycles open at their lowest edge: cut the edge pointing to it
    is_open = np.zeros(count, dtype=bool)
    is_open[label[~has_succ]] = True
    first = np.full(count, m, dtype=np.int64)
    np.minimum.at(first, label, np.arange(m))
    cut = has_succ & ~is_open[label] & (succ == first[label])
    succ = np.where(cut, -1, succ)
    # pointer jumping: steps from each edge to the end of its chain
    steps = (succ >= 0).astype(np.int64)
    jump = succ.copy()
    active = np.flatnonzero(jump >= 0)
    while len(active):
        nxt = jump[active]
        steps[active] += steps[nxt]
        jump[active] = jump[nxt]
        active = active[jump[active] >= 0]
    order = np.lexsort((-steps, label))
    sizes = np.bincount(label, minlength=count)
    chains = np.split(order, np.cumsum(sizes)[:-1])
    loops = []
    for chain in chains:
        verts = B[chain, 0]
        if is_open[label[chain[0]]]:
            verts = np.append(verts, B[chain[-1], 1])
        loops.append(verts)
    loops.sort(key=len, reverse=True)
    return loops


def _successor_edges(B: np.ndarray) -> np.ndarray:
    """For directed edges ``B`` (b, 2), an edge leaving where each edge arrives.

    At a vertex with several incoming and outgoing edges, the r-th incoming edge
    (in edge order) is paired with the r-th outgoing one; -1 where none is left.
    """
    m = len(B)
    out_order = np.argsort(B[:, 0], kind="stable")
    in_order = np.argsort(B[:, 1], kind="stable")
    out_v, in_v = B[out_order, 0], B[in_order, 1]
    # rank of each incoming edge among the edges entering the same vertex
    in_first = np.searchsorted(in_v, in_v, side="left")
    in_rank = np.arange(m) - in_first
    # position of the matching outgoing edge in out_order
    pos = np.searchsorted(out_v, in_v, side="left") + in_rank
    out_count = np.searchsorted(out_v, in_v, side="right") - \
        np.searchsorted(out_v, in_v, side="left")
    ok = in_rank < out_count
    succ = np.full(m, -1, dtype=np.int64)
    succ[in_order[ok]] = out_order[pos[ok]]
    return succ


def connected_components(T, n) -> np.ndarray:
    """Connected component of each vertex.

    Parameters
    ----------
    T : (t, 3) int64
        Triangles; two vertices are connected when an edge path joins them.
    n : int
        Number of vertices, isolated ones included.

    Returns
    -------
    labels : (n,) int64
        Component ids ``0 .. c - 1``, numbered in order of their lowest vertex;
        a vertex used by no triangle is a component of its own.

    Examples
    --------
    >>> connected_components([[0, 1, 2], [3, 4, 5]], 7).tolist()
    [0, 0, 0, 1, 1, 1, 2]
    """
    n = as_count(n)
    T = as_triangles(T, n)
    # the half edges as they come: repeats only add up in the matrix, and skipping
    # the unique-edge sort makes this ~10x faster (0.3 s -> 0.03 s on 200k triangles)
    a, b = half_edges(T)
    A = sp.csr_matrix((np.ones(len(a), dtype=np.int8), (a, b)), shape=(n, n))
    _, labels = csgraph.connected_components(A, directed=False)
    return labels.astype(np.int64)


