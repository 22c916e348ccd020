"""The 2D face detector and landmark model: dlib's, loaded once, on first use.

dlib's HOG frontal face detector (``dlib.get_frontal_face_detector``) finds faces;
the iBUG 300-W 68-point shape predictor (``shape_predictor_68_face_landmarks.dat``
from the ``face-recognition-models`` wheel) places the 68 points in iBUG order, so no
mapping table is needed.  Both come as wheels from PyPI (``dlib-bin``,
``face-recognition-models``) and nothing is fetched at run time.  They are the
optional extra ``facewrap[landmarks]``; without it :func:`face_model` raises one
:class:`~facewrap.errors.InputError` naming the extra.

Licence note: dlib is Boost-licensed, but the 68-point model was trained on the
iBUG 300-W data set, whose licence excludes commercial use; a studio shipping it
commercially needs its own model (see the README).

Why dlib rather than mediapipe 0.10.14 (measured, see ``docs/benchmarks.md``): its
points are the iBUG 68 natively, it installs as two wheels with no other
dependency (mediapipe pulls jax, matplotlib and a second, non-headless OpenCV that
needs a system GL library), and it works on numpy 1.26 and 2.x alike.
"""

from __future__ import annotations

import importlib.util
import os
from dataclasses import dataclass

import numpy as np

from facewrap.errors import InputError

__all__ = ["EXTRA_HINT", "IBUG68_MIRROR", "FaceFound", "FaceModel", "face_model"]

#: What to install when the detector is missing.
EXTRA_HINT = ("landmark detection needs the optional extra 'landmarks': "
              "pip install 'facewrap[landmarks]' (dlib-bin, face-recognition-models)")

#: iBUG-68 index of each point's mirror image (the subject's right and left swapped).
IBUG68_MIRROR = np.array(
    list(range(16, -1, -1)) + list(range(26, 16, -1)) + [27, 28, 29, 30]
    + [35, 34, 33, 32, 31] + [45, 44, 43, 42, 47, 46] + [39, 38, 37, 36, 41, 40]
    + [54, 53, 52, 51, 50, 49, 48, 59, 58, 57, 56, 55] + [64, 63, 62, 61, 60, 67, 66, 65])

#: Starting boxes of the predictor: (scale, shift right, shift down), shifts in half
#: box widths, around the detector's box.
_JITTER = ((1.0, 0.0, 0.0), (1.08, 0.0, 0.0), (0.93, 0.0, 0.0))

_PREDICTOR = os.path.join("models", "shape_predictor_68_face_landmarks.dat")
_MODEL = None          # the loaded FaceModel, shared by every call in the process


@dataclass(frozen=True)
class FaceFound:
    """One face in one picture.

    Attributes
    ----------
    box : (4,) float64
        left, top, right, bottom in pixels.
    score : float
        The detector's score (larger is surer; 0 is its threshold).
    points : (68, 2) float64
        iBUG-68 points, pixel coordinates (x right, y down; centres at integers).
    """
    box: np.ndarray
    score: float
    points: np.ndarray


class FaceModel:
    """dlib's detector and 68-point predictor (build with :func:`face_model`)."""

    def __init__(self, dlib_module, predictor_path: str):
        self._dlib = dlib_module
        self._detector = dlib_module.get_frontal_face_detector()
        self._predictor = dlib_module.shape_predictor(predictor_path)

    def faces(self, gray: np.ndarray, upsample: int = 0) -> list[FaceFound]:
        """Faces found in a (H, W) uint8 picture, best score first.

        ``upsample`` doubles the picture that many times first (finds smaller faces).
        """
        img = np.ascontiguousarray(gray, dtype=np.uint8)
        rects, scores, _ = self._detector.run(img, int(upsample), 0.0)
        found = []
        for rect, score in zip(rects, scores):
            box = np.array([rect.left(), rect.top(), rect.right(), rect.bottom()],
                           dtype=np.float64)
            found.append(FaceFound(box, float(score), self.points(img, box)))
        return sorted(found, key=lambda f: -f.score)

    def points(self, gray: np.ndarray, box) -> np.ndarray:
        """(68, 2) points of the face in ``box``.

        The mean of the predictor's answers from a few boxes (the detector's, a
        little larger and smaller: the regression depends on where it starts) on the picture and on its mirror image (mirrored back, left and
        right swapped, which cancels the model's one-sided bias).
        """
        left, top, right, bottom = np.asarray(box, dtype=np.float64)
        # the predictor copies the picture it is given: give it the face's surroundings
        h, w = gray.shape
        pad = right - left
        c0, r0 = int(max(left - pad, 0)), int(max(top - pad, 0))
        c1, r1 = int(min(right + pad + 1, w)), int(min(bottom + pad + 1, h))
        img = np.ascontiguousarray(gray[r0:r1, c0:c1], dtype=np.uint8)
        flipped = np.ascontiguousarray(img[:, ::-1])
        w = img.shape[1]
        left, right, top, bottom = left - c0, right - c0, top - r0, bottom - r0
        cx, cy, half = (left + right) / 2, (top + bottom) / 2, (right - left) / 2
        total = np.zeros((68, 2))
        for scale, dx, dy in _JITTER:
            r = half * scale
            x0, x1 = cx + dx * half - r, cx + dx * half + r
            y0, y1 = cy + dy * half - r, cy + dy * half + r
            total += self._shape(img, x0, y0, x1, y1)
            mirror = self._shape(flipped, w - 1 - x1, y0, w - 1 - x0, y1)
            mirror[:, 0] = w - 1 - mirror[:, 0]
            total += mirror[IBUG68_MIRROR]
        return total / (2 * len(_JITTER)) + [c0, r0]

    def _shape(self, img, left, top, right, bottom) -> np.ndarray:
        box = self._dlib.rectangle(*(int(round(v)) for v in (left, top, right, bottom)))
        shape = self._predictor(img, box)
        return np.array([[p.x, p.y] for p in shape.parts()], dtype=np.float64)


def _predictor_path() -> str | None:
    """The 68-point model's file inside ``face_recognition_models``, without importing
    the package (its ``__init__`` imports the deprecated ``pkg_resources``)."""
    spec = importlib.util.find_spec("face_recognition_models")
    if spec is None or not spec.submodule_search_locations:
        return None
    for folder in spec.submodule_search_locations:
        path = os.path.join(folder, _PREDICTOR)
        if os.path.isfile(path):
            return path
    return None


def face_model() -> FaceModel:
    """The process's face model, loaded on first use (about a second).

    Raises
    ------
    InputError
        When the optional extra ``facewrap[landmarks]`` is not installed.
    """
    global _MODEL
    if _MODEL is None:
        try:
            import dlib
        except ImportError:
            raise InputError(EXTRA_HINT) from None
        path = _predictor_path()
        if path is None:
            raise InputError(EXTRA_HINT)
        _MODEL = FaceModel(dlib, path)
    return _MODEL
