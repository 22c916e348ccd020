"""Face parts of the landmark-guided avatar transfer (Onizuka et al. 2019, SPEC §4).

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
from dataclasses import dataclass

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import read_json

__all__ = ["FacePart", "IBUG51_PARTS", "read_parts", "check_parts", "part_frame",
           "part_motions"]


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


def check_parts(parts, n_landmarks: int, path=None) -> None:
    """Raise :class:`InputError` (naming ``path``) when a part uses a landmark index
    beyond ``n_landmarks``."""
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
