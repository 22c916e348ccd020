"""Deformation transfer of source poses onto a target (SPEC §3.3).

This module owns the transfer solve.  For each source pose, the target vertices
minimise ``Σ_{(s,t)∈M} ||S_s - T_t||²_F`` where ``S_s`` is source triangle ``s``'s
deformation gradient (reference → pose) and ``T_t = x V̂_t^-1`` the target's
(:mod:`.gradients`).  The normal matrix depends only on the target reference and
the correspondence ``M``, so :class:`DeformationTransfer` factors it once in
:meth:`~DeformationTransfer.fit` (sparse Cholesky, one ``(n + t)``-sized factor
shared by x, y and z) and each pose is one back-substitution with three
right-hand sides; many poses are solved together as ``3 k`` right-hand sides.

Translation is free in the energy: one target vertex (the *anchor*) is eliminated
at its reference position, and with ``anchor="markers"`` the result is then
translated so that the target markers' centroid moves as the source markers'
centroid does.  Target triangles that have no partner in ``M`` follow their
neighbours (they borrow their neighbours' partners), so every unknown is
determined.  A fourth vertex appears only in its own triangle's gradient, so the
fourth-vertex block of the normal matrix is diagonal and is eliminated exactly: the
factor has one unknown per target vertex (minus the anchor).

The least-squares solve matches gradients only on average, and where the target
cannot follow its partners (a crease matched to both lips as the mouth opens, tiny
triangles the source squeezes) it folds a few triangles over although their
partners do not flip.  With ``fix_flips`` (the default) such poses are re-solved
locally until no such *new* flip remains (:class:`_FlipRepair`); poses without
one keep the plain back-substitution, bit for bit.
"""

from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import vertex_adjacency
from facewrap.geometry.checks import as_triangles, as_vertices
from facewrap.mesh import Mesh
from facewrap.solve import FixedSystem, factorize
from facewrap.transfer.correspondence import _TETHER, Correspondence, untethered_vertices
from facewrap.transfer.gradients import (GradientOperator, _fourth_offsets, _typical_edge,
                        adjacent_triangle_pairs, gradient_operator)

__all__ = ["DeformationTransfer", "pair_matrix", "complete_pairs",
           "source_gradient_blocks", "extend_poses", "as_pose_stack",
           "flipped_triangles"]

#: Flip repair (:class:`_FlipRepair`): first weight of the unfolding term (times the
#: system's diagonal at the triangle), its growth per round where a triangle still
#: flips, rounds per schedule, the margins tried in turn (smallest singular value /
#: largest of an unfolded triangle's in-plane map), and how many vertex rings
#: around the repaired triangles are re-solved.
_REPAIR_WEIGHT = 1.0
_REPAIR_GROWTH = 10.0
_REPAIR_ROUNDS = 10
_REPAIR_MARGINS = (0.1, 0.05, 0.2)
_REPAIR_RINGS = 3
#: A flipped target triangle whose transferred gradient turns its normal by more
#: than this (degrees) follows the source and is not repaired.
_REPAIR_TURN = 95.0


def as_pose_stack(poses, n_vertices: int, name: str = "poses") -> tuple[np.ndarray, bool]:
    """Poses as a (k, n, 3) float64 stack, and whether one (n, 3) pose was given.

    Raises
    ------
    ValueError
        Naming ``name``, when the vertex count or shape is wrong or values are
        not finite.
    """
    P = np.asarray(poses, dtype=np.float64)
    single = P.ndim == 2
    if single:
        P = P[None]
    if P.ndim != 3 or P.shape[1:] != (n_vertices, 3):
        raise ValueError(f"{name} must have shape (k, {n_vertices}, 3) or "
                         f"({n_vertices}, 3), got {np.shape(poses)}")
    if not np.isfinite(P).all():
        raise ValueError(f"{name} contain NaN or infinite coordinates")
    return P, single


def pair_matrix(correspondence: Correspondence) -> sp.csr_matrix:
    """(t_target, t_source) sparse 0/1 matrix of the triangle pairs ``M``."""
    c = correspondence
    return sp.csr_matrix((np.ones(len(c)), (c.target_triangles, c.source_triangles)),
                         shape=(c.n_target_triangles, c.n_source_triangles))


