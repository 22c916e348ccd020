"""Landmark-guided avatar blendshapes (Onizuka et al. 2019, SPEC §4).

This module owns making an avatar's key shapes from a template blendshape set and
a few corresponding landmarks.  :class:`AvatarTransfer`:

1. re-scales the avatar by the ratio of bounding-box diagonals (source / avatar)
   and rotates it onto the source on the landmarks (the transfer needs both meshes
   in one frame; results are mapped back to the avatar's own frame and units);
2. deforms the avatar onto the source neutral (:func:`~.find_correspondence` with
   ``deform="target"`` and :data:`ONIZUKA_SCHEDULE`: one round with
   ``w_S=1, w_I=0.1, w_C=0``, three with ``w_S=1, w_I=0.001, w_C>0``:
   :class:`~facewrap.transfer.CorrespondenceStage` weights), then
   matches triangles both ways;
3. factors, once, the key-shape energy

       E = w_d E_d + w_l E_l + w_s E_s + w_i E_i

   (deformation gradients over the matched pairs, weight ``gradient_weight``;
   landmark motion, ``landmark_weight``; equal gradients of neighbouring avatar
   triangles, ``smooth_weight``; gradients near the identity,
   ``identity_weight``) and solves one back-substitution per key shape;
4. unfolds triangles the solve flipped where the source does not (``fix_flips``):
   the landmark term pulls lids shut, and on an avatar whose eye area has no lid
   geometry (Mario) that folds the skin around the eye over.  Only such shapes are
   re-solved, locally, with a term that unfolds exactly those triangles: the lids
   still close as far as the avatar's surface allows, and where the avatar has lids
   nothing changes.

The landmark term's per-part frames and scales are :mod:`.parts`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from facewrap.avatar.parts import IBUG51_PARTS, FacePart, check_parts, part_motions
from facewrap.geometry import Similarity, similarity_transform, vertex_normals
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import (Constraint, Flag, Instances, Interval, NoneAllowed,
                             expect_instance, validate)
from facewrap.solve import factorize
from facewrap.transfer import (Correspondence, CorrespondenceSettings,
                               CorrespondenceStage, DeformationTransfer, FlipRepair,
                               adjacent_triangle_pairs, as_pose_stack, check_markers,
                               complete_pairs, find_correspondence, gradient_operator,
                               pair_matrix, source_gradient_blocks,
                               tether_weights, triangle_smoothness_operator,
                               untethered_vertices)

__all__ = ["ONIZUKA_SCHEDULE", "AvatarSettings", "AvatarTransfer"]


#: Length of the paper's template diagonal (its onizuka2019 neutral, mm).
_PAPER_DIAGONAL = 380.0

#: Onizuka et al. 2019: one round w_S=1, w_I=0.1, w_C=0, then three with w_S=1,
#: w_I=0.001, w_C=1 in the paper's units (template diagonal ≈ 380 mm); here w_C is in
#: units of the source's bounding-box diagonal, 1 mm² of theirs ≈ 1/380² of ours.
ONIZUKA_SCHEDULE: tuple[CorrespondenceStage, ...] = (
    CorrespondenceStage(smooth_weight=1.0, identity_weight=0.1, closest_weight=0.0),
    *(CorrespondenceStage(smooth_weight=1.0, identity_weight=0.001,
                          closest_weight=_PAPER_DIAGONAL ** 2) for _ in range(3)),
)


class _SettingsOf(Constraint):
    """An instance of one settings class (itself validated at construction)."""

    def __init__(self, kind: type):
        self.kind = kind

    def holds(self, value) -> bool:
        return isinstance(value, self.kind)

    def describe(self) -> str:
        return f"a {self.kind.__name__}"

    def invalid(self) -> list:
        return ["x", 3]


@dataclass(frozen=True)
class AvatarSettings:
    """How :class:`AvatarTransfer` works (its constructor arguments, checked).

    Attributes
    ----------
    gradient_weight, landmark_weight, smooth_weight, identity_weight : float
        ``w_d, w_l, w_s, w_i``: weights of gradient matching, landmark motion,
        smoothness and identity (lengths measured with the source's bounding-box
        diagonal counting 380, as the paper's template in mm, so the defaults keep
        their meaning for a source in any unit).  The landmark term fixes the
        translation: its weight is positive.
    landmark_guided : bool
        False gives plain deformation transfer (Sumner 2004) with the same
        correspondence, for comparison.
    parts : tuple of FacePart
        Face parts over the landmark list.
    correspondence : CorrespondenceSettings or None
        None: deform the avatar with :data:`ONIZUKA_SCHEDULE`.
    fix_flips : bool
        Unfold triangles the transfer flips where the source does not.
    """

    gradient_weight: float = 1.0
    landmark_weight: float = 100.0
    smooth_weight: float = 10.0
    identity_weight: float = 1.0
    landmark_guided: bool = True
    parts: tuple = IBUG51_PARTS
    correspondence: CorrespondenceSettings | None = None
    fix_flips: bool = True

    constraints = {
        "gradient_weight": Interval(float, 0, None),
        "landmark_weight": Interval(float, 0, None, closed="neither"),
        "smooth_weight": Interval(float, 0, None),
        "identity_weight": Interval(float, 0, None),
        "landmark_guided": Flag(),
        "parts": Instances(FacePart),
        "correspondence": (NoneAllowed(), _SettingsOf(CorrespondenceSettings)),
        "fix_flips": Flag(),
    }

    def __post_init__(self):
        validate(self)
        object.__setattr__(self, "parts", tuple(self.parts))


class AvatarTransfer:
    """Key shapes for an avatar from a template blendshape set (Onizuka 2019).

    Parameters
    ----------
    gradient_weight, landmark_weight, smooth_weight, identity_weight : float
        Weights of gradient matching, landmark motion, smoothness and identity
        (see :class:`AvatarSettings`).
    landmark_guided : bool
        False gives plain deformation transfer (Sumner 2004) with the same
        correspondence, for comparison.
    parts : sequence of FacePart
        Face parts over the landmark list (default :data:`IBUG51_PARTS`).
    correspondence : CorrespondenceSettings, optional
        Default: deform the avatar with :data:`ONIZUKA_SCHEDULE`.
    fix_flips : bool
        Unfold triangles the transfer flips where the source does not (both
        methods; see :class:`~facewrap.transfer.DeformationTransfer`).  False keeps
        the plain solve of either energy.

    Attributes
    ----------
    correspondence_ : Correspondence
    alignment_ : facewrap.geometry.Similarity
        Avatar → source frame (bounding-box scale, rotation, translation).
    motions_ : (K, 3, 3) float64
        Per-part landmark motion maps.
    parts_info_ : list of dict
    factor_ : facewrap.solve.factor.Factor
    timings_ : dict
    repairs_ : dict of (k,) int64 arrays
        Set by each :meth:`transfer` with ``fix_flips``: per shape ``found`` (new
        flips of the plain solve), ``repaired`` (triangles given the unfolding
        term), ``remaining`` (normally 0) and ``rounds``.
    """

    def __init__(self, gradient_weight: float = 1.0, landmark_weight: float = 100.0,
                 smooth_weight: float = 10.0, identity_weight: float = 1.0,
                 landmark_guided: bool = True, parts=IBUG51_PARTS,
                 correspondence: CorrespondenceSettings | None = None,
                 fix_flips: bool = True):
        #: the checked constructor arguments (read-only)
        self.settings = AvatarSettings(gradient_weight, landmark_weight,
                                       smooth_weight, identity_weight,
                                       landmark_guided, parts, correspondence, fix_flips)

    def fit(self, source: Mesh, source_landmarks, avatar: Mesh, avatar_landmarks, *,
            correspondence: Correspondence | None = None,
            landmarks_path=None) -> "AvatarTransfer":
        """Correspond the avatar with the source and factor the key-shape system.

        Parameters
        ----------
        source : Mesh
            Template neutral.
        source_landmarks, avatar_landmarks : (L,) int
            Corresponding vertex ids on each mesh (e.g. 51 iBUG points).
        avatar : Mesh
            Neutral avatar, any topology.
        correspondence : Correspondence, optional
            A saved one for this pair (skips the deformation and matching).
        landmarks_path : str, optional
            Named in error messages.

        Returns
        -------
        self
        """
        check_mesh(source, "source")
        check_mesh(avatar, "avatar")
        expect_instance(correspondence, Correspondence, "correspondence", optional=True)
        t0 = time.perf_counter()
        ls, la = check_markers((source_landmarks, avatar_landmarks), source.n_vertices,
                               avatar.n_vertices, landmarks_path)
        if self.settings.landmark_guided:
            check_parts(self.settings.parts, len(ls), landmarks_path)
        self.source_, self.avatar_ = source, avatar
        self._ls, self._la = ls, la
        # 1. bounding-box rescale, then rotation + translation on the landmarks
        ratio = source.scale() / max(avatar.scale(), 1e-300)
        rigid = similarity_transform(avatar.vertices[la] * ratio, source.vertices[ls],
                                     scale=False)
        self.alignment_ = rigid.compose(Similarity(scale=ratio))
        aligned = avatar.with_vertices(self.alignment_.apply(avatar.vertices))
        self._aligned = aligned
        # 2. correspondence: the avatar deformed onto the source
        if correspondence is None:
            settings = self.settings.correspondence or CorrespondenceSettings(
                schedule=ONIZUKA_SCHEDULE, deform="target", align="none")
            correspondence = find_correspondence(source, aligned, (ls, la), settings,
                                                 markers_path=landmarks_path)
        correspondence.check(source, avatar)
        self.correspondence_ = correspondence
        t1 = time.perf_counter()
        # 3. the key-shape system
        if self.settings.landmark_guided:
            self._fit_guided(source, aligned, ls, la)
        else:
            self._plain = DeformationTransfer(
                anchor="markers", fix_flips=self.settings.fix_flips).fit(source, aligned,
                                                                correspondence)
            self.factor_ = self._plain.factor_
        self.timings_ = {"correspondence": t1 - t0,
                         "factor": time.perf_counter() - t1}
        return self

    def _fit_guided(self, source: Mesh, aligned: Mesh, ls, la) -> None:
        self._source_op = gradient_operator(source.vertices, source.triangles)
        op = gradient_operator(aligned.vertices, aligned.triangles)
        self._avatar_op = op
        self._pairs = pair_matrix(self.correspondence_)
        counts = np.asarray(self._pairs.sum(axis=1)).ravel()
        # lengths in the paper's units: the source diagonal counts 380 (its template
        # in mm), whatever the source's own units
        self._unit = source.scale() / _PAPER_DIAGONAL
        G = op.matrix
        D = triangle_smoothness_operator(op, adjacent_triangle_pairs(aligned.triangles))
        uniq_la = np.unique(la)
        lm_w = np.zeros(op.n_unknowns)
        np.add.at(lm_w, la, 1.0)
        s = self.settings
        H = (s.gradient_weight * (G.T @ sp.diags(np.repeat(counts, 3)) @ G)
             + s.smooth_weight * (D.T @ D) + s.identity_weight * (G.T @ G)
             + sp.diags(s.landmark_weight * lm_w / self._unit ** 2))
        # components without landmarks: a tiny pull toward rest fixes translation
        loose = np.zeros(op.n_unknowns)
        loose[:aligned.n_vertices] = untethered_vertices(aligned.triangles,
                                                         aligned.n_vertices, la)
        tether = tether_weights(H, loose)
        H = H + sp.diags(tether)
        self._tether_rhs = tether[:, None] * op.extend(aligned.vertices)
        self._identity_rhs = s.identity_weight * np.asarray(
            G.T @ np.tile(np.eye(3), (op.n_triangles, 1)))
        self._H = H.tocsr()
        self.factor_ = factorize(self._H)
        self._repair = FlipRepair(aligned.vertices, aligned.triangles, self._source_op,
                                   source.vertices,
                                   complete_pairs(self._pairs, aligned.triangles)[0])
        src_n = vertex_normals(source.vertices, source.triangles)[ls]
        ava_n = vertex_normals(aligned.vertices, aligned.triangles)[la]
        self.motions_, self._owner, self.parts_info_ = part_motions(
            source.vertices[ls], src_n, aligned.vertices[la], ava_n, s.parts)
        self._uniq_la = uniq_la

    def landmark_targets(self, shapes) -> np.ndarray:
        """Where each avatar landmark should go, in the aligned avatar frame.

        Parameters
        ----------
        shapes : (k, n_source, 3) float64

        Returns
        -------
        (k, L, 3) float64
            ``a_corr(i) + M_k u_i``.
        """
        U = shapes[:, self._ls] - self.source_.vertices[self._ls]        # (k, L, 3)
        M = np.where(self._owner[:, None, None] >= 0,
                     self.motions_[np.maximum(self._owner, 0)], np.eye(3))  # (L, 3, 3)
        moved = np.einsum("lij,klj->kli", M, U)
        return self._aligned.vertices[self._la][None] + moved

    def transfer(self, shapes) -> np.ndarray:
        """Avatar key shapes for source key shapes.

        Parameters
        ----------
        shapes : (n_source, 3) or (k, n_source, 3) float64
            Source shapes (vertex positions) in the source neutral's topology.

        Returns
        -------
        (n_avatar, 3) or (k, n_avatar, 3) float64
            In the avatar's own frame and units.
        """
        P, single = as_pose_stack(shapes, self.source_.n_vertices, "shapes")
        if self.settings.landmark_guided:
            out = self._solve_guided(P)
        else:
            out = self._plain.transfer(P)
            if self.settings.fix_flips:
                self.repairs_ = self._plain.repairs_
        out = self.alignment_.inverse().apply(out.reshape(-1, 3)).reshape(out.shape)
        return out[0] if single else out

    def _solve_guided(self, P: np.ndarray) -> np.ndarray:
        k = len(P)
        op = self._avatar_op
        blocks = source_gradient_blocks(self._source_op, P)
        summed = np.stack([self._pairs @ b for b in blocks])
        B = summed.reshape(k, op.n_triangles, 3, 3).transpose(1, 2, 0, 3)
        rhs = self.settings.gradient_weight * np.asarray(
            op.matrix.T @ B.reshape(3 * op.n_triangles, 3 * k))
        rhs += np.tile(self._identity_rhs + self._tether_rhs, (1, k))
        goals = self.landmark_targets(P)                                   # (k, L, 3)
        w = self.settings.landmark_weight / self._unit ** 2
        lm_rhs = np.zeros((op.n_unknowns, k, 3))
        np.add.at(lm_rhs, self._la, w * goals.transpose(1, 0, 2))
        rhs += lm_rhs.reshape(op.n_unknowns, 3 * k)
        x = self.factor_.solve(rhs)
        if self.settings.fix_flips:
            out, self.repairs_ = self._repair.repair_poses(self._H, rhs, x, P)
            return out
        return x[:self.avatar_.n_vertices].reshape(-1, k, 3).transpose(1, 0, 2)

    def transfer_meshes(self, shapes) -> list[Mesh]:
        """:meth:`transfer` as meshes in the avatar's exact topology."""
        P, _ = as_pose_stack(shapes, self.source_.n_vertices, "shapes")
        return [self.avatar_.with_vertices(v) for v in self.transfer(P)]
