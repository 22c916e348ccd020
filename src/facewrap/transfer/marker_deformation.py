"""The marker-constrained deformation of the correspondence step (SPEC §3.2).

One mesh (the *moving* one) is deformed toward the other (the *fixed* one), keeping
its topology, by minimising

    smooth_weight E_S + identity_weight E_I + closest_weight E_C

over its vertices and fourth vertices (:mod:`.gradients`), with the markers as
hard constraints eliminated exactly (:func:`facewrap.solve.split_fixed`: their
columns move to the right-hand side).  ``E_S`` asks neighbouring triangles for
equal deformation gradients, ``E_I`` for gradients near the identity, ``E_C`` for
vertices near their closest compatible point on the fixed mesh (normals within
90°, :func:`facewrap.geometry.matching.closest_compatible_points` with its
nearest-vertex fallback).  A :class:`CorrespondenceStage` per step gives the
weights; :data:`SUMNER_SCHEDULE` starts with ``closest_weight = 0`` and raises it
to 5000, recomputing closest points every step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.spatial import cKDTree

from facewrap.geometry import ClosestPointTree, vertex_normals
from facewrap.geometry.matching import closest_compatible_points
from facewrap.params import Interval, validate
from facewrap.solve import conjugate_gradients, factorize, refactorize, split_fixed
from facewrap.transfer.constraints import TETHER_WEIGHT, untethered_vertices
from facewrap.transfer.gradients import (adjacent_triangle_pairs, gradient_operator,
                                         triangle_smoothness_operator)

__all__ = ["CorrespondenceStage", "SUMNER_SCHEDULE", "WeightedFreeSystem",
           "deform_toward"]


@dataclass(frozen=True)
class CorrespondenceStage:
    """Weights of one step of the correspondence deformation.

    Attributes
    ----------
    smooth_weight : float
        ``w_S``, equal gradients of neighbouring triangles.
    identity_weight : float
        ``w_I``, gradients near the identity (the moving mesh keeps its shape).
    closest_weight : float
        ``w_C``, vertices near their closest compatible point (in units of the
        fixed mesh's bounding-box diagonal); 0 switches the term off.
    iterations : int
        Solves in this step, closest points recomputed before each.

    Raises
    ------
    ValueError
        A value outside :attr:`constraints`, or ``smooth_weight +
        identity_weight`` zero (nothing would hold the mesh's shape).
    """

    smooth_weight: float = 1.0
    identity_weight: float = 0.001
    closest_weight: float = 0.0
    iterations: int = 1

    constraints = {
        "smooth_weight": Interval(float, 0, None),
        "identity_weight": Interval(float, 0, None),
        "closest_weight": Interval(float, 0, None),
        "iterations": Interval(int, 1, None),
    }

    def __post_init__(self):
        validate(self)
        if self.smooth_weight + self.identity_weight <= 0:
            raise ValueError("CorrespondenceStage.smooth_weight + identity_weight "
                             "must be positive; got 0")


#: Sumner & Popović 2004: w_S = 1, w_I = 0.001, first w_C = 0, then w_C from 1 to
#: 5000 in four steps (``smooth_weight``, ``identity_weight``, ``closest_weight``).
SUMNER_SCHEDULE: tuple[CorrespondenceStage, ...] = (
    CorrespondenceStage(1.0, 0.001, 0.0),
    *(CorrespondenceStage(1.0, 0.001, float(w)) for w in np.geomspace(1.0, 5000.0, 4)),
)


#: Conjugate gradients stop when the preconditioned residual (an estimate of the
#: remaining error, an overestimate for a preconditioner factored with smaller
#: diagonal) is below this fraction of the largest coordinate.  The deformed
#: meshes then differ from exact solves by far less than the closest-point
#: distances (measured on ICT → Oldman, cat → lion, horse → camel): the same
#: closest points, the same triangle pairs.
_CG_TOLERANCE = 1e-7

#: Back-substitutions worth one new factorisation.  A supernodal Cholesky of the
#: systems here costs a few dozen back-substitutions with the reference BLAS
#: cholespy ships; conjugate gradients that would need more than this give up early
#: (judged from their convergence rate) and the matrix is factored instead.
_CG_BUDGET = 40


class WeightedFreeSystem:
    """``w_S DᵀD + w_I GᵀG + diag(d)`` over the free unknowns, for changing weights.

    Every solve of a correspondence schedule has this matrix with the marked
    unknowns eliminated, and between steps only ``d`` changes (``w_C`` on the
    vertices with a valid closest point, the tether), ``w_S`` and ``w_I`` from stage
    to stage.  So the free block of each term is cut out once, onto one sparsity
    pattern that includes the whole diagonal, and a step's matrix is a weighted sum
    of value arrays; the marked columns become two fixed right-hand-side offsets.

    Each step's matrix is factored with CHOLMOD's supernodal Cholesky
    (``factorize(..., solves="few")``, several times faster to factor than
    cholespy, whose back-substitutions are cheaper): five factorisations and five
    solves for :data:`SUMNER_SCHEDULE`.  Without cvxopt (cholespy only),
    solves reuse the last factorisation as a preconditioner of conjugate gradients
    (three coordinates at once, one back-substitution per iteration for all three),
    warm-started at the previous step's solution: a diagonal change costs a few
    back-substitutions instead of a factorisation.  When
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

    Attributes
    ----------
    n : int
        Free unknowns.
    free : (n,) int64
        Their indices.
    factorizations, cg_iterations : int
        Work done so far (factorisations, conjugate-gradient iterations).
    fixed : (N,) bool
        Marked unknowns.
    fixed_values : (m, 3) float64
        Their positions, in the order of ``np.flatnonzero(fixed)``.
    """

    def __init__(self, DtD, GtG, fixed: np.ndarray, fixed_values: np.ndarray):
        # the two terms' free blocks, and their marked columns times the markers'
        # positions: fixed right-hand-side offsets
        free, _, smooth, smooth_known = split_fixed(DtD, fixed)
        _, _, ident, ident_known = split_fixed(GtG, fixed)
        nf = len(free)
        self._smooth_rhs = np.asarray(smooth_known @ fixed_values)
        self._identity_rhs = np.asarray(ident_known @ fixed_values)
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

    def matrix(self, smooth_weight: float, identity_weight: float,
               diag) -> sp.csr_matrix:
        """(f, f) csr free block for these weights and ``diag`` (f,) float64."""
        data = smooth_weight * self._smooth + identity_weight * self._identity
        data[self._diagonal] += diag
        return sp.csr_matrix((data, self._indices, self._indptr), shape=(self.n, self.n))

    def solve(self, smooth_weight: float, identity_weight: float, diag, rhs,
              x0) -> np.ndarray:
        """Minimiser over the free unknowns.

        Parameters
        ----------
        smooth_weight, identity_weight : float
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
        weights = (smooth_weight, identity_weight)
        H = self.matrix(*weights, diag)
        b = rhs - (smooth_weight * self._smooth_rhs
                   + identity_weight * self._identity_rhs)
        # conjugate gradients pay off only when factoring costs many solves
        if (self._factor is not None and self._factor.method == "cholesky"
                and self._factor_weights == weights):
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
        self._factor_weights = weights
        self._factor_diag = np.array(diag, dtype=np.float64)
        self._factor_pivots = H.data[self._diagonal]
        self._last_run = None
        self.factorizations += 1
        return self._factor.solve(b)


def deform_toward(moving_V, moving_T, fixed_V, fixed_T, moving_ids, fixed_points,
                  schedule=SUMNER_SCHEDULE, neighbours: int = 16
                  ) -> tuple[np.ndarray, dict]:
    """Deform a mesh toward another with markers as hard constraints (SPEC §3.2).

    Each step minimises ``w_S E_S + w_I E_I + w_C E_C`` (the stage's weights;
    normal equations over the vertices and fourth vertices, markers eliminated);
    the matrices of successive steps differ only on the diagonal, so they share
    factorisations (:class:`WeightedFreeSystem`).

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
    system = WeightedFreeSystem(DtD, GtG, fixed, P)
    free = system.free
    x = op.extend(moving_V)
    x[np.flatnonzero(fixed)] = P
    loose = np.zeros(N)
    loose[:n] = untethered_vertices(moving_T, n, moving_ids)
    tether = TETHER_WEIGHT * float(GtG.diagonal().mean() + DtD.diagonal().mean()) * loose
    tether_rhs = tether[:, None] * op.extend(moving_V)
    tree = ClosestPointTree(fixed_V, fixed_T)
    vertex_tree = cKDTree(tree.vertices)
    stats = {"solves": 0, "valid_closest": None}
    for stage in schedule:
        for _ in range(int(stage.iterations)):
            diag = tether.copy()
            rhs = stage.identity_weight * identity_rhs + tether_rhs
            if stage.closest_weight > 0:
                valid, cp = _closest_targets(tree, vertex_tree, x[:n], moving_T,
                                             neighbours)
                valid[moving_ids] = False
                w = stage.closest_weight * valid
                diag[:n] += w
                rhs[:n] += w[:, None] * cp
                stats["valid_closest"] = float(valid.sum() / max(n - len(P), 1))
            x[free] = system.solve(stage.smooth_weight, stage.identity_weight,
                                   diag[free], rhs[free], x[free])
            stats["solves"] += 1
    stats.update(factorizations=system.factorizations, cg_iterations=system.cg_iterations)
    return x[:n], stats




def _closest_targets(tree: ClosestPointTree, vertex_tree: cKDTree, X, T, neighbours):
    """(valid (n,) bool, points (n, 3)): each vertex's closest point on the fixed
    mesh whose normal is within 90° of the vertex normal (else the nearest of
    ``neighbours`` fixed vertices whose normal is); rows without one keep ``X``."""
    matches = closest_compatible_points(tree, X, vertex_normals(X, T),
                                        max_normal_angle=90.0, fallback=vertex_tree,
                                        neighbours=neighbours)
    points = np.array(X, dtype=np.float64)
    points[matches.index] = matches.points
    return matches.accepted.copy(), points