def complete_pairs(pairs: sp.csr_matrix, target_T) -> tuple[sp.csr_matrix, np.ndarray]:
    """Give unmatched target triangles the partners of their matched neighbours.

    Grows ring by ring across edges, so a target triangle without a partner in
    ``M`` deforms like the triangles around it.  Triangles of a component with no
    match at all become *orphans* (kept near their rest shape).

    Parameters
    ----------
    pairs : (t_target, t_source) scipy.sparse.csr_matrix
        From :func:`pair_matrix`.
    target_T : (t_target, 3) int64

    Returns
    -------
    pairs : (t_target, t_source) csr_matrix
        With rows filled in (each new row averages its neighbours' partners, rows
        scaled to sum to 1).
    orphans : (t_target,) float64
        1 for orphan triangles, else 0.
    """
    matched = np.asarray(pairs.getnnz(axis=1)) > 0
    if matched.all():
        return pairs, np.zeros(len(matched))
    adj = adjacent_triangle_pairs(target_T)
    t = len(matched)
    A = sp.csr_matrix((np.ones(2 * len(adj)), (np.r_[adj[:, 0], adj[:, 1]],
                                               np.r_[adj[:, 1], adj[:, 0]])),
                      shape=(t, t))
    P = pairs.tocsr().astype(np.float64)
    while not matched.all():
        rows = ~matched & (A @ matched.astype(np.float64) > 0)
        if not rows.any():
            break
        grow = sp.diags(rows.astype(np.float64)) @ A @ sp.diags(matched.astype(np.float64))
        new = (grow @ P).tocsr()
        sums = np.asarray(new.sum(axis=1)).ravel()
        new = sp.diags(np.where(sums > 0, 1.0 / np.where(sums > 0, sums, 1), 0)) @ new
        P = (P + new).tocsr()
        matched = matched | rows
    return P, (~matched).astype(np.float64)


def extend_poses(op: GradientOperator, poses: np.ndarray) -> np.ndarray:
    """Poses with their fourth vertices, as columns: (n + t, 3 k) float64.

    Column ``3 j + d`` is coordinate ``d`` of pose ``j`` (the layout ``op.matrix``
    multiplies); all poses' fourth vertices are built in one vectorised pass.
    """
    k, n = poses.shape[0], poses.shape[1]
    T = op.triangles
    P0 = poses[:, T[:, 0]].reshape(-1, 3)
    e1 = poses[:, T[:, 1]].reshape(-1, 3) - P0
    e2 = poses[:, T[:, 2]].reshape(-1, 3) - P0
    # the typical edge only sizes zero-size triangles' offsets: the first pose's
    offsets, _ = _fourth_offsets(e1, e2, _typical_edge(e1[:len(T)], e2[:len(T)]))
    fourth = (P0 + offsets).reshape(k, len(T), 3)
    ext = np.concatenate([poses, fourth], axis=1)                   # (k, n + t, 3)
    return np.ascontiguousarray(ext.transpose(1, 0, 2).reshape(n + len(T), 3 * k))


def source_gradient_blocks(op: GradientOperator, poses: np.ndarray) -> np.ndarray:
    """Transposed deformation gradients of each pose, flattened.

    Parameters
    ----------
    op : GradientOperator
        Of the source reference.
    poses : (k, n, 3) float64

    Returns
    -------
    (k, t, 9) float64
        Row ``i`` of pose ``j`` is ``S_iᵀ`` row-major (the layout of ``G @ X``).
    """
    k, t = len(poses), op.n_triangles
    ext = extend_poses(op, poses)                                     # (n + t, 3k)
    blocks = np.asarray(op.matrix @ ext)                              # (3t, 3k)
    return blocks.reshape(t, 3, k, 3).transpose(2, 0, 1, 3).reshape(k, t, 9)


