"""Flip repair: unfold the triangles a transfer folded over where the source did not.

A least-squares transfer matches each target triangle's gradient to its source
partners' only on average, and where the target cannot follow (a crease matched
to both lips as the mouth opens, tiny triangles the source squeezes, an avatar
eye without lid geometry pulled shut by its landmarks) a few triangles turn past
90°.  :class:`FlipRepair` finds those *new* flips (the turn test is
:func:`facewrap.geometry.turned`, at 90° for a flip and :data:`REPAIR_TURN` for a
transferred gradient that itself turns the triangle) and re-solves the poses that
have one locally (:class:`facewrap.solve.FixedSystem`: a few vertex rings free,
the rest of the pose known).  :class:`~facewrap.transfer.DeformationTransfer` and
:class:`~facewrap.avatar.AvatarTransfer` both use it.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import triangle_normals, turned, turned_from, vertex_adjacency
from facewrap.solve import FixedSystem
from facewrap.transfer.gradients import (GradientOperator, fourth_vertex_offsets,
                                         typical_edge_length)

__all__ = ["FlipRepair", "nearest_proper_maps", "REPAIR_TURN", "REPAIR_MARGINS"]


#: Flip repair (:class:`FlipRepair`): first weight of the unfolding term (times the
#: system's diagonal at the triangle), its growth per round where a triangle still
#: flips, rounds per schedule, the margins tried in turn (smallest singular value /
#: largest of an unfolded triangle's in-plane map), and how many vertex rings
#: around the repaired triangles are re-solved.
_REPAIR_WEIGHT = 1.0
_REPAIR_GROWTH = 10.0
_REPAIR_ROUNDS = 10
REPAIR_MARGINS = (0.1, 0.05, 0.2)
_REPAIR_RINGS = 3
#: A flipped target triangle whose transferred gradient turns its normal by more
#: than this (degrees) follows the source and is not repaired.
REPAIR_TURN = 95.0


class FlipRepair:
    """Finds and unfolds the flipped triangles a transfer made (set up once per pair).

    A least-squares transfer matches each target triangle's gradient to its source
    partners' only on average.  Where the target cannot follow — a mouth corner
    whose crease is matched to both lips as they part, tiny triangles in a crease
    the source squeezes, an avatar eye without lid geometry whose lid landmarks are
    pulled shut — a few triangles fold over: their normal turns more than 90°
    against the target reference although none of their source partners flips.
    Those are *new* flips, made by the transfer.  Flips the source makes itself (a
    lid rolling over the eye, lips pressed through each other) are *copied* on
    purpose and left alone.

    :meth:`repair` re-solves one pose in rounds, local/global as in
    as-rigid-as-possible.  Local step: each offending triangle's goal is its current
    in-plane map with the part in its rest plane replaced by the nearest proper map
    (reflection removed, singular values at least ``margin`` times the largest):
    the smallest change that unfolds it.  Global step: the system plus a term
    pulling the triangle's edges toward that goal, re-solved on a few vertex rings
    around the triangles that still flip (a small sparse system, factored anew; the
    rest of the pose keeps its solution).  The term's weight starts at the system's
    own stiffness at the triangle and grows tenfold each round it still flips;
    triangles that unfolded keep their term (goal: their current shape, proper), so
    the fold is not pushed back onto them.  The round with the fewest new flips is
    kept, so a repair never makes a pose worse; if flips remain after
    :data:`_REPAIR_ROUNDS`, the schedule is retried with another margin
    (:data:`REPAIR_MARGINS`).

    Two other repairs were measured and dropped: pulling offenders toward the
    rotation of their transferred gradient (or toward the neutral), and relaxing
    the region (fading its data term, adding gradient smoothness).  Both stiffen a
    whole patch where partners' goals disagree (at a mouth corner one lip turns up,
    the other down), and the stiff patch folds its border: more flips, not fewer.

    Parameters
    ----------
    reference : (n, 3) float64
        Target reference, in the frame of the solve.
    triangles : (t, 3) int64
    source_op : GradientOperator
        Of the source reference.
    source_reference : (n_source, 3) float64
    pairs : (t, t_source) scipy.sparse.csr_matrix
        Every target triangle's source partners (:func:`complete_pairs`).
    fixed : sequence of int
        Vertices the system keeps fixed (the anchor).
    """

    def __init__(self, reference, triangles, source_op: GradientOperator,
                 source_reference, pairs, fixed=()):
        V0 = np.asarray(reference, dtype=np.float64)
        T = np.asarray(triangles, dtype=np.int64)
        n, t = len(V0), len(T)
        self.reference, self.triangles = V0, T
        self._source_op = source_op
        self._source_reference = np.asarray(source_reference, dtype=np.float64)
        self._pairs = pairs.tocsr()
        sums = np.asarray(self._pairs.sum(axis=1)).ravel()
        self._matched = sums > 0
        self._mean_pairs = (sp.diags(1.0 / np.where(self._matched, sums, 1.0))
                            @ self._pairs).tocsr()
        self._fixed = np.zeros(n, dtype=bool)
        self._fixed[np.asarray(fixed, dtype=np.int64)] = True
        self._incidence = sp.csr_matrix((np.ones(3 * t), (np.repeat(np.arange(t), 3),
                                                          T.ravel())), shape=(t, n))
        self._incidence_t = self._incidence.T.tocsr()
        self._adjacency = vertex_adjacency(T, n)
        # each triangle's rest plane: orthonormal basis (t, 3, 2) with u along
        # v1 - v0, the edges v1 - v0, v2 - v0 in it (t, 2, 2: upper triangular) and
        # their inverse (zero for a degenerate triangle, which never counts as flipped)
        e1 = V0[T[:, 1]] - V0[T[:, 0]]
        e2 = V0[T[:, 2]] - V0[T[:, 0]]
        self._normals = np.cross(e1, e2)
        self._source_normals = triangle_normals(self._source_reference, source_op.triangles)
        a = np.linalg.norm(e1, axis=1)
        u = e1 / np.maximum(a, 1e-300)[:, None]
        v = np.cross(self._normals, u)
        v /= np.maximum(np.linalg.norm(v, axis=1), 1e-300)[:, None]
        self._basis = np.stack([u, v], axis=2)
        b = np.einsum("ij,ij->i", e2, u)
        d = np.einsum("ij,ij->i", e2, v)
        E = np.zeros((t, 2, 2))
        E[:, 0, 0], E[:, 0, 1], E[:, 1, 1] = a, b, d
        ok = (a > 0) & (d > 0)
        ad = np.where(ok, a * d, 1.0)
        self._edges_inv = np.zeros((t, 2, 2))
        self._edges_inv[:, 0, 0] = np.where(ok, d / ad, 0.0)
        self._edges_inv[:, 0, 1] = np.where(ok, -b / ad, 0.0)
        self._edges_inv[:, 1, 1] = np.where(ok, a / ad, 0.0)
        # the three edges head - tail (v1 - v0, v2 - v1, v0 - v2) in the rest plane
        self._edges = np.stack([E[:, :, 0], E[:, :, 1] - E[:, :, 0], -E[:, :, 1]], axis=2)
        self._ends = np.stack([T[:, [1, 2, 0]], T], axis=2)              # (t, 3, 2)

    def offenders(self, X, poses) -> tuple[np.ndarray, np.ndarray]:
        """New flips and copied flips of transferred poses.

        A flipped target triangle is *copied* when one of its source partners flips
        too, or when the transferred gradient (the mean of its partners' gradients)
        itself turns its normal by more than :data:`REPAIR_TURN`: a limb turned
        past 90° by the source, or lips rolling in, follow the source.  Every other
        flipped triangle is *new*.

        Parameters
        ----------
        X : (k, n, 3) float64
            Transferred target poses (any translation).
        poses : (k, n_source, 3) float64
            The source poses they came from.

        Returns
        -------
        new, copied : (k, t) bool
            ``copied`` is only filled in for poses with a flipped triangle.
        """
        flipped = turned_from(self._normals, X, self.triangles)
        copied = np.zeros_like(flipped)
        some = np.flatnonzero(flipped.any(axis=1))
        if len(some):
            src = turned_from(self._source_normals, np.asarray(poses)[some],
                              self._source_op.triangles)
            copied[some] = (self._pairs @ src.T.astype(np.float64)).T > 0
        for j in some:
            cand = np.flatnonzero(flipped[j] & ~copied[j])
            if len(cand):
                copied[j, cand] = self.follows_source(poses[j], cand)
        return flipped & ~copied, copied

    def follows_source(self, pose, tris) -> np.ndarray:
        """Whether the rotation of each triangle's transferred gradient (the mean of
        its partners' gradients) turns its rest normal by more than
        :data:`REPAIR_TURN`: such a flip follows the source.

        Parameters
        ----------
        pose : (n_source, 3) float64
            A source pose.
        tris : (r,) int64
            Target triangles to test.

        Returns
        -------
        (r,) bool
        """
        rows = self._mean_pairs[tris]
        src, inv = np.unique(rows.indices, return_inverse=True)
        # the partners' gradients Q = [x1 - x0, x2 - x0, x3 - x0] V⁻¹, fourth vertex x3
        # built as the gradient operator builds it
        Ts = self._source_op.triangles[src]
        e1, e2 = pose[Ts[:, 1]] - pose[Ts[:, 0]], pose[Ts[:, 2]] - pose[Ts[:, 0]]
        e3, _ = fourth_vertex_offsets(e1, e2, typical_edge_length(e1, e2))
        Q = np.stack([e1, e2, e3], axis=2) @ self._source_op.inverse_edges[src]
        local = sp.csr_matrix((rows.data, inv.ravel(), rows.indptr),
                              shape=(len(tris), len(src)))
        S = np.asarray(local @ Q.reshape(-1, 9)).reshape(-1, 3, 3)
        S[~self._matched[tris]] = np.eye(3)
        U, _, Vt = np.linalg.svd(S)
        U[:, :, 2] *= np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)[:, None]
        n0 = self._normals[tris]
        return turned(n0, np.einsum("tij,tj->ti", U @ Vt, n0), REPAIR_TURN)

    def repair_poses(self, H, rhs, x, poses) -> tuple[np.ndarray, dict]:
        """Repair every pose of a solve that has new flips; leave the others.

        Parameters
        ----------
        H : (N, N) scipy.sparse.csr_matrix
            The system's matrix (see :meth:`repair`).
        rhs, x : (N, 3 k) float64
            Right-hand sides and plain solutions, column ``3 j + d`` coordinate
            ``d`` of pose ``j``.
        poses : (k, n_source, 3) float64

        Returns
        -------
        out : (k, n, 3) float64
            Target vertices; a pose without new flips is the plain solution.
        stats : dict of (k,) int64
            Per pose, :meth:`repair`'s ``found``, ``repaired``, ``remaining`` and
            ``rounds`` (zero where nothing was repaired).
        """
        n, k = len(self.reference), len(poses)
        out = x[:n].reshape(n, k, 3).transpose(1, 0, 2)
        bad, copied = self.offenders(out, poses)
        stats = {key: np.zeros(k, dtype=np.int64)
                 for key in ("found", "repaired", "remaining", "rounds")}
        todo = np.flatnonzero(bad.any(axis=1))
        if len(todo):
            out = out.copy()
        for j in todo:
            cols = slice(3 * j, 3 * j + 3)
            xj, st = self.repair(H, rhs[:, cols], x[:, cols], poses[j], bad[j], copied[j])
            out[j] = xj[:n]
            for key, value in st.items():
                stats[key][j] = value
        return out, stats

    def repair(self, H, rhs, x, pose, bad, copied) -> tuple[np.ndarray, dict]:
        """Re-solve one pose until it has no new flip (or the rounds run out).

        Parameters
        ----------
        H : (N, N) scipy.sparse.csr_matrix
            The system's matrix: ``n`` vertices first, then (if ``N = n + t``) one
            fourth vertex per triangle.  Rows of fixed vertices are not used.
        rhs : (N, 3) float64
            Its right-hand side for this pose.
        x : (N, 3) float64
            The plain solution (fixed vertices at their values).
        pose : (n_source, 3) float64
            The source pose.
        bad, copied : (t,) bool
            This pose's :meth:`offenders`.

        Returns
        -------
        x : (N, 3) float64
            The repaired solution (``x`` itself when nothing improved).
        stats : dict
            ``found`` (new flips at first), ``repaired`` (triangles given the
            unfolding term), ``remaining`` (new flips left), ``rounds``.
        """
        x = np.asarray(x, dtype=np.float64)
        diag = H.diagonal()[:len(self.reference)]
        # triangles that flip during the repair are checked against the source too
        follows = _CopiedFlips(self, pose, copied, bad)
        best = x
        stats = {"found": int(bad.sum()), "repaired": 0, "remaining": int(bad.sum()),
                 "rounds": 0}
        for margin in REPAIR_MARGINS:
            if stats["remaining"] == 0:
                break
            y, left, repaired, rounds = self._unfold(H, rhs, x, bad, follows, diag,
                                                     margin)
            stats["repaired"] = max(stats["repaired"], repaired)
            stats["rounds"] += rounds
            if left < stats["remaining"]:
                best, stats["remaining"] = y, left
        return best, stats

    def _unfold(self, H, rhs, x, bad, follows, diag, margin):
        """One schedule of :meth:`repair`: (best x, its new flips, triangles given
        the term, rounds)."""
        n, t = len(self.reference), len(self.triangles)
        best, best_count = x, int(bad.sum())
        w = np.zeros(t)
        rounds = 0
        while bad.any() and rounds < _REPAIR_ROUNDS:
            rounds += 1
            w[bad] = np.where(w[bad] > 0, w[bad] * _REPAIR_GROWTH, _REPAIR_WEIGHT)
            # the region re-solved: a few vertex rings around the triangles that flip
            # now (triangles unfolded in earlier rounds elsewhere stay as they are)
            region = self._incidence_t @ bad.astype(np.float64) > 0
            for _ in range(_REPAIR_RINGS):
                region |= self._adjacency @ region.astype(np.float64) > 0
            near = self._incidence @ region.astype(np.float64) > 0
            x = self._resolve(H, rhs, x, np.flatnonzero((w > 0) & near), w, diag,
                              region, near, margin)
            bad = np.zeros(t, dtype=bool)
            bad[near] = turned_from(self._normals[near], x[None, :n], self.triangles[near])[0]
            bad &= ~follows(bad)
            if bad.sum() < best_count:
                best, best_count = x, int(bad.sum())
        return best, best_count, int((w > 0).sum()), rounds

    def _resolve(self, H, rhs, x, R, w, diag, region, near, margin) -> np.ndarray:
        """One local/global round: the repaired triangles ``R`` pulled toward their
        nearest proper maps, the system re-solved on ``region`` (vertices) and the
        fourth vertices of the ``near`` triangles, everything else kept."""
        n, t = len(self.reference), len(self.triangles)
        N = H.shape[0]
        T = self.triangles[R]
        # local step: the nearest proper in-plane map of each repaired triangle
        F = np.stack([x[T[:, 1]] - x[T[:, 0]], x[T[:, 2]] - x[T[:, 0]]], axis=2)
        F = nearest_proper_maps(F @ self._edges_inv[R], self._basis[R], margin)
        goal = np.einsum("rik,rke->rei", F, self._edges[R]).reshape(-1, 3)
        c = np.repeat(w[R] * diag[T].mean(axis=1), 3)
        # global step: H + Eᵀ C E (E: the repaired triangles' edges, head - tail)
        # with every unknown outside the region known at its current value
        free = np.zeros(N, dtype=bool)
        free[:n] = region & ~self._fixed
        if N == n + t:                              # fourth vertices of those triangles
            free[n:] = near
        ends = self._ends[R].reshape(-1, 2)                              # (3r, 2)
        E = sp.csr_matrix((np.tile([1.0, -1.0], len(ends)),
                           (np.repeat(np.arange(len(ends)), 2), ends.ravel())),
                          shape=(len(ends), N))
        J = np.flatnonzero(free)
        E_J = E[:, J]
        system = FixedSystem.from_free_rows(H[J] + E_J.T @ sp.diags(c) @ E, ~free,
                                            solves="few", check=False)
        # the term's right-hand side only touches the free rows: added there, so
        # the full right-hand side is not copied every round
        b_free = system.free_rhs(rhs, x[system.known]) + E_J.T @ (c[:, None] * goal)
        x = x.copy()
        x[J] = system.factor.solve(b_free)
        return x


class _CopiedFlips:
    """Copied flips of one pose, checked lazily for triangles that start to flip."""

    def __init__(self, repair: FlipRepair, pose, copied, bad):
        self._repair, self._pose = repair, pose
        self._copied = copied.copy()
        self._known = copied | bad

    def __call__(self, flipped) -> np.ndarray:
        """(t,) bool: which of the ``flipped`` triangles follow the source."""
        new = np.flatnonzero(flipped & ~self._known)
        if len(new):
            self._copied[new] = self._repair.follows_source(self._pose, new)
            self._known[new] = True
        return self._copied & flipped


def nearest_proper_maps(F, basis, margin: float) -> np.ndarray:
    """In-plane maps ``F`` (m, 3, 2) with their rest-plane part made proper.

    ``basis`` (m, 3, 2) spans each rest plane; the 2 x 2 part ``A = basisᵀ F`` is
    replaced by the nearest matrix with positive determinant and singular values at
    least ``margin`` times the largest (a reflection removed, a collapse opened);
    the part off the rest plane is kept.  The local step of :class:`FlipRepair`.

    Parameters
    ----------
    F : (m, 3, 2) float64
        In-plane maps (deformed edges times the rest edges' inverse).
    basis : (m, 3, 2) float64
        Orthonormal bases of the rest planes.
    margin : float
        Smallest allowed ratio of the singular values.

    Returns
    -------
    (m, 3, 2) float64

    Examples
    --------
    A reflection across the rest plane's v axis is turned back:

    >>> basis = np.array([[[1.0, 0], [0, 1], [0, 0]]])
    >>> F = np.array([[[1.0, 0], [0, -1], [0, 0]]])
    >>> bool(np.linalg.det(nearest_proper_maps(F, basis, 0.1)[0, :2]) > 0)
    True
    """
    A = np.einsum("mki,mkc->mic", basis, F)
    U, s, Vt = np.linalg.svd(A)
    U[:, :, 1] *= np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)[:, None]
    s[:, 1] = np.maximum(s[:, 1], margin * s[:, 0])
    return F + basis @ (U @ (s[:, :, None] * Vt) - A)
