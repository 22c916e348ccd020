"""Landmark-guided avatar blendshapes (Onizuka et al. 2019, SPEC §4).

This module owns making an avatar's key shapes from a template blendshape set and
a few corresponding landmarks.  :class:`AvatarTransfer`:

1. re-scales the avatar by the ratio of bounding-box diagonals (source / avatar)
   and rotates it onto the source on the landmarks (the transfer needs both meshes
   in one frame; results are mapped back to the avatar's own frame and units);
2. deforms the avatar onto the source neutral (:func:`~.find_correspondence` with
   ``deform="target"`` and :data:`ONIZUKA_SCHEDULE`: one round with
   ``w_S=1, w_I=0.1, w_C=0``, three with ``w_S=1, w_I=0.001, w_C>0``), then
   matches triangles both ways;
3. factors, once, the key-shape energy

       E = w_d E_d + w_l E_l + w_s E_s + w_i E_i

   (deformation gradients over the matched pairs; landmark motion; equal gradients
   of neighbouring avatar triangles; gradients near the identity) and solves one
   back-substitution per key shape;
4. unfolds triangles the solve flipped where the source does not (``fix_flips``):
   the landmark term pulls lids shut, and on an avatar whose eye area has no lid
   geometry (Mario) that folds the skin around the eye over.  Only such shapes are
   re-solved, locally, with a term that unfolds exactly those triangles: the lids
   still close as far as the avatar's surface allows, and where the avatar has lids
   nothing changes.

The landmark term moves avatar landmark ``corr(i)`` by ``R_tᵀ A_k R_s u_i``: the
source landmark's displacement ``u_i`` expressed in the frame of its face part
``k`` on the source (``R_s``), scaled by the part's size ratio ``A_k`` and turned
into the avatar part's frame (``R_t``).  A part's frame has its normal as the
direction most perpendicular to the lines between its frame landmarks (smallest
singular vector, oriented along the surface normal) and its x axis along two named
landmarks.  For the mouth, whose opening a closed neutral cannot show, the z ratio
is 1 and the y ratio is the ratio of nose-bottom → lower-lip distances.

Parts come from :data:`IBUG51_PARTS` (the 51-point dlib/iBUG layout: 68 points
without the jaw line) or from a small JSON file read by :func:`read_parts`::

    {"format": "facewrap.parts", "version": 1,
     "parts": [{"name": "right_eye", "landmarks": [[19, 24]], "axis": [19, 22]},
               {"name": "mouth", "landmarks": [[31, 50]], "axis": [31, 37],
                "mouth": {"nose_bottom": 16, "lower_lip": [40, 49]}}, ...]}

``landmarks`` and the optional ``frame`` are inclusive index ranges (or single
indices) into the landmark list.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.errors import InputError
from facewrap.geometry import vertex_normals
from facewrap.io.files import read_json
from facewrap.mesh import Mesh
from facewrap.solve import factorize
from facewrap.transfer.correspondence import (_TETHER, Correspondence, CorrespondenceSettings,
                             CorrespondenceStage, check_markers, find_correspondence,
                             untethered_vertices)
from facewrap.transfer import adjacent_triangle_pairs, gradient_operator, triangle_smoothness_operator
from facewrap.transfer.deformation import DeformationTransfer, _FlipRepair, as_pose_stack, complete_pairs, \
    pair_matrix, source_gradient_blocks

__all__ = ["FacePart", "IBUG51_PARTS", "read_parts", "ONIZUKA_SCHEDULE",
           "AvatarTransfer", "part_frame", "part_motions"]


@dataclass(frozen=True)
class FacePart:
    """A face part: its landmarks and how its frame is built.

    Attributes
    ----------
    name : str
    landmarks : tuple of int
        Indices into the landmark list of the landmarks that move with this part.
    frame : tuple of int
        Landmarks whose connecting lines the part's normal is most perpendicular
        to (defaults to ``landmarks``).
    axis : (int, int)
        The part's x axis points from the first to the second of these landmarks.
    nose_bottom : int
        Mouth rule only (-1 otherwise): landmark at the bottom of the nose.
    lower_lip : tuple of int
        Mouth rule only: landmarks whose mean is the centre of the lower lip.
    """

    name: str
    landmarks: tuple
    axis: tuple
    frame: tuple = ()
    nose_bottom: int = -1
    lower_lip: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "landmarks", tuple(int(i) for i in self.landmarks))
        object.__setattr__(self, "frame", tuple(int(i) for i in self.frame)
                           or self.landmarks)
        object.__setattr__(self, "axis", tuple(int(i) for i in self.axis))
        object.__setattr__(self, "lower_lip", tuple(int(i) for i in self.lower_lip))
        if len(self.axis) != 2 or self.axis[0] == self.axis[1]:
            raise ValueError(f"part {self.name!r}: axis must be two different landmarks")
        if len(self.frame) < 3:
            raise ValueError(f"part {self.name!r}: a frame needs at least 3 landmarks")
        if self.is_mouth and not self.lower_lip:
            raise ValueError(f"part {self.name!r}: the mouth rule needs lower_lip")

    @property
    def is_mouth(self) -> bool:
        """Whether the mouth rule (z ratio 1, y from nose → lower lip) applies."""
        return self.nose_bottom >= 0

    def indices(self) -> np.ndarray:
        """Every landmark index the part uses (int64)."""
        return np.asarray(sorted({*self.landmarks, *self.frame, *self.axis,
                                  *self.lower_lip}
                                 | ({self.nose_bottom} if self.is_mouth else set())),
                          dtype=np.int64)


def _r(a, b):
    return tuple(range(a, b + 1))


#: The six parts on the 51-point dlib/iBUG layout (iBUG-68 minus the jaw, index =
#: iBUG index - 17): brows 0-9, nose 10-18 (16: bottom centre), eyes 19-24 / 25-30,
#: mouth 31-50 (40 / 49: outer / inner lower-lip centre).  "Right" is the subject's
#: right (iBUG numbers it first).  A brow's frame includes its eye (five points on an
#: arc do not define a plane); the nose's is the top of the bridge and the nostril
#: row (bridge and tip span the sagittal plane, whose normal is sideways).
IBUG51_PARTS: tuple[FacePart, ...] = (
    FacePart("right_brow", _r(0, 4), (0, 4), frame=_r(0, 4) + _r(19, 24)),
    FacePart("left_brow", _r(5, 9), (5, 9), frame=_r(5, 9) + _r(25, 30)),
    FacePart("nose", _r(10, 18), (14, 18), frame=(10,) + _r(14, 18)),
    FacePart("right_eye", _r(19, 24), (19, 22)),
    FacePart("left_eye", _r(25, 30), (25, 28)),
    FacePart("mouth", _r(31, 50), (31, 37), nose_bottom=16, lower_lip=(40, 49)),
)


def _ranges(value, where, path) -> tuple:
    if isinstance(value, int) and not isinstance(value, bool):
        return (value,)
    out = []
    if not isinstance(value, list):
        raise InputError(f"{where} must be a list of indices or [first, last] ranges",
                         path)
    for item in value:
        if isinstance(item, int) and not isinstance(item, bool):
            out.append(item)
        elif (isinstance(item, list) and len(item) == 2
              and all(isinstance(x, int) and not isinstance(x, bool) for x in item)
              and item[0] <= item[1]):
            out.extend(range(item[0], item[1] + 1))
        else:
            raise InputError(f"{where}: {item!r} is not an index or a [first, last] "
                             "range", path)
    if any(i < 0 for i in out):
        raise InputError(f"{where}: negative landmark index", path)
    return tuple(out)


def read_parts(path) -> tuple[FacePart, ...]:
    """Read face parts from a JSON file (format in the module docstring).

    Raises
    ------
    InputError
        Missing file, invalid JSON or an invalid part, naming the file.
    """
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    d = read_json(path)
    if not isinstance(d, dict) or d.get("format") != "facewrap.parts":
        raise InputError('not a facewrap parts file ("format": "facewrap.parts" '
                         "missing)", path)
    items = d.get("parts")
    if not isinstance(items, list) or not items:
        raise InputError("'parts' must be a non-empty list", path)
    parts = []
    for k, it in enumerate(items):
        where = f"part {k}"
        if not isinstance(it, dict) or not isinstance(it.get("name"), str):
            raise InputError(f"{where} must be an object with a 'name'", path)
        where = f"part {it['name']!r}"
        mouth = it.get("mouth") or {}
        try:
            parts.append(FacePart(
                it["name"], _ranges(it.get("landmarks"), f"{where} landmarks", path),
                _ranges(it.get("axis"), f"{where} axis", path),
                frame=_ranges(it["frame"], f"{where} frame", path) if "frame" in it
                else (),
                nose_bottom=int(mouth.get("nose_bottom", -1)) if mouth else -1,
                lower_lip=_ranges(mouth.get("lower_lip", []), f"{where} lower_lip",
                                  path) if mouth else ()))
        except ValueError as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(str(exc), path) from None
    return tuple(parts)


def _check_parts(parts, n_landmarks: int, path=None) -> None:
    for part in parts:
        idx = part.indices()
        if len(idx) and idx.max() >= n_landmarks:
            raise InputError(f"part {part.name!r} uses landmark {int(idx.max())} but "
                             f"there are only {n_landmarks} landmarks", path)


def part_frame(points, normals, part: FacePart) -> tuple[np.ndarray, np.ndarray]:
    """A part's rotation into its own frame and its bounding-box size there.

    Parameters
    ----------
    points : (L, 3) float64
        All landmark positions of one mesh.
    normals : (L, 3) float64
        Surface normals at the landmarks (orient the part's normal outward).
    part : FacePart

    Returns
    -------
    R : (3, 3) float64
        Rows: x axis, y axis, normal; ``R @ p`` is ``p`` in the part's frame.
    extent : (3,) float64
        Bounding-box size of the part's landmarks in that frame.
    """
    P = np.asarray(points, dtype=np.float64)
    Q = P[list(part.frame)]
    i, j = np.triu_indices(len(Q), 1)
    diffs = Q[i] - Q[j]
    n = np.linalg.svd(diffs, full_matrices=False)[2][-1]
    if np.dot(n, np.asarray(normals)[list(part.landmarks)].sum(axis=0)) < 0:
        n = -n
    x = P[part.axis[1]] - P[part.axis[0]]
    x = x - np.dot(x, n) * n
    nx = np.linalg.norm(x)
    if nx <= 1e-12 * max(np.abs(diffs).max(), 1e-300):
        # axis along the normal: any perpendicular will do
        x = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        nx = np.linalg.norm(x)
    x = x / nx
    R = np.stack([x, np.cross(n, x), n])
    E = P[list(part.landmarks)] @ R.T
    return R, E.max(axis=0) - E.min(axis=0)


def _lip_distance(P: np.ndarray, part: FacePart) -> float:
    return float(np.linalg.norm(P[list(part.lower_lip)].mean(axis=0) - P[part.nose_bottom]))


def part_motions(source_points, source_normals, target_points, target_normals,
                 parts=IBUG51_PARTS, ratio_range=(0.05, 20.0)
                 ) -> tuple[np.ndarray, np.ndarray, list[dict]]:
    """Per-part motion maps ``R_tᵀ A_k R_s`` (SPEC §4.3).

    Parameters
    ----------
    source_points, target_points : (L, 3) float64
        Landmarks on the source neutral and on the (rescaled, aligned) avatar.
    source_normals, target_normals : (L, 3) float64
        Surface normals there.
    parts : sequence of FacePart
    ratio_range : (float, float)
        Scale ratios are clipped to this range.

    Returns
    -------
    motions : (K, 3, 3) float64
        One matrix per part.
    landmark_part : (L,) int64
        Part of each landmark, -1 for landmarks in no part (they move as the
        source's, unscaled).
    info : list of dict
        Per part: ``name``, ``ratio`` (A_k diagonal).
    """
    Ps = np.asarray(source_points, dtype=np.float64)
    Pt = np.asarray(target_points, dtype=np.float64)
    L = len(Ps)
    motions = np.empty((len(parts), 3, 3))
    owner = np.full(L, -1, dtype=np.int64)
    info = []
    lo, hi = ratio_range
    for k, part in enumerate(parts):
        Rs, es = part_frame(Ps, source_normals, part)
        Rt, et = part_frame(Pt, target_normals, part)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(es > 0, et / np.where(es > 0, es, 1.0), 1.0)
        ratio = np.clip(np.nan_to_num(ratio, nan=1.0), lo, hi)
        if part.is_mouth:
            ds, dt = _lip_distance(Ps, part), _lip_distance(Pt, part)
            ratio[1] = np.clip(dt / ds, lo, hi) if ds > 0 else 1.0
            ratio[2] = 1.0
        elif es[2] < 0.1 * es[0] or et[2] < 0.1 * et[0]:
            # a flat part has no reliable depth: use the in-plane scale
            ratio[2] = np.sqrt(ratio[0] * ratio[1])
        motions[k] = Rt.T @ np.diag(ratio) @ Rs
        owner[list(part.landmarks)] = k
        info.append({"name": part.name, "ratio": ratio.tolist()})
    return motions, owner, info


#: Length of the paper's template diagonal (its onizuka2019 neutral, mm).
_PAPER_DIAGONAL = 380.0

#: Onizuka et al. 2019: one round w_S=1, w_I=0.1, w_C=0, then three with w_S=1,
#: w_I=0.001, w_C=1 in the paper's units (template diagonal ≈ 380 mm); here w_C is in
#: units of the source's bounding-box diagonal, 1 mm² of theirs ≈ 1/380² of ours.
ONIZUKA_SCHEDULE: tuple[CorrespondenceStage, ...] = (
    CorrespondenceStage(1.0, 0.1, 0.0),
    *(CorrespondenceStage(1.0, 0.001, _PAPER_DIAGONAL ** 2) for _ in range(3)),
)


class AvatarTransfer:
    """Key shapes for an avatar from a template blendshape set (Onizuka 2019).

    Parameters
    ----------
    w_d, w_l, w_s, w_i : float
        Weights of gradient matching, landmark motion, smoothness and identity
        (lengths measured with the source's bounding-box diagonal counting 380, as
        the paper's template in mm, so the defaults keep their meaning for a
        source in any unit).
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
    alignment_ : facewrap.wrapping.align.Similarity
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

    def __init__(self, w_d: float = 1.0, w_l: float = 100.0, w_s: float = 10.0,
                 w_i: float = 1.0, landmark_guided: bool = True,
                 parts=IBUG51_PARTS, correspondence: CorrespondenceSettings | None = None,
                 fix_flips: bool = True):
        self.w_d, self.w_l, self.w_s, self.w_i = w_d, w_l, w_s, w_i
        self.fix_flips = fix_flips
        self.landmark_guided = landmark_guided
        self.parts = tuple(parts)
        self.correspondence = correspondence

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
        t0 = time.perf_counter()
        ls, la = check_markers((source_landmarks, avatar_landmarks), source.n_vertices,
                               avatar.n_vertices, landmarks_path)
        if self.landmark_guided:
            _check_parts(self.parts, len(ls), landmarks_path)
            if self.w_l <= 0:
                raise ValueError("w_l must be > 0 (it fixes the translation)")
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
            settings = self.correspondence or CorrespondenceSettings(
                schedule=ONIZUKA_SCHEDULE, deform="target", align="none")
            correspondence = find_correspondence(source, aligned, (ls, la), settings,
                                                 markers_path=landmarks_path)
        correspondence.check(source, avatar)
        self.correspondence_ = correspondence
        t1 = time.perf_counter()
        # 3. the key-shape system
        if self.landmark_guided:
            self._fit_guided(source, aligned, ls, la)
        else:
            self._plain = DeformationTransfer(
                anchor="markers", fix_flips=self.fix_flips).fit(source, aligned,
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
        H = (self.w_d * (G.T @ sp.diags(np.repeat(counts, 3)) @ G)
             + self.w_s * (D.T @ D) + self.w_i * (G.T @ G)
             + sp.diags(self.w_l * lm_w / self._unit ** 2))
        # components without landmarks: a tiny pull toward rest fixes translation
        loose = np.zeros(op.n_unknowns)
        loose[:aligned.n_vertices] = untethered_vertices(aligned.triangles,
                                                         aligned.n_vertices, la)
        tether = _TETHER * float(H.diagonal().mean()) * loose
        H = H + sp.diags(tether)
        self._tether_rhs = tether[:, None] * op.extend(aligned.vertices)
        self._identity_rhs = self.w_i * np.asarray(
            G.T @ np.tile(np.eye(3), (op.n_triangles, 1)))
        self._H = H.tocsr()
        self.factor_ = factorize(self._H)
        self._repair = _FlipRepair(aligned.vertices, aligned.triangles, self._source_op,
                                   source.vertices,
                                   complete_pairs(self._pairs, aligned.triangles)[0])
        src_n = vertex_normals(source.vertices, source.triangles)[ls]
        ava_n = vertex_normals(aligned.vertices, aligned.triangles)[la]
        self.motions_, self._owner, self.parts_info_ = part_motions(
            source.vertices[ls], src_n, aligned.vertices[la], ava_n, self.parts)
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
        if self.landmark_guided:
            out = self._solve_guided(P)
        else:
            out = self._plain.transfer(P)
            if self.fix_flips:
                self.repairs_ = self._plain.repairs_
        out = self.alignment_.inverse().apply(out.reshape(-1, 3)).reshape(out.shape)
        return out[0] if single else out

    def _solve_guided(self, P: np.ndarray) -> np.ndarray:
        k = len(P)
        op = self._avatar_op
        blocks = source_gradient_blocks(self._source_op, P)
        summed = np.stack([self._pairs @ b for b in blocks])
        B = summed.reshape(k, op.n_triangles, 3, 3).transpose(1, 2, 0, 3)
        rhs = self.w_d * np.asarray(op.matrix.T @ B.reshape(3 * op.n_triangles, 3 * k))
        rhs += np.tile(self._identity_rhs + self._tether_rhs, (1, k))
        goals = self.landmark_targets(P)                                   # (k, L, 3)
        w = self.w_l / self._unit ** 2
        lm_rhs = np.zeros((op.n_unknowns, k, 3))
        np.add.at(lm_rhs, self._la, w * goals.transpose(1, 0, 2))
        rhs += lm_rhs.reshape(op.n_unknowns, 3 * k)
        x = self.factor_.solve(rhs)
        if self.fix_flips:
            out, self.repairs_ = self._repair.repair_poses(self._H, rhs, x, P)
            return out
        return x[:self.avatar_.n_vertices].reshape(-1, k, 3).transpose(1, 0, 2)

    def transfer_meshes(self, shapes) -> list[Mesh]:
        """:meth:`transfer` as meshes in the avatar's exact topology."""
        P, _ = as_pose_stack(shapes, self.source_.n_vertices, "shapes")
        return [self.avatar_.with_vertices(v) for v in self.transfer(P)]