def flipped_triangles(poses, reference, triangles) -> np.ndarray:
    """Triangles whose normal turned more than 90° from the reference's.

    Parameters
    ----------
    poses : (n, 3) or (k, n, 3) float64
    reference : (n, 3) float64
    triangles : (t, 3) int64

    Returns
    -------
    (t,) or (k, t) bool
        Same leading shape as ``poses``; zero-area triangles count as not flipped.

    Raises
    ------
    ValueError
        When the shapes disagree or an index is out of range.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    >>> flipped_triangles(V * [1, -1, 1], V, [[0, 1, 2]]).tolist()
    [True]
    """
    V0 = as_vertices(reference, "reference")
    T = as_triangles(triangles, len(V0), "triangles")
    P = np.asarray(poses, dtype=np.float64)
    if P.ndim not in (2, 3) or P.shape[-2:] != V0.shape:
        raise ValueError(f"poses must have shape (k, {len(V0)}, 3) or ({len(V0)}, 3), "
                         f"got {P.shape}")
    T0, T1, T2 = T[:, 0], T[:, 1], T[:, 2]
    n0 = np.cross(V0[T1] - V0[T0], V0[T2] - V0[T0])
    out = np.empty(P.shape[:-2] + (len(T),), dtype=bool)
    # pose by pose and coordinate by coordinate: small arrays that stay in cache
    for X, o in zip(P.reshape(-1, *P.shape[-2:]), out.reshape(-1, len(T))):
        x, y, z = X[:, 0], X[:, 1], X[:, 2]
        ax, ay, az = x[T1] - x[T0], y[T1] - y[T0], z[T1] - z[T0]
        bx, by, bz = x[T2] - x[T0], y[T2] - y[T0], z[T2] - z[T0]
        o[:] = (n0[:, 0] * (ay * bz - az * by) + n0[:, 1] * (az * bx - ax * bz)
                + n0[:, 2] * (ax * by - ay * bx)) < 0
    return out


class _FlipRepair:
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
    (:data:`_REPAIR_MARGINS`).

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
        itself turns its normal by more than :data:`_REPAIR_TURN`: a limb turned
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
        flipped = flipped_triangles(X, self.reference, self.triangles)
        copied = np.zeros_like(flipped)
        some = np.flatnonzero(flipped.any(axis=1))
        if len(some):
            src = flipped_triangles(np.asarray(poses)[some], self._source_reference,
                                    self._source_op.triangles)
            copied[some] = (self._pairs @ src.T.astype(np.float64)).T > 0
        for j in some:
            cand = np.flatnonzero(flipped[j] & ~copied[j])
            if len(cand):
                copied[j, cand] = self._turned(poses[j], cand)
        return flipped & ~copied, copied

    def _turned(self, pose, tris) -> np.ndarray:
        """Whether the rotation of each triangle's transferred gradient (the mean of
        its partners' gradients) turns its rest normal by more than
        :data:`_REPAIR_TURN`."""
        rows = self._mean_pairs[tris]
        src, inv = np.unique(rows.indices, return_inverse=True)
        # the partners' gradients Q = [x1 - x0, x2 - x0, x3 - x0] V⁻¹, fourth vertex x3
        # built as the gradient operator builds it
        Ts = self._source_op.triangles[src]
        e1, e2 = pose[Ts[:, 1]] - pose[Ts[:, 0]], pose[Ts[:, 2]] - pose[Ts[:, 0]]
        e3, _ = _fourth_offsets(e1, e2, _typical_edge(e1, e2))
        Q = np.stack([e1, e2, e3], axis=2) @ self._source_op.inverse_edges[src]
        local = sp.csr_matrix((rows.data, inv.ravel(), rows.indptr),
                              shape=(len(tris), len(src)))
        S = np.asarray(local @ Q.reshape(-1, 9)).reshape(-1, 3, 3)
        S[~self._matched[tris]] = np.eye(3)
        U, _, Vt = np.linalg.svd(S)
        U[:, :, 2] *= np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)[:, None]
        n0 = self._normals[tris]
        turned = np.einsum("ti,tij,tj->t", n0, U @ Vt, n0)
        return turned < np.cos(np.radians(_REPAIR_TURN)) * np.einsum("ti,ti->t", n0, n0)

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
        follows = _Follows(self, pose, copied, bad)
        best = x
        stats = {"found": int(bad.sum()), "repaired": 0, "remaining": int(bad.sum()),
                 "rounds": 0}
        for margin in _REPAIR_MARGINS:
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
        N = H.shape[0]
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
            R = np.flatnonzero((w > 0) & near)
            T = self.triangles[R]
            # local step: the nearest proper in-plane map of each repaired triangle
            F = np.stack([x[T[:, 1]] - x[T[:, 0]], x[T[:, 2]] - x[T[:, 0]]], axis=2)
            F = _nearest_proper(F @ self._edges_inv[R], self._basis[R], margin)
            goal = np.einsum("rik,rke->rei", F, self._edges[R]).reshape(-1, 3)
            c = np.repeat(w[R] * diag[T].mean(axis=1), 3)
            # global step on the region: H + Dᵀ C D (D: the repaired triangles' edges)
            J = np.flatnonzero(region & ~self._fixed)
            if N == n + t:                          # fourth vertices of those triangles
                J = np.r_[J, n + np.flatnonzero(near)]
            local = np.full(N, -1)
            local[J] = np.arange(len(J))
            ends = local[self._ends[R]].reshape(-1, 2)                    # (3r, 2)
            # an edge to a vertex outside the region or fixed (the anchor):
            # x_head - x_tail ≈ goal with that end moved to the right-hand side
            glob = self._ends[R].reshape(-1, 2)
            goal = (goal + np.where(ends[:, 1:] < 0, x[glob[:, 1]], 0.0)
                    - np.where(ends[:, :1] < 0, x[glob[:, 0]], 0.0))
            keep = ends >= 0
            rows = np.repeat(np.arange(len(ends)), 2).reshape(-1, 2)[keep]
            D = sp.csr_matrix((np.tile([1.0, -1.0], (len(ends), 1))[keep],
                               (rows, ends[keep])), shape=(len(ends), len(J)))
            H_J = H[J]
            rest = x.copy()
            rest[J] = 0.0
            b = rhs[J] - H_J @ rest + D.T @ (c[:, None] * goal)
            # H[J][:, J] by filtering H[J]'s columns through the local numbering
            cols = local[H_J.indices]
            inside = cols >= 0
            indptr = np.r_[0, np.cumsum(inside)][H_J.indptr]
            A = (sp.csr_matrix((H_J.data[inside], cols[inside], indptr),
                               shape=(len(J), len(J))) + D.T @ sp.diags(c) @ D)
            x = x.copy()
            x[J] = factorize(A, check=False, solves="few").solve(b)
            bad = np.zeros(t, dtype=bool)
            bad[near] = flipped_triangles(x[:n], self.reference, self.triangles[near])
            bad &= ~follows(bad)
            if bad.sum() < best_count:
                best, best_count = x, int(bad.sum())
        return best, best_count, int((w > 0).sum()), rounds


