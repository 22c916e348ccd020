"""Embedded deformation graph (Sumner, Schmid, Pauly 2007; SPEC §2.3).

:class:`DeformationGraph` is the structure built once on the template: nodes (a
Poisson-disk subset of vertices, so they are spread evenly), each vertex's ``k``
nearest nodes and skinning weights, and the node edges of the smoothness term.
:class:`GraphModel` is the deformation model on it: per-node rotation ``R_j`` and
translation ``t_j``,

    v_i = Σ_j w_ij ( R_j (b_i − x_j) + x_j + t_j )                       [6]
    E_smooth = Σ_(j,k) ‖ R_j (x_k − x_j) + x_j + t_j − x_k − t_k ‖²        [7]

with ``b`` the undeformed positions and ``x_j = b[node_j]``.

Nearest nodes are found **along the surface** (Dijkstra on the mesh edges, not
Euclidean distance): a neutral template's upper and lower lips, or upper and
lower eyelids, touch in space but are far apart on the surface, and Euclidean
neighbours would glue them so the mouth could not open.  Parts with no path to
the face (eyeballs, teeth as separate components) are tied to the nearest face
nodes so they follow smoothly.

The functions :func:`graph_vertices`, :func:`graph_jacobian` and
:func:`graph_smoothness` take the undeformed positions as an argument so the
hybrid model (:mod:`facewrap.wrapping.models.hybrid`) reuses them on blended positions.
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components as _components
from scipy.sparse.csgraph import dijkstra

from facewrap.geometry import edges as mesh_edges
from facewrap.geometry import poisson_disk_vertices
from facewrap.geometry.arrays import unique_integers
from facewrap.geometry.frames import NormalisedFrame
from facewrap.io.cache import content_key, load_arrays, save_arrays
from facewrap.wrapping.models.base import (DeformationModel, cross_matrix_blocks,
                                           nearest_rotations, rotation_exp)

__all__ = ["DeformationGraph", "GraphParams", "GraphModel", "build_graph",
           "graph_vertices", "graph_jacobian", "graph_smoothness", "resample_params",
           "GraphCache", "DEFAULT_GRAPH_CACHE"]


@dataclass(frozen=True)
class DeformationGraph:
    """Nodes, skinning weights and edges of an embedded deformation graph.

    Attributes
    ----------
    nodes : (m,) int64
        Template vertex ids of the nodes.
    vertex_nodes : (n, k) int64
        For each vertex, its ``k`` nearest nodes (indices into ``nodes``).
    vertex_weights : (n, k) float64
        Skinning weights, rows sum to 1.
    edges : (e, 2) int64
        Directed node pairs (j, k) of the smoothness term; both directions present.
    """
    nodes: np.ndarray
    vertex_nodes: np.ndarray
    vertex_weights: np.ndarray
    edges: np.ndarray

    @property
    def n_nodes(self) -> int:
        return len(self.nodes)

    @property
    def smoothness_scale(self) -> float:
        """1/√edges: eq. 7 as a mean over edges, so its weight does not depend
        on how many nodes the graph has."""
        return 1.0 / np.sqrt(max(len(self.edges), 1))


def build_graph(V, T, spacing: float, k: int = 4, seed: int = 0) -> DeformationGraph:
    """Build a deformation graph on a triangle mesh.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int
    spacing : float
        Node spacing (Poisson-disk radius) in the mesh's units.
    k : int
        Nodes per vertex.
    seed : int
        Sampling seed (the result is deterministic for a given seed).

    Returns
    -------
    DeformationGraph
    """
    V = np.asarray(V, dtype=np.float64)
    T = np.asarray(T, dtype=np.int64)
    n = len(V)
    if spacing <= 0:
        raise ValueError("spacing must be positive")
    E = mesh_edges(T)
    length = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[length, length], (np.r_[E[:, 0], E[:, 1]],
                                                np.r_[E[:, 1], E[:, 0]])),
                      shape=(n, n)).tocsr()
    nodes = _surface_poisson_nodes(V, G, spacing, seed)
    k = int(min(k, len(nodes)))
    nearest, dist = _nearest_nodes_on_surface(G, V, nodes, k + 1, limit=4.0 * spacing)
    # vertices with fewer than k nodes in reach (small separate parts): fill in
    # with Euclidean nearest nodes so every vertex is skinned
    missing = ~np.isfinite(dist[:, k - 1])
    if missing.any():
        from scipy.spatial import cKDTree   # building only: a cached graph needs none
        d_e, j_e = cKDTree(V[nodes]).query(V[missing], k=k + 1)
        d_e, j_e = d_e.reshape(-1, k + 1), j_e.reshape(-1, k + 1)
        nearest[missing], dist[missing] = j_e, d_e
    d_max = dist[:, k]
    d_max = np.where(np.isfinite(d_max), d_max, 1.5 * dist[:, k - 1])
    d_max = np.maximum(d_max, 1e-12)
    w = (1.0 - dist[:, :k] / d_max[:, None]) ** 2  # Sumner's weights
    w = np.maximum(w, 1e-12)
    w /= w.sum(axis=1, keepdims=True)
    vertex_nodes = nearest[:, :k]
    # edges: nodes that share a vertex of the surface (a point no face uses, or a
    # part left out of T, is skinned by Euclidean neighbours: were those edges, a
    # tooth between the lips would tie the lips' nodes together) ...
    on_surface = vertex_nodes[np.diff(G.indptr) > 0] if G.nnz else vertex_nodes
    a = np.repeat(on_surface, k, axis=1).ravel()
    b = np.tile(on_surface, (1, k)).ravel()
    pairs = _unique_pairs(a[a != b], b[a != b], len(nodes))
    pairs = _tie_components(pairs, V[nodes])
    return DeformationGraph(nodes, vertex_nodes, w, pairs)


def _unique_pairs(a, b, m: int) -> np.ndarray:
    """(e, 2) unique ordered pairs, sorted; one sort of int64 keys (several times
    faster than ``np.unique(..., axis=0)``)."""
    key = unique_integers(np.asarray(a, np.int64) * m + np.asarray(b, np.int64))
    return np.stack([key // m, key % m], axis=1)


def _surface_poisson_nodes(V, G, spacing, seed, rounds: int = 4):
    """Poisson-disk nodes that cover the surface *along* the surface.

    A Euclidean Poisson-disk sample puts one node between two sheets that touch
    (closed lips, closed lids), leaving the other sheet without nodes of its own.
    So: sample, find the vertices farther than ``spacing`` from every node along
    the surface, sample those again, and repeat until the surface is covered.
    """
    # nodes on the surface only: a point no face uses (an exporter's stray) is
    # skinned to the nearest ones instead (build_graph's Euclidean fill)
    surface = np.flatnonzero(np.diff(G.indptr) > 0)
    if len(surface) in (0, len(V)):
        surface = np.arange(len(V))
    nodes = surface[poisson_disk_vertices(V[surface], spacing, seed=seed)]
    on_surface = np.zeros(len(V), dtype=bool)
    on_surface[surface] = True
    for _ in range(rounds):
        d = dijkstra(G, directed=False, indices=nodes, min_only=True, limit=1.5 * spacing)
        uncovered = np.flatnonzero((d > spacing) & on_surface)
        if len(uncovered) == 0:
            break
        extra = uncovered[poisson_disk_vertices(V[uncovered], spacing, seed=seed)]
        nodes = np.union1d(nodes, extra)
    return np.sort(nodes).astype(np.int64)


def _nearest_nodes_on_surface(G, V, nodes, count, limit):
    """The ``count`` nearest nodes of every vertex by graph distance (≤ limit).

    Most vertices find them well inside ``limit`` (Poisson-disk nodes: the
    fifth is within ~2.2 spacings), so a first pass searches 3/4 of it —
    half the work — and only vertices left short are searched again to the
    full limit, from the nodes that can reach them (Euclidean distance is a
    lower bound of the surface distance).  The result equals one full pass.
    """
    best_j, best_d = _nearest_within(G, nodes, count, 0.75 * limit)
    short = np.flatnonzero(~np.isfinite(best_d[:, -1]))
    if len(short):
        from scipy.spatial import cKDTree   # building only (see build_graph)
        hits = cKDTree(V[short]).query_ball_point(V[nodes], r=limit)
        near = np.flatnonzero([len(h) > 0 for h in hits])
        if len(near):
            j, d = _nearest_within(G, nodes[near], count, limit, rows=short)
            best_j[short], best_d[short] = np.where(np.isfinite(d), near[j], 0), d
    return best_j, best_d


def _nearest_within(G, sources, count, limit, rows=None):
    """(n, count) indices into ``sources`` and distances of the nearest sources
    of every vertex (or of ``rows``) within ``limit``; inf where fewer.

    Each source reaches a few hundred vertices within ``limit``: the (vertex,
    source, distance) triples it reaches are kept and sorted once (by vertex, then
    distance, then the lower source), where selecting among every vertex's row of
    mostly infinite distances cost twice the searches themselves."""
    n = G.shape[0] if rows is None else len(rows)
    found = []
    chunk = max(64, int(4_000_000 // max(G.shape[0], 1)))  # sources per chunk bound memory
    for start in range(0, len(sources), chunk):
        ids = np.arange(start, min(start + chunk, len(sources)))
        D = dijkstra(G, directed=False, indices=sources[ids], limit=limit)   # (c, n)
        if rows is not None:
            D = D[:, rows]
        s, v = np.nonzero(np.isfinite(D))
        found.append((v, ids[s], D[s, v]))
    v, j, d = (np.concatenate(parts) for parts in zip(*found)) if found else (
        np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0))
    order = np.lexsort((j, d, v))           # ties: lower node first
    v, j, d = v[order], j[order], d[order]
    first = np.searchsorted(v, np.arange(n))
    rank = np.arange(len(v)) - first[v]
    keep = rank < count
    best_d = np.full((n, count), np.inf)
    best_j = np.zeros((n, count), dtype=np.int64)
    best_d[v[keep], rank[keep]] = d[keep]
    best_j[v[keep], rank[keep]] = j[keep]
    return best_j, best_d


def _tie_components(pairs, X, ties: int = 3):
    """Connect node-graph components to the largest one (eyes follow the face)."""
    m = len(X)
    A = sp.coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(m, m))
    count, label = _components(A, directed=False)
    if count <= 1:
        return pairs
    main = np.bincount(label).argmax()
    inside = np.flatnonzero(label == main)
    other = np.flatnonzero(label != main)
    from scipy.spatial import cKDTree       # building only (see build_graph)
    _, j = cKDTree(X[inside]).query(X[other], k=min(ties, len(inside)))
    j = inside[np.asarray(j).reshape(len(other), -1)]
    extra = np.stack([np.repeat(other, j.shape[1]), j.ravel()], 1)
    extra = np.concatenate([extra, extra[:, ::-1]])
    return np.unique(np.concatenate([pairs, extra]), axis=0)


@dataclass(frozen=True)
class GraphParams:
    """Per-node rotations ``R`` (m, 3, 3) and translations ``t`` (m, 3)."""
    R: np.ndarray
    t: np.ndarray

    @classmethod
    def identity(cls, m: int) -> "GraphParams":
        return cls(np.broadcast_to(np.eye(3), (m, 3, 3)).copy(), np.zeros((m, 3)))

    def updated(self, delta) -> "GraphParams":
        """Apply an increment ``delta`` (6m,) ordered [δθ_j, δt_j] per node."""
        d = np.asarray(delta).reshape(-1, 6)
        return GraphParams(rotation_exp(d[:, :3]) @ self.R, self.t + d[:, 3:])


def graph_vertices(B, graph: DeformationGraph, p: GraphParams) -> np.ndarray:
    """Eq. 6 on undeformed positions ``B`` (n, 3); returns (n, 3)."""
    X = B[graph.nodes]
    J, W = graph.vertex_nodes, graph.vertex_weights
    # Σ_j w_ij (R_j (b_i − x_j) + x_j + t_j) = (Σ_j w_ij R_j) b_i + Σ_j w_ij c_j with
    # c_j = x_j + t_j − R_j x_j: the rotations act once per node, not once per
    # (vertex, node) pair (a few times faster than rotating every local vector)
    c = X + p.t - np.einsum("mab,mb->ma", p.R, X)
    M = np.einsum("nk,nkab->nab", W, p.R[J])
    return np.einsum("nab,nb->na", M, B) + np.einsum("nk,nka->na", W, c[J])


def resample_params(B, source: DeformationGraph, params: GraphParams,
                    target: DeformationGraph) -> GraphParams:
    """Parameters of graph ``target`` that continue ``source``'s deformation
    (coarse-to-fine: a stiff stage on few nodes hands over to many).

    Each target node is translated to where ``source`` moves its vertex (eq. 6)
    and takes the rotation nearest to the skinning-weighted mean of its source
    nodes' rotations: every node's own transform agrees with ``source`` to first
    order around it, so the skinned surface changes only by the difference of
    the two interpolations (small for a smooth, stiff-stage deformation).

    Parameters
    ----------
    B : (n, 3) float64
        Undeformed positions both graphs act on.
    source : DeformationGraph
    params : GraphParams
        Of ``source``.
    target : DeformationGraph
        Built on the same template vertices.

    Returns
    -------
    GraphParams of ``target``.
    """
    u = target.nodes
    X = B[source.nodes]
    J, W = source.vertex_nodes[u], source.vertex_weights[u]
    local = B[u][:, None, :] - X[J]
    moved = np.einsum("mkab,mkb->mka", params.R[J], local) + X[J] + params.t[J]
    R = nearest_rotations(np.einsum("mk,mkab->mab", W, params.R[J]))
    return GraphParams(R, np.einsum("mk,mka->ma", W, moved) - B[u])


def graph_jacobian(B, graph: DeformationGraph, p: GraphParams,
                   vertices=None) -> sp.csr_matrix:
    """Derivative of eq. 6 w.r.t. node increments: (3n, 6m), or (3v, 6m) for the
    rows of the given ``vertices`` only."""
    X = B[graph.nodes]
    J, W = graph.vertex_nodes, graph.vertex_weights
    if vertices is not None:
        J, W, B = J[vertices], W[vertices], B[vertices]
    n, k = J.shape
    rotated = np.einsum("nkab,nkb->nka", p.R[J], B[:, None, :] - X[J])
    # values laid out row by row (vertex i, coordinate a), then slot, then column
    blocks = np.empty((n, 3, k, 6))
    blocks[..., :3] = (cross_matrix_blocks(rotated) * W[..., None, None]).transpose(0, 2, 1, 3)
    blocks[..., 3:] = np.eye(3)[None, :, None, :] * W[:, None, :, None]
    indices, indptr = _vertex_jacobian_pattern(J)
    return sp.csr_matrix((blocks.ravel(), indices, indptr),
                         shape=(3 * n, 6 * graph.n_nodes))


def _vertex_jacobian_pattern(J):
    """CSR column indices and row pointers of the (3n, 6m) vertex Jacobian: the
    pattern is fixed by the skinning, so it is built without sorting."""
    n, k = J.shape
    cols = (6 * J)[:, None, :, None] + np.arange(6)                  # (n, 1, k, 6)
    indices = np.broadcast_to(cols, (n, 3, k, 6)).ravel()
    indptr = np.arange(0, 3 * n * 6 * k + 1, 6 * k)
    return indices, indptr


def graph_smoothness(B, graph: DeformationGraph, p: GraphParams, jacobian=True):
    """Eq. 7 residuals (3e,) and their Jacobian (3e, 6m) on positions ``B``
    (only the residuals when ``jacobian`` is False)."""
    X = B[graph.nodes]
    j, k = graph.edges[:, 0], graph.edges[:, 1]
    d = X[k] - X[j]
    rotated = np.einsum("eab,eb->ea", p.R[j], d)
    r = rotated + X[j] + p.t[j] - X[k] - p.t[k]
    if not jacobian:
        return r.ravel()
    e = len(j)
    blocks = np.zeros((e, 3, 3, 3))  # per edge: [θ_j block, t_j block, t_k block]
    blocks[:, 0] = cross_matrix_blocks(rotated)
    blocks[:, 1] = np.eye(3)
    blocks[:, 2] = -np.eye(3)
    col0 = np.stack([6 * j, 6 * j + 3, 6 * k + 3], 1)               # (e, 3)
    rows = np.broadcast_to((3 * np.arange(e))[:, None, None, None]
                           + np.arange(3)[None, None, :, None], blocks.shape)
    cols = np.broadcast_to(col0[:, :, None, None] + np.arange(3), blocks.shape)
    Jm = sp.csr_matrix((blocks.ravel(), (rows.ravel(), cols.ravel())),
                       shape=(3 * e, 6 * graph.n_nodes))
    return r.ravel(), Jm


class GraphModel(DeformationModel):
    """Embedded deformation graph model.

    Parameters
    ----------
    base : (n, 3) float64
        Undeformed vertex positions (the aligned template).
    graph : DeformationGraph
        Built with :func:`build_graph` on the template.

    Regularisers: ``"smooth"`` (eq. 7, normalised by the number of edges).
    Rotations are updated on the rotation group, so they stay orthonormal.
    """

    regularizer_names = ("smooth",)
    param_block = 6

    def __init__(self, base, graph: DeformationGraph):
        self.base = np.asarray(base, dtype=np.float64)
        self.graph = graph
        self.n_vertices = len(self.base)
        self.n_params = 6 * graph.n_nodes

    def initial_params(self) -> GraphParams:
        return GraphParams.identity(self.graph.n_nodes)

    def vertices(self, params: GraphParams) -> np.ndarray:
        return graph_vertices(self.base, self.graph, params)

    def jacobian(self, params: GraphParams, vertices=None):
        return graph_jacobian(self.base, self.graph, params, vertices)

    def regularizers(self, params: GraphParams) -> dict:
        r, J = graph_smoothness(self.base, self.graph, params)
        scale = self.graph.smoothness_scale
        return {"smooth": (r * scale, J * scale)}

    def regularizer_residuals(self, params: GraphParams) -> dict:
        r = graph_smoothness(self.base, self.graph, params, jacobian=False)
        return {"smooth": r * self.graph.smoothness_scale}

    def update(self, params: GraphParams, delta) -> GraphParams:
        return params.updated(delta)

    def on_graph(self, graph: DeformationGraph, params: GraphParams
                 ) -> tuple["GraphModel", GraphParams]:
        """The same model on another graph of the template, with parameters that
        continue ``params`` (:func:`resample_params`; coarse-to-fine)."""
        return (GraphModel(self.base, graph),
                resample_params(self.base, self.graph, params, graph))

    def summary(self, params: GraphParams) -> dict:
        return {"nodes": self.graph.n_nodes, "edges": int(len(self.graph.edges))}


class GraphCache:
    """Deformation graphs by template content and node spacing, least recently used
    dropped first.

    Nodes and skinning depend only on the template's surface (geodesic distances
    in its normalised frame, which a similarity does not change), so every scan of
    a batch or frame of a sequence reuses one graph.  The key is the template's
    content, not the object: batch jobs read the template afresh and still share
    one graph.  Graphs are also kept on disk by content (:mod:`facewrap.io.cache`;
    off with ``FACEWRAP_CACHE=0``), so a new process reads them back instead of
    building them.  :func:`facewrap.wrapping.wrap` and :func:`facewrap.wrapping.track`
    take a cache (``graph_cache=``) and use :data:`DEFAULT_GRAPH_CACHE` when given
    none.

    Parameters
    ----------
    capacity : int
        Graphs kept (at least 1).

    Examples
    --------
    >>> import os, tempfile
    >>> os.environ["FACEWRAP_CACHE_DIR"] = tempfile.mkdtemp()   # not the home folder
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2]])
    >>> cache = GraphCache(capacity=2)
    >>> cache.graph(V, T, 0.5) is cache.graph(V.copy(), T.copy(), 0.5), len(cache)
    (True, 1)
    >>> cache.clear(); len(cache)
    0
    >>> g = GraphCache().graph(V, T, 0.5)        # a new cache (process) reads it back
    >>> bool((g.nodes == cache.graph(V, T, 0.5).nodes).all())
    True
    >>> del os.environ["FACEWRAP_CACHE_DIR"]
    """

    def __init__(self, capacity: int = 8):
        if int(capacity) < 1:
            raise ValueError(f"capacity must be at least 1, got {capacity!r}")
        self.capacity = int(capacity)
        self._graphs: OrderedDict[tuple, DeformationGraph] = OrderedDict()
        # wraps on several threads share one cache: a lookup must not see a graph
        # another thread is dropping (graphs are built outside it, so two threads
        # may build one graph, never wait for each other's)
        self._lock = threading.Lock()

    def __len__(self) -> int:
        with self._lock:
            return len(self._graphs)

    def clear(self) -> None:
        """Forget every graph (e.g. between batches of different templates)."""
        with self._lock:
            self._graphs.clear()

    def graph(self, vertices, triangles, spacing: float) -> DeformationGraph:
        """The graph of a template at a node spacing, built on first use.

        Parameters
        ----------
        vertices : (n, 3) float64
            Template positions (in any units: the graph is built in their
            normalised frame).
        triangles : (t, 3) int64
        spacing : float
            Node spacing as a fraction of the template's bounding-box diagonal.

        Returns
        -------
        DeformationGraph
        """
        V = np.ascontiguousarray(vertices)
        T = np.ascontiguousarray(triangles)
        key = (hashlib.sha1(V.tobytes() + T.tobytes()).hexdigest(), V.shape, T.shape,
               float(spacing))
        with self._lock:
            if key in self._graphs:
                self._graphs.move_to_end(key)
                return self._graphs[key]
        # on disk too (facewrap.io.cache): a new process (every CLI run, every
        # batch worker) reads the graph of a template it has seen instead of
        # running the surface Dijkstra searches again
        surface = np.zeros(len(V), dtype=bool)
        surface[T.ravel()] = True
        # (a template with points no face uses: a key of its own, since its graph
        # changed when they were left out of the frame and the nodes)
        disk_key = content_key(V, T, float(spacing),
                               "k=4 seed=0" + ("" if surface.all() else " surface"))
        graph = _stored_graph(disk_key, len(V))
        if graph is None:
            frame = NormalisedFrame.of(V[surface] if surface.any() else V)
            graph = build_graph(frame.to_frame(V), T, spacing=spacing)
            save_arrays(_GRAPH_KIND, disk_key, {f: getattr(graph, f) for f in _GRAPH_FIELDS},
                        version=_GRAPH_VERSION)
        with self._lock:
            self._graphs[key] = graph
            self._graphs.move_to_end(key)
            while len(self._graphs) > self.capacity:
                self._graphs.popitem(last=False)
        return graph


#: the on-disk cache entries of graphs: their kind, layout, and the version of
#: :func:`build_graph`'s algorithm (bump it when the nodes, skinning or edges a
#: template gets change, so no graph of the old algorithm is read back)
_GRAPH_KIND = "deformation-graph"
_GRAPH_FIELDS = ("nodes", "vertex_nodes", "vertex_weights", "edges")
_GRAPH_VERSION = 2


def _stored_graph(key: str, n_vertices: int) -> DeformationGraph | None:
    """The graph stored under ``key`` when the entry is whole and consistent with a
    template of ``n_vertices`` vertices, else None (it is built again)."""
    arrays = load_arrays(_GRAPH_KIND, key, _GRAPH_FIELDS, version=_GRAPH_VERSION)
    if arrays is None:
        return None
    nodes, vn, vw, edges = (arrays[f] for f in _GRAPH_FIELDS)
    m = len(nodes)
    ints = all(a.dtype.kind == "i" for a in (nodes, vn, edges))
    if not (ints and vw.dtype == np.float64 and nodes.ndim == 1 and m > 0
            and vn.ndim == 2 and vn.shape[0] == n_vertices and vw.shape == vn.shape
            and edges.ndim == 2 and edges.shape[1] == 2):
        return None
    if not (0 <= nodes.min() and nodes.max() < n_vertices and 0 <= vn.min()
            and vn.max() < m and (edges.size == 0 or (0 <= edges.min()
                                                      and edges.max() < m))):
        return None
    return DeformationGraph(nodes.astype(np.int64), vn.astype(np.int64), vw,
                            edges.astype(np.int64))


#: the cache of callers that pass none
DEFAULT_GRAPH_CACHE = GraphCache()
