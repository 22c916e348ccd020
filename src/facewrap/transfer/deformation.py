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
locally until no such *new* flip remains (:class:`~.flip_repair.FlipRepair`);
poses without one keep the plain back-substitution, bit for bit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from facewrap.mesh import Mesh, check_mesh
from facewrap.params import Flag, Interval, Options, expect_instance, validate
from facewrap.solve import FixedSystem
from facewrap.transfer.constraints import tether_weights, untethered_vertices
from facewrap.transfer.correspondence import Correspondence
from facewrap.transfer.flip_repair import FlipRepair
from facewrap.transfer.gradients import (FourthVertexElimination, GradientOperator,
                                         adjacent_triangle_pairs, fourth_vertex_offsets,
                                         gradient_operator, typical_edge_length)
from facewrap.units import too_large

__all__ = ["DeformationTransfer", "TransferSettings", "pair_matrix", "complete_pairs",
           "source_gradient_blocks", "extend_poses", "as_pose_stack"]


def as_pose_stack(poses, n_vertices: int, name: str = "poses") -> tuple[np.ndarray, bool]:
    """Poses as a (k, n, 3) float64 stack, and whether one (n, 3) pose was given.

    Raises
    ------
    ValueError
        Naming ``name``, when the vertex count or shape is wrong or values are
        not finite.
    TypeError
        Naming ``name``, for a dict or what is no array of numbers.
    """
    if isinstance(poses, dict):   # a shape set as read: say how to pass it
        raise TypeError(f"{name} must be an array, not a dict: pass "
                        "np.stack(list(shapes.values())) and zip the names back")
    try:
        P = np.asarray(poses, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise TypeError(f"{name} must be a (k, {n_vertices}, 3) or ({n_vertices}, 3) "
                        f"float array: {exc}") from None
    single = P.ndim == 2
    if single:
        P = P[None]
    if P.ndim != 3 or P.shape[1:] != (n_vertices, 3):
        raise ValueError(f"{name} must have shape (k, {n_vertices}, 3) or "
                         f"({n_vertices}, 3), got {np.shape(poses)}")
    if not np.isfinite(P).all():
        raise ValueError(f"{name} contain NaN or infinite coordinates")
    for k, pose in enumerate(P):   # a 1e300 was solved into inf, with a warning
        problem = too_large(pose)
        if problem is not None:
            raise ValueError(f"{name}[{k}]: {problem}")
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
    offsets, _ = fourth_vertex_offsets(e1, e2, typical_edge_length(e1[:len(T)],
                                                                   e2[:len(T)]))
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


@dataclass(frozen=True)
class TransferSettings:
    """How :class:`DeformationTransfer` solves (its constructor arguments, checked).

    Attributes
    ----------
    anchor : int or "markers"
        See :class:`DeformationTransfer`.
    fix_flips : bool
    """

    anchor: int | str = "markers"
    fix_flips: bool = True

    constraints = {"anchor": (Options("markers"), Interval(int, 0, None)),
                   "fix_flips": Flag()}

    def __post_init__(self):
        validate(self)


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
        (see :class:`~facewrap.transfer.FlipRepair`).  Flips that follow the source
        (a partner flips, or the transferred gradient turns the triangle past
        :data:`~facewrap.transfer.flip_repair.REPAIR_TURN` degrees) are kept.  False
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
    >>> from facewrap.sample import make_template
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
        self.settings = TransferSettings(anchor, fix_flips)

    @property
    def anchor(self) -> int | str:
        """The anchor setting (read-only: settings are given to the constructor)."""
        return self.settings.anchor

    @property
    def fix_flips(self) -> bool:
        """The flip-repair setting.  It only changes what :meth:`transfer` does, so
        it may be switched between transfers (checked like the constructor's)."""
        return self.settings.fix_flips

    @fix_flips.setter
    def fix_flips(self, value: bool) -> None:
        self.settings = replace(self.settings, fix_flips=value)

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
        check_mesh(source, "source")
        check_mesh(target, "target")
        expect_instance(correspondence, Correspondence, "correspondence")
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
        # H = Gᵀ W G with its fourth vertices eliminated exactly: the factor has
        # one unknown per target vertex
        n = target.n_vertices
        G = op.matrix
        fourth = FourthVertexElimination(G.T @ sp.diags(np.repeat(counts, 3)) @ G, n)
        H_red = fourth.matrix
        # components without the anchor: a tiny pull toward rest fixes their
        # translation (an eyeball turns about its own centre)
        loose = untethered_vertices(target.triangles, n, [anchor])
        tether = tether_weights(H_red, loose)
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
        self._rhs_map = fourth.reduce(rhs_map).tocsr()
        self._const_rhs = fourth.reduce(self._identity_rhs) + self._tether_rhs
        m = correspondence.markers
        spread = [np.sqrt(((X[ids] - X[ids].mean(0)) ** 2).sum(1).mean())
                  for X, ids in ((source.vertices, m[:, 0]), (target.vertices, m[:, 1]))]
        self._marker_scale = spread[1] / spread[0] if spread[0] > 0 else 1.0
        t1 = time.perf_counter()
        # the anchor is known (at rest): one factor of the free block for every pose
        self._system = FixedSystem(H_red, [anchor])
        self.factor_ = self._system.factor
        self._repair = FlipRepair(target.vertices, target.triangles, self._source_op,
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
        if isinstance(self.anchor, str):                  # "markers"
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
        P, single = as_pose_stack(poses, self._fitted().source_.n_vertices)
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
        X, single = as_pose_stack(poses, self._fitted().source_.n_vertices)
        return [self.target_.with_vertices(v) for v in self.transfer(X)]

    def _fitted(self) -> "DeformationTransfer":
        """``self`` once :meth:`fit` has run, else an error that says to call it."""
        if not hasattr(self, "source_"):
            raise RuntimeError("DeformationTransfer is not fitted: call "
                               "fit(source, target, correspondence) first")
        return self