class _Follows:
    """Copied flips of one pose, checked lazily for triangles that start to flip."""

    def __init__(self, repair: _FlipRepair, pose, copied, bad):
        self._repair, self._pose = repair, pose
        self._copied = copied.copy()
        self._known = copied | bad

    def __call__(self, flipped) -> np.ndarray:
        """(t,) bool: which of the ``flipped`` triangles follow the source."""
        new = np.flatnonzero(flipped & ~self._known)
        if len(new):
            self._copied[new] = self._repair._turned(self._pose, new)
            self._known[new] = True
        return self._copied & flipped


def _nearest_proper(F, basis, margin):
    """In-plane maps ``F`` (m, 3, 2) with their rest-plane part made proper.

    ``basis`` (m, 3, 2) spans each rest plane; the 2 x 2 part ``A = basisᵀ F`` is
    replaced by the nearest matrix with positive determinant and singular values at
    least ``margin`` times the largest (a reflection removed, a collapse opened);
    the part off the rest plane is kept.
    """
    A = np.einsum("mki,mkc->mic", basis, F)
    U, s, Vt = np.linalg.svd(A)
    U[:, :, 1] *= np.where(np.linalg.det(U @ Vt) < 0, -1.0, 1.0)[:, None]
    s[:, 1] = np.maximum(s[:, 1], margin * s[:, 0])
    return F + basis @ (U @ (s[:, :, None] * Vt) - A)


