"""Triangle correspondence between two meshes of different topology (SPEC §3.2).

This module owns the step that makes deformation transfer possible: which
triangles of the source correspond to which triangles of the target.

1. **Deform** one mesh (the *moving* one, normally the source) toward the other
   (the *fixed* one), keeping its topology, by minimising

       w_S E_S + w_I E_I + w_C E_C

   over its vertices and fourth vertices (:mod:`.gradients`), with the markers as
   hard constraints eliminated exactly (their columns move to the right-hand side).
   ``E_S`` asks neighbouring triangles for equal deformation gradients, ``E_I``
   for gradients near the identity, ``E_C`` for vertices near their closest valid
   point on the fixed mesh (normals within 90°).  A :class:`CorrespondenceStage`
   per step gives the weights; :data:`SUMNER_SCHEDULE` starts with ``w_C = 0`` and
   raises it to 5000, recomputing closest points every step.
2. **Match** triangles: for each moving triangle the nearest fixed triangle by
   centroid whose normal is within 90°, and the same the other way round; the
   union is the many-to-many :class:`Correspondence`.

Lengths are measured in units of the fixed mesh's bounding-box diagonal (after a
similarity alignment on the markers), so the weights mean the same for meshes in
millimetres or metres.  A :class:`Correspondence` saves to and loads from ``.npz``
so it is computed once per source/target pair.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.errors import InputError
from facewrap.geometry import ClosestPointTree, face_normals, vertex_normals
from facewrap.mesh import Mesh
from facewrap.solve import conjugate_gradients, factorize, refactorize
from facewrap.transfer.gradients import adjacent_triangle_pairs, gradient_operator, \
    triangle_smoothness_operator

__all__ = ["CorrespondenceStage", "SUMNER_SCHEDULE", "CorrespondenceSettings",
           "Correspondence", "find_correspondence", "deform_toward",
           "match_triangles", "closest_valid_points", "check_markers",
           "untethered_vertices"]


@dataclass(frozen=True)
class CorrespondenceStage:
    """Weights of one step of the correspondence deformation.

    Attributes
    ----------
    w_smooth : float
        ``w_S``, equal gradients of neighbouring triangles.
    w_identity : float
        ``w_I``, gradients near the identity (the moving mesh keeps its shape).
    w_closest : float
        ``w_C``, vertices near their closest valid point (in units of the fixed
        mesh's bounding-box diagonal); 0 switches the term off.
    iterations : int
        Solves in this step, closest points recomputed before each.
    """

    w_smooth: float = 1.0
    w_identity: float = 0.001
    w_closest: float = 0.0
    iterations: int = 1

    def __post_init__(self):
        for name in ("w_smooth", "w_identity", "w_closest"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be finite and >= 0, got {v}")
        if self.w_smooth + self.w_identity <= 0:
            raise ValueError("w_smooth + w_identity must be positive")
        if int(self.iterations) < 1:
            raise ValueError(f"iterations must be >= 1, got {self.iterations}")


#: Sumner & Popović 2004: w_S = 1, w_I = 0.001, first w_C = 0, then w_C from 1 to
#: 5000 in four steps.
SUMNER_SCHEDULE: tuple[CorrespondenceStage, ...] = (
    CorrespondenceStage(1.0, 0.001, 0.0),
    *(CorrespondenceStage(1.0, 0.001, float(w)) for w in np.geomspace(1.0, 5000.0, 4)),
)


@dataclass(frozen=True)
class CorrespondenceSettings:
    """How :func:`find_correspondence` works.

    Attributes
    ----------
    schedule : tuple of CorrespondenceStage
        Deformation steps, in order.
    deform : {"source", "target"}
        Which mesh is deformed toward the other (Sumner deforms the source;
        Onizuka et al. deform the avatar, i.e. the target).
    align : {"similarity", "rigid", "none"}
        Pre-alignment of the moving mesh on the markers before deforming.
    neighbours : int
        Candidates examined (nearest first) when looking for a compatible
        triangle or a valid closest vertex.
    max_distance : float or None
        Triangle pairs whose centroids are farther apart than this (fraction of the
        fixed mesh's bounding-box diagonal) are not matched.
    """

    schedule: tuple = SUMNER_SCHEDULE
    deform: str = "source"
    align: str = "similarity"
    neighbours: int = 16
    max_distance: float | None = None

    def __post_init__(self):
        if self.deform not in ("source", "target"):
            raise ValueError(f"deform must be 'source' or 'target', got {self.deform!r}")
        if self.align not in ("similarity", "rigid", "none"):
            raise ValueError(f"align must be 'similarity', 'rigid' or 'none', got "
                             f"{self.align!r}")
        if not self.schedule or not all(isinstance(s, CorrespondenceStage)
                                        for s in self.schedule):
            raise ValueError("schedule must be a non-empty tuple of CorrespondenceStage")
        if int(self.neighbours) < 1:
            raise ValueError("neighbours must be >= 1")


_FORMAT = "facewrap.correspondence"
_VERSION = 1


@dataclass(frozen=True, eq=False)
class Correspondence:
    """Many-to-many triangle correspondence between a source and a target.

    Attributes
    ----------
    source_triangles, target_triangles : (k,) int64
        Pair ``j`` says source triangle ``source_triangles[j]`` corresponds to target
        triangle ``target_triangles[j]`` (indices into ``mesh.triangles``).  Sorted,
        without duplicates.
    n_source_vertices, n_source_triangles, n_target_vertices, n_target_triangles : int
        Sizes of the meshes it belongs to (checked when used).
    markers : (m, 2) int64
        The (source vertex, target vertex) pairs it was computed with.
    deformed : (n_moving, 3) float64
        The deformed moving mesh, in the fixed mesh's coordinates (for inspection).
    deformed_mesh : {"source", "target"}
        Which mesh ``deformed`` belongs to.
    stats : dict
        Timings and counts (closest-point validity, unmatched triangles).
    """

    source_triangles: np.ndarray
    target_triangles: np.ndarray
    n_source_vertices: int
    n_source_triangles: int
    n_target_vertices: int
    n_target_triangles: int
    markers: np.ndarray
    deformed: np.ndarray
    deformed_mesh: str = "source"
    stats: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.source_triangles)

    @property
    def unmatched_target(self) -> np.ndarray:
        """int64 target triangles without any source partner."""
        used = np.zeros(self.n_target_triangles, dtype=bool)
        used[self.target_triangles] = True
        return np.flatnonzero(~used)

    @property
    def unmatched_source(self) -> np.ndarray:
        """int64 source triangles without any target partner."""
        used = np.zeros(self.n_source_triangles, dtype=bool)
        used[self.source_triangles] = True
        return np.flatnonzero(~used)

    def check(self, source: Mesh | None = None, target: Mesh | None = None,
              path=None) -> None:
        """Raise :class:`InputError` when the meshes are not the ones it was made for.

        Parameters
        ----------
        source, target : Mesh, optional
        path : str, optional
            File to name in the message (the correspondence file).
        """
        for name, mesh, nv, nt in (("source", source, self.n_source_vertices,
                                    self.n_source_triangles),
                                   ("target", target, self.n_target_vertices,
                                    self.n_target_triangles)):
            if mesh is None:
                continue
            if mesh.n_vertices != nv or len(mesh.triangles) != nt:
                raise InputError(f"correspondence was made for a {name} with {nv} "
                                 f"vertices and {nt} triangles, got "
                                 f"{mesh.n_vertices} and {len(mesh.triangles)}", path)

    def save(self, path) -> None:
        """Write to an ``.npz`` file (atomically)."""
        from facewrap.io.atomic import atomic_write
        import json
        with atomic_write(path, "wb") as fh:
            np.savez_compressed(
                fh, format=np.array(_FORMAT), version=np.array(_VERSION),
                source_triangles=self.source_triangles,
                target_triangles=self.target_triangles,
                sizes=np.array([self.n_source_vertices, self.n_source_triangles,
                                self.n_target_vertices, self.n_target_triangles]),
                markers=self.markers, deformed=self.deformed,
                deformed_mesh=np.array(self.deformed_mesh),
                stats=np.array(json.dumps(self.stats)))

    @classmethod
    def load(cls, path) -> "Correspondence":
        """Read a file written by :meth:`save`.

        Raises
        ------
        InputError
            Missing file, not a facewrap correspondence, or inconsistent content.
        """
        import json
        import zipfile
        if not os.path.isfile(path):
            raise InputError("no such file", path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if "format" not in z.files or str(z["format"]) != _FORMAT:
                    raise InputError("not a facewrap correspondence file", path)
                if int(z["version"]) > _VERSION:
                    raise InputError(f"correspondence version {int(z['version'])} is "
                                     "newer than this facewrap reads", path)
                d = {k: z[k] for k in z.files}
        except (OSError, ValueError, zipfile.BadZipFile, KeyError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"cannot read correspondence: {exc}", path) from None
        try:
            nsv, nst, ntv, ntt = (int(x) for x in d["sizes"])
            src = d["source_triangles"].astype(np.int64)
            tgt = d["target_triangles"].astype(np.int64)
            markers = d["markers"].astype(np.int64).reshape(-1, 2)
            deformed = d["deformed"].astype(np.float64)
            which = str(d["deformed_mesh"])
            stats = json.loads(str(d["stats"]))
        except (KeyError, ValueError, TypeError) as exc:
            raise InputError(f"incomplete correspondence file ({exc})", path) from None
        if (src.shape != tgt.shape or src.ndim != 1
                or (len(src) and (src.min() < 0 or src.max() >= nst
                                  or tgt.min() < 0 or tgt.max() >= ntt))):
            raise InputError("triangle pairs out of range", path)
        return cls(_ro(src), _ro(tgt), nsv, nst, ntv, ntt, _ro(markers), _ro(deformed),
                   which, stats)


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def check_markers(markers, n_source: int, n_target: int, path=None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Validate marker pairs against the two meshes.

    Parameters
    ----------
    markers : (src, tgt) pair of (m,) int arrays, or (m, 2) int
    n_source, n_target : int
        Vertex counts.
    path : str, optional
        Marker file to name in errors.

    Returns
    -------
    source, target : (m,) int64

    Raises
    ------
    InputError
        No markers, or an id out of range.
    """
    if isinstance(markers, tuple) and len(markers) == 2:
        src, tgt = (np.asarray(m, dtype=np.int64).reshape(-1) for m in markers)
    else:
        arr = np.asarray(markers, dtype=np.int64)
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise InputError(f"markers must be (m, 2) pairs, got shape {arr.shape}", path)
        src, tgt = arr[:, 0], arr[:, 1]
    if len(src) != len(tgt) or len(src) == 0:
        raise InputError("need at least one (source, target) marker pair", path)
    for name, ids, n in (("source", src, n_source), ("target", tgt, n_target)):
        bad = (ids < 0) | (ids >= n)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError(f"marker {k}: {name} vertex {int(ids[k])} out of range "
                             f"(the {name} mesh has {n} vertices)", path)
    return src, tgt


#: Weight, relative to the mean diagonal of a normal matrix, of the tiny pull toward
#: rest positions that fixes the translation of components without any constraint.
_TETHER = 1e-8


def untethered_vertices(T, n: int, fixed_ids) -> np.ndarray:
    """(n,) bool: vertices of connected components that contain no fixed vertex.

    Their translation is free in every gradient energy; callers add a tiny pull
    toward their rest positions (so an eyeball turns about its own centre).
    """
    from facewrap.geometry import connected_components
    comp = connected_components(T, n)
    has = np.zeros(int(comp.max()) + 1 if n else 0, dtype=bool)
    has[comp[np.asarray(fixed_ids, dtype=np.int64)]] = True
    return ~has[comp]


def closest_valid_points(tree: ClosestPointTree, kdtree: cKDTree, X, normals,
                         neighbours: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on a mesh whose normal is within 90° of each query's normal.

    The exact closest surface point is used when its interpolated normal agrees;
    otherwise the nearest mesh vertex (of ``neighbours`` candidates) that agrees.

    Parameters
    ----------
    tree : ClosestPointTree
        Of the fixed mesh.
    kdtree : scipy.spatial.cKDTree
        Over the same mesh's vertices.
    X : (k, 3) float64
        Query points.
    normals : (k, 3) float64
        Their unit normals.
    neighbours : int

    Returns
    -------
    points : (k, 3) float64
    valid : (k,) bool
        False where no compatible point was found (its row of ``points`` is ``X``).
    """
    cp = tree.query(X)
    points = cp.points.copy()
    valid = np.einsum("ij,ij->i", cp.normals, normals) > 0
    bad = np.flatnonzero(~valid)
    if len(bad):
        k = min(int(neighbours), kdtree.n)
        _, idx = kdtree.query(X[bad], k=k)
        idx = idx.reshape(len(bad), k)
        ok = np.einsum("ikj,ij->ik", tree.vertex_normals[idx], normals[bad]) > 0
        first = ok.argmax(axis=1)
        found = ok[np.arange(len(bad)), first]
        points[bad[found]] = tree.vertices[idx[found, first[found]]]
        valid[bad[found]] = True
        points[bad[~found]] = X[bad[~found]]
    return points, valid


#: Conjugate gradients stop when the preconditioned residual (an estimate of the
#: remaining error, an overestimate for a preconditioner factored with smaller
#: diagonal) is below this fraction of the largest coordinate.  The deformed
#: meshes then differ from exact solves by < 1e-8 of the fixed mesh's diagonal
#: (ICT → Oldman, cat → lion, horse → camel): the same closest points, the same
#: triangle pairs.
_CG_TOLERANCE = 1e-7

#: Back-substitutions worth one new factorisation.  A supernodal Cholesky of the
#: ~30k-unknown systems here costs 50–60 back-substitutions with the reference BLAS
#: cholespy ships; conjugate gradients that would need more than this give up early
#: (judged from their convergence rate) and the matrix is factored instead.
_CG_BUDGET = 40


class _FreeSystem:
    """``w_S DᵀD + w_I GᵀG + diag(d)`` over the free unknowns, for changing weights.

    Every solve of a correspondence schedule has this matrix with the marked
    unknowns eliminated, and between steps only ``d`` changes (``w_C`` on the
    vertices with a valid closest point, the tether), ``w_S`` and ``w_I`` from stage
    to stage.  So the free block of each term is cut out once, onto one sparsity
    pattern that includes the whole diagonal, and a step's matrix is a weighted sum
    of value arrays; the marked columns become two fixed right-hand-side offsets.

    Each step's matrix is factored with CHOLMOD's supernodal Cholesky
    (``factorize(..., solves="few")``, 0.13 s at 28k unknowns, against 0.79 s
    for cholespy, whose back-substitutions are 3x cheaper): five factorisations
    and five solves, 0.8 s for ICT → Oldman.  Without cvxopt (cholespy only),
    solves reuse the last factorisation as a preconditioner of conjugate gradients
    (three coordinates at once, one back-substitution per iteration for all three),
    warm-started at the previous step's solution: a diagonal change costs a few
    back-substitutions instead of a factorisation (~0.8 s at 28k unknowns).  When
    the diagonal has changed too much since the factorisation (``w_C`` rising
    1 → 5000 over the smooth modes, or a huge ``w_C`` switched on and off at many
    vertices), the current matrix is factored instead, decided before the
    iterations when the change or the last run predict it, otherwise as soon as
    their convergence rate does; a change of ``w_S`` or ``w_I`` (a new
    off-diagonal) always is.  With :data:`SUMNER_SCHEDULE` this makes two
    factorisations of five solves.

    Parameters
    ----------
    DtD, GtG : (N, N) scipy.sparse matrix
        ``DᵀD`` and ``GᵀG``.
    fixed : (N,) bool
        Marked unknowns.
    fixed_values : (m, 3) float64
        Their positions, in the order of ``np.flatnonzero(fixed)``.
    """

    def __init__(self, DtD, GtG, fixed: np.ndarray, fixed_values: np.ndarray):
        free = np.flatnonzero(~fixed)
        marked = np.flatnonzero(fixed)
        nf = len(free)
        DtD, GtG = sp.csr_matrix(DtD), sp.csr_matrix(GtG)
        smooth, ident = DtD[free], GtG[free]
        self._smooth_rhs = np.asarray(smooth[:, marked] @ fixed_values)
        self._identity_rhs = np.asarray(ident[:, marked] @ fixed_values)
        smooth, ident = smooth[:, free].tocsr(), ident[:, free].tocsr()
        for m in (smooth, ident):
            m.eliminate_zeros()
            m.sum_duplicates()
        def ones(m):
            return sp.csr_matrix((np.ones(m.nnz), m.indices, m.indptr), shape=m.shape)
        pattern = (ones(smooth) + ones(ident) + sp.identity(nf, format="csr")).tocsr()
        pattern.sum_duplicates()               # canonical: rows in order, columns sorted
        keys = self._keys(pattern)

        def on_pattern(m):
            vals = np.zeros(pattern.nnz)
            vals[np.searchsorted(keys, self._keys(m))] = m.data
            return vals
        self._indices, self._indptr = pattern.indices, pattern.indptr
        self._smooth = on_pattern(smooth)
        self._identity = on_pattern(ident)
        self._diagonal = np.searchsorted(keys, np.arange(nf, dtype=np.int64) * (nf + 1))
        self.n = nf
        self.free = free
        self._factor = None
        self._factor_weights = None
        self._factor_diag = None
        self._factor_pivots = None        # diagonal of the factored matrix
        self._last_run = None           # (iterations, diagonal change) of the last CG
        self.factorizations = 0
        self.cg_iterations = 0

    @staticmethod
    def _keys(m) -> np.ndarray:
        rows = np.repeat(np.arange(m.shape[0], dtype=np.int64), np.diff(m.indptr))
        return rows * m.shape[1] + m.indices

    def matrix(self, w_smooth: float, w_identity: float, diag) -> sp.csr_matrix:
        """(f, f) csr free block for these weights and ``diag`` (f,) float64."""
        data = w_smooth * self._smooth + w_identity * self._identity
        data[self._diagonal] += diag
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(self.n, self.n))

    def solve(self, w_smooth: float, w_identity: float, diag, rhs, x0) -> np.ndarray:
        """Minimiser over the free unknowns.

        Parameters
        ----------
        w_smooth, w_identity : float
        diag : (f,) float64
            Diagonal term of the free unknowns.
        rhs : (f, 3) float64
            Right-hand side of the full system at the free rows (before the
            marked columns are moved over).
        x0 : (f, 3) float64
            Starting guess for conjugate gradients.

        Returns
        -------
        (f, 3) float64
        """
        H = self.matrix(w_smooth, w_identity, diag)
        b = rhs - (w_smooth * self._smooth_rhs + w_identity * self._identity_rhs)
        # conjugate gradients pay off only when factoring costs many solves
        if (self._factor is not None and self._factor.method == "cholesky"
                and self._factor_weights == (w_smooth, w_identity)):
            delta = np.abs(diag - self._factor_diag)
            change = float(delta.max(initial=0.0))
            # Skip a CG run that cannot pay off.  An entry whose diagonal more than
            # doubles is an outlying eigenvalue CG resolves with about one
            # iteration of its own (a huge w_C switched on where a closest point
            # became valid); and the iterations for a change spread over the
            # smooth modes grow with its square root (the condition number of the
            # preconditioned matrix), so the last run predicts the next.
            outliers = int(np.count_nonzero(delta > self._factor_pivots))
            last = self._last_run
            if outliers <= _CG_BUDGET // 2 and (
                    last is None or last[1] <= 0
                    or last[0] * np.sqrt(change / last[1]) <= _CG_BUDGET):
                run = conjugate_gradients(H, b, x0, self._factor, rtol=_CG_TOLERANCE,
                                          max_iterations=_CG_BUDGET, stop="error",
                                          give_up=True)
                self.cg_iterations += run.iterations
                if run.converged:
                    self._last_run = (run.iterations, change)
                    return run.x
        self._factor = (factorize(H, solves="few") if self._factor is None
                        else refactorize(self._factor, H))     # one pattern throughout
        self._factor_weights = (w_smooth, w_identity)
        self._factor_diag = np.array(diag, dtype=np.float64)
        self._factor_pivots = H.data[self._diagonal]
        self._last_run = None
        self.factorizations += 1
        return self._factor.solve(b)


def deform_toward(moving_V, moving_T, fixed_V, fixed_T, moving_ids, fixed_points,
                  schedule=SUMNER_SCHEDULE, neighbours: int = 16
                  ) -> tuple[np.ndarray, dict]:
    """Deform a mesh toward another with markers as hard constraints (SPEC §3.2).

    Each step minimises ``w_S E_S + w_I E_I + w_C E_C`` (normal equations over the
    vertices and fourth vertices, markers eliminated); the matrices of successive
    steps differ only on the diagonal, so they share factorisations
    (:class:`_FreeSystem`).

    Parameters
    ----------
    moving_V : (n, 3) float64
        Moving mesh, already aligned with the fixed one.
    moving_T : (t, 3) int64
    fixed_V : (q, 3) float64
    fixed_T : (s, 3) int64
    moving_ids : (m,) int64
        Constrained vertices of the moving mesh (unique).
    fixed_points : (m, 3) float64
        Where they must go.
    schedule : sequence of CorrespondenceStage
    neighbours : int

    Returns
    -------
    deformed : (n, 3) float64
    stats : dict
        ``valid_closest`` (fraction of vertices with a valid closest point, last
        step), ``solves``, ``factorizations``, ``cg_iterations``.
    """
    n = len(moving_V)
    op = gradient_operator(moving_V, moving_T)
    N, t = op.n_unknowns, op.n_triangles
    G = op.matrix
    GtG = (G.T @ G).tocsr()
    D = triangle_smoothness_operator(op, adjacent_triangle_pairs(moving_T))
    DtD = (D.T @ D).tocsr()
    identity_rhs = np.asarray(G.T @ np.tile(np.eye(3), (t, 1)))
    fixed = np.zeros(N, dtype=bool)
    fixed[moving_ids] = True
    order = np.argsort(moving_ids)
    P = np.asarray(fixed_points, dtype=np.float64)[order]
    system = _FreeSystem(DtD, GtG, fixed, P)
    free = system.free
    x = op.extend(moving_V)
    x[np.flatnonzero(fixed)] = P
    loose = np.zeros(N)
    loose[:n] = untethered_vertices(moving_T, n, moving_ids)
    tether = _TETHER * float(GtG.diagonal().mean() + DtD.diagonal().mean()) * loose
    tether_rhs = tether[:, None] * op.extend(moving_V)
    tree = ClosestPointTree(fixed_V, fixed_T)
    kd = cKDTree(tree.vertices)
    stats = {"solves": 0, "valid_closest": None}
    for stage in schedule:
        for _ in range(int(stage.iterations)):
            diag = tether.copy()
            rhs = stage.w_identity * identity_rhs + tether_rhs
            if stage.w_closest > 0:
                X = x[:n]
                normals = vertex_normals(X, moving_T)
                cp, valid = closest_valid_points(tree, kd, X, normals, neighbours)
                valid[moving_ids] = False
                w = stage.w_closest * valid
                diag[:n] += w
                rhs[:n] += w[:, None] * cp
                stats["valid_closest"] = float(valid.sum() / max(n - len(P), 1))
            x[free] = system.solve(stage.w_smooth, stage.w_identity, diag[free],
                                   rhs[free], x[free])
            stats["solves"] += 1
    stats.update(factorizations=system.factorizations, cg_iterations=system.cg_iterations)
    return x[:n], stats


def _centroids_normals(V: np.ndarray, T: np.ndarray):
    return V[T].mean(axis=1), face_normals(V, T)


def _nearest_compatible(query_c, query_n, tree: cKDTree, normals, k: int,
                        max_distance: float) -> np.ndarray:
    """Index of the nearest compatible triangle per query (-1 when none).

    The nearest triangle is compatible for almost every query, so only the others
    look further (``k`` candidates): a k-nearest query costs ~4x a nearest one.
    """
    k = min(k, tree.n)
    rows = np.arange(len(query_c))
    dist, idx = tree.query(query_c, k=1, distance_upper_bound=max_distance)
    found = np.isfinite(dist)
    safe = np.where(found, idx, 0)
    ok = found & (np.einsum("ij,ij->i", normals[safe], query_n) > 0)
    out = np.where(ok, safe, -1)
    retry = rows[found & ~ok] if k > 1 else rows[:0]
    if len(retry):
        dist, idx = tree.query(query_c[retry], k=k, distance_upper_bound=max_distance)
        dist, idx = dist.reshape(len(retry), k), idx.reshape(len(retry), k)
        found = np.isfinite(dist)
        safe = np.where(found, idx, 0)
        ok = found & (np.einsum("ikj,ij->ik", normals[safe], query_n[retry]) > 0)
        first = ok.argmax(axis=1)
        sub = np.arange(len(retry))
        out[retry] = np.where(ok[sub, first], safe[sub, first], -1)
    return out


def match_triangles(source_V, source_T, target_V, target_T, neighbours: int = 16,
                    max_distance: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
    """Match triangles by centroid distance and normals within 90°, both ways.

    Parameters
    ----------
    source_V : (n, 3) float64
        Source positions (deformed onto the target, or the target deformed onto it:
        the two meshes must lie on top of each other).
    source_T : (t, 3) int64
    target_V : (q, 3) float64
    target_T : (s, 3) int64
    neighbours : int
        Candidates examined per triangle, nearest first.
    max_distance : float
        Farthest centroid distance of a pair.

    Returns
    -------
    source_triangles, target_triangles : (k,) int64
        Sorted unique pairs: for every source triangle its nearest compatible
        target triangle, and for every target triangle its nearest compatible
        source triangle.
    """
    cs, ns = _centroids_normals(np.asarray(source_V, float), np.asarray(source_T))
    ct, nt = _centroids_normals(np.asarray(target_V, float), np.asarray(target_T))
    ts = _nearest_compatible(cs, ns, cKDTree(ct), nt, neighbours, max_distance)
    st = _nearest_compatible(ct, nt, cKDTree(cs), ns, neighbours, max_distance)
    a = np.flatnonzero(ts >= 0)
    b = np.flatnonzero(st >= 0)
    pairs = np.concatenate([np.stack([a, ts[a]], 1), np.stack([st[b], b], 1)])
    pairs = np.unique(pairs, axis=0) if len(pairs) else np.zeros((0, 2), np.int64)
    return pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)


def _align(moving: np.ndarray, fixed: np.ndarray, how: str) -> Similarity:
    if how == "none" or len(moving) < 3:
        return Similarity()
    return similarity_transform(moving, fixed, scale=(how == "similarity"))


def find_correspondence(source: Mesh, target: Mesh, markers,
                        settings: CorrespondenceSettings | None = None, *,
                        markers_path=None) -> Correspondence:
    """Compute the triangle correspondence of a source and a target mesh.

    Parameters
    ----------
    source, target : Mesh
        Reference meshes (any polygons; their fan triangulations are used).
    markers : (src, tgt) pair of (m,) int, or (m, 2) int
        Source vertex ↔ target vertex pairs, 0-based, at least one (three or more
        for the alignment).
    settings : CorrespondenceSettings, optional
    markers_path : str, optional
        Marker file, named in error messages.

    Returns
    -------
    Correspondence

    Raises
    ------
    InputError
        Marker ids out of range.
    """
    settings = settings or CorrespondenceSettings()
    src_ids, tgt_ids = check_markers(markers, source.n_vertices, target.n_vertices,
                                     markers_path)
    t0 = time.perf_counter()
    if settings.deform == "source":
        moving, fixed, m_ids, f_ids = source, target, src_ids, tgt_ids
    else:
        moving, fixed, m_ids, f_ids = target, source, tgt_ids, src_ids
    # one position per constrained moving vertex (mean when it is paired twice)
    uniq, inv = np.unique(m_ids, return_inverse=True)
    cnt = np.bincount(inv)
    goal = np.stack([np.bincount(inv, fixed.vertices[f_ids][:, d]) for d in range(3)],
                    axis=1) / cnt[:, None]
    align = _align(moving.vertices[m_ids], fixed.vertices[f_ids], settings.align)
    lo, hi = fixed.bounding_box()
    centre, unit = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0
    norm = lambda P: (P - centre) / unit   # noqa: E731
    Vm = norm(align.apply(moving.vertices))
    Vf = norm(fixed.vertices)
    deformed, stats = deform_toward(Vm, moving.triangles, Vf, fixed.triangles, uniq,
                                    norm(goal), settings.schedule, settings.neighbours)
    t1 = time.perf_counter()
    max_d = np.inf if settings.max_distance is None else float(settings.max_distance)
    if settings.deform == "source":
        s_tri, t_tri = match_triangles(deformed, source.triangles, Vf, target.triangles,
                                       settings.neighbours, max_d)
    else:
        s_tri, t_tri = match_triangles(Vf, source.triangles, deformed, target.triangles,
                                       settings.neighbours, max_d)
    t2 = time.perf_counter()
    stats.update(deform_seconds=t1 - t0, match_seconds=t2 - t1, pairs=int(len(s_tri)))
    corr = Correspondence(
        _ro(s_tri), _ro(t_tri), source.n_vertices, len(source.triangles),
        target.n_vertices, len(target.triangles),
        _ro(np.stack([src_ids, tgt_ids], axis=1)), _ro(deformed * unit + centre),
        settings.deform, stats)
    stats.update(unmatched_source=int(len(corr.unmatched_source)),
                 unmatched_target=int(len(corr.unmatched_target)))
    return corr