class DeformationTransfer:
    """Transfer source poses onto a target of another topology (Sumner 2004).

    Parameters
    ----------
    anchor : int or "markers"
        Target vertex kept at its reference position, or ``"markers"``: solve with
        the first target marker fixed, then translate the result so the target
        markers' centroid moves by the source markers' centroid displacement
        (scaled by the ratio of the two marker sets' spreads).
    fix_flips : bool
        Unfold the triangles the transfer flips (normal turned more than 90°
        against the target reference) where the source does not: such a pose is
        re-solved on a few vertex rings around them with a term that unfolds them
        (see :class:`_FlipRepair`).  Flips that follow the source (a partner flips,
        or the transferred gradient turns the triangle past 95°) are kept.  False
        gives the plain least-squares transfer.

    Attributes
    ----------
    source_ : Mesh
    target_ : Mesh
    correspondence_ : Correspondence
    factor_ : facewrap.solve.factor.Factor
        The factored normal matrix (target vertices; fourth vertices and the
        anchor eliminated exactly).
    timings_ : dict
        Seconds spent in :meth:`fit` (``build``, ``factor``).
    repairs_ : dict of (k,) int64 arrays
        Set by each :meth:`transfer` with ``fix_flips``, per pose: ``found`` (new
        flips of the plain solve), ``repaired`` (triangles given the unfolding
        term), ``remaining`` (new flips left, normally 0) and ``rounds`` (re-solves).
        All zero for a pose that needed no repair.

    Examples
    --------
    A source pose that is a rigid motion moves the target rigidly:

    >>> from facewrap.transfer import find_correspondence
    >>> from facewrap.sample.face import make_template
    >>> full = make_template(20).mesh
    >>> mesh, _ = full.submesh(full.face_groups == 0)     # the face, one component
    >>> corr = find_correspondence(mesh, mesh, [[0, 0], [50, 50], [99, 99]])
    >>> dt = DeformationTransfer(anchor=0).fit(mesh, mesh, corr)
    >>> R = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    >>> out = dt.transfer(mesh.vertices @ R.T)
    >>> bool(np.allclose(out - out[0], (mesh.vertices - mesh.vertices[0]) @ R.T))
    True
    """

    def __init__(self, anchor: int | str = "markers", fix_flips: bool = True):
        self.anchor = anchor
        self.fix_flips = fix_flips

    def fit(self, source: Mesh, target: Mesh,
            correspondence: Correspondence) -> "DeformationTransfer":
        """Build and factor the transfer system for this source/target pair.

        Parameters
        ----------
        source, target : Mesh
            Reference meshes (the ones the correspondence was made for).
        correspondence : Correspondence

        Returns
        -------
        self
        """
        correspondence.check(source, target)
        t0 = time.perf_counter()
        anchor = self._anchor_vertex(correspondence, target.n_vertices)
        self.source_, self.target_ = source, target
        self.correspondence_ = correspondence
        self._source_op = gradient_operator(source.vertices, source.triangles)
        op = gradient_operator(target.vertices, target.triangles)
        self._target_op = op
        self._pairs, orphans = complete_pairs(pair_matrix(correspondence),
                                              target.triangles)
        self._orphans = orphans
        counts = np.asarray(self._pairs.sum(axis=1)).ravel() + orphans
        # H = Gᵀ W G.  A fourth vertex only appears in its own triangle's rows, so
        # the fourth-vertex block of H is diagonal and is eliminated exactly
        # (Schur complement): the factor has one unknown per target vertex.
        n = target.n_vertices
        G = op.matrix
        H = (G.T @ sp.diags(np.repeat(counts, 3)) @ G).tocsc()
        H_vv, H_vf = H[:n, :n], H[:n, n:]
        d_ff = H[n:, n:].diagonal()
        self._Hvf_dff = (H_vf @ sp.diags(1.0 / d_ff)).tocsr()
        H_red = (H_vv - self._Hvf_dff @ H_vf.T).tocsr()
        # components without the anchor: a tiny pull toward rest fixes their
        # translation (an eyeball turns about its own centre)
        loose = untethered_vertices(target.triangles, n, [anchor])
        tether = _TETHER * float(H_red.diagonal().mean()) * loose
        H_red = (H_red + sp.diags(tether)).tocsr()
        self._H_red = H_red
        self._tether_rhs = tether[:, None] * target.vertices
        self._anchor = anchor
        self._identity_rhs = np.asarray(
            G.T @ (np.repeat(orphans, 3)[:, None] * np.tile(np.eye(3), (op.n_triangles, 1))))
        # The right-hand side is linear in the source poses: Gₜᵀ (M ⊗ I₃) G_s applied
        # to the poses' vertices and fourth vertices, then reduced like H.  One sparse
        # map, built once, so a pose costs one sparse product and one back-substitution.
        K = sp.kron(self._pairs, sp.identity(3), format="csr")
        rhs_map = (G.T @ (K @ self._source_op.matrix)).tocsr()
        self._rhs_map = (rhs_map[:n] - self._Hvf_dff @ rhs_map[n:]).tocsr()
        self._const_rhs = (self._identity_rhs[:n] - self._Hvf_dff @ self._identity_rhs[n:]
                           + self._tether_rhs)
        m = correspondence.markers
        spread = [np.sqrt(((X[ids] - X[ids].mean(0)) ** 2).sum(1).mean())
                  for X, ids in ((source.vertices, m[:, 0]), (target.vertices, m[:, 1]))]
        self._marker_scale = spread[1] / spread[0] if spread[0] > 0 else 1.0
        t1 = time.perf_counter()
        # the anchor is known (at rest): one factor of the free block for every pose
        self._system = FixedSystem(H_red, [anchor])
        self.factor_ = self._system.factor
        self._repair = _FlipRepair(target.vertices, target.triangles, self._source_op,
                                   source.vertices, self._pairs, fixed=[anchor])
        self.timings_ = {"build": t1 - t0, "factor": time.perf_counter() - t1}
        self.stats_ = {"unmatched_target_triangles": int(len(correspondence.unmatched_target)),
                       "orphan_target_triangles": int(orphans.sum()),
                       "degenerate_target_triangles": int(op.degenerate.sum()),
                       "degenerate_source_triangles":
                           int(self._source_op.degenerate.sum()),
                       "factorisation": self.factor_.method}
        return self

    def _anchor_vertex(self, corr: Correspondence, n: int) -> int:
        if isinstance(self.anchor, str):
            if self.anchor != "markers":
                raise ValueError(f"anchor must be a vertex id or 'markers', got "
                                 f"{self.anchor!r}")
            if len(corr.markers) == 0:
                raise ValueError("anchor='markers' needs a correspondence with markers")
            return int(corr.markers[0, 1])
        a = int(self.anchor)
        if not 0 <= a < n:
            raise ValueError(f"anchor vertex {a} out of range (target has {n} vertices)")
        return a

    def transfer(self, poses) -> np.ndarray:
        """Target positions for source poses.

        Parameters
        ----------
        poses : (n_source, 3) or (k, n_source, 3) float64
            Source vertex positions in the source reference's topology.

        Returns
        -------
        (n_target, 3) or (k, n_target, 3) float64
            Same leading shape as ``poses``.  With ``fix_flips``, poses with new
            flips are repaired (:attr:`repairs_` says which and how).
        """
        P, single = as_pose_stack(poses, self.source_.n_vertices)
        k = len(P)
        rhs = self._rhs_map @ extend_poses(self._source_op, P)
        rhs += np.tile(self._const_rhs, (1, k))
        xa = np.tile(self.target_.vertices[self._anchor], k)
        x = self._system.solve(rhs, xa[None, :])
        if self.fix_flips:
            out, self.repairs_ = self._repair.repair_poses(self._H_red, rhs, x, P)
        else:
            out = x.reshape(-1, k, 3).transpose(1, 0, 2)
        if self.anchor == "markers":
            m = self.correspondence_.markers
            src_move = P[:, m[:, 0]].mean(axis=1) - self.source_.vertices[m[:, 0]].mean(0)
            src_move = src_move * self._marker_scale
            tgt_move = out[:, m[:, 1]].mean(axis=1) - self.target_.vertices[m[:, 1]].mean(0)
            out = out + (src_move - tgt_move)[:, None, :]
        return out[0] if single else out

    def transfer_meshes(self, poses) -> list[Mesh]:
        """:meth:`transfer` as meshes in the target's exact topology (quads, UVs)."""
        X, single = as_pose_stack(poses, self.source_.n_vertices)
        return [self.target_.with_vertices(v) for v in self.transfer(X)]
