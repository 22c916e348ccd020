"""Finding the face on a mesh in any orientation and unit, then the face's frame.

The mesh is drawn whole from up to 26 directions (the six axes first, then the
twelve edge and eight corner diagonals of a cube), ordered so the directions the
surface faces most come first (an open face scan faces its front; a closed head
leaves the order as it is).  Each picture is shown to the detector at four
in-plane turns (``np.rot90``: free, no new render), which covers every 90° turn
of a scan about any axis.  The first direction with a face ends the search.  The 68 points of that face, lifted onto the surface, give the face frame
(:func:`face_frame`): eyes left to right, up from the mouth to the eyes, front
toward the viewer; the refined views look along it.  The detector finds faces of
about 80 pixels and more, so a face must span a quarter of ``search_size`` (a head
scan does; a full-body scan needs a larger ``search_size``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import product

import numpy as np

from facewrap.detection.backend import FaceFound, FaceModel
from facewrap.detection.views import Camera, RenderedView, SceneArrays, render_view

__all__ = ["SearchResult", "search_directions", "find_face", "face_frame"]

_MARGIN = 1.1          # the whole mesh fills 1 / _MARGIN of a search picture
_EYE_R, _EYE_L, _MOUTH = slice(36, 42), slice(42, 48), slice(48, 68)


def search_directions(V, T) -> np.ndarray:
    """(26, 3) unit view directions, the ones the surface faces most first.

    Ties (a closed head, whose normals cancel) keep the order axes, edges, corners.

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])        # faces +z
    >>> search_directions(V, [[0, 1, 2]])[0].tolist()
    [0.0, 0.0, 1.0]
    """
    cube = np.array([d for d in product((-1, 0, 1), repeat=3) if any(d)], dtype=np.float64)
    kind = np.abs(cube).sum(axis=1)                           # 1 axis, 2 edge, 3 corner
    D = cube / np.linalg.norm(cube, axis=1, keepdims=True)
    V = np.asarray(V, dtype=np.float64)
    T = np.asarray(T, dtype=np.int64)
    facing = np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]).sum(axis=0)
    norm = np.linalg.norm(facing)
    total = np.linalg.norm(np.cross(V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]),
                           axis=1).sum()
    # an open scan's summed normal is a sizeable share of its area; a closed one's ~0
    score = D @ (facing / norm) if norm > 0.05 * total else np.zeros(len(D))
    order = np.lexsort((kind, -np.round(score, 6)))
    return D[order]


def _camera_looking_along(direction, center, pixel_size, size) -> Camera:
    """A camera on the ``direction`` side of ``center`` with some up perpendicular."""
    back = direction / np.linalg.norm(direction)
    helper = np.eye(3)[int(np.argmin(np.abs(back)))]
    right = np.cross(helper, back)
    right /= np.linalg.norm(right)
    up = np.cross(back, right)
    return Camera(np.stack([right, up, back]), center, pixel_size, size)


def _unturn(points, k: int, w: int, h: int) -> np.ndarray:
    """Pixel coordinates in ``np.rot90(image, k)`` back to the (h, w) image's."""
    x, y = points[:, 0], points[:, 1]
    back = {0: (x, y), 1: (w - 1 - y, x), 2: (w - 1 - x, h - 1 - y), 3: (y, h - 1 - x)}
    return np.column_stack(back[k % 4])


@dataclass(frozen=True, eq=False)
class SearchResult:
    """The first face found.

    Attributes
    ----------
    view : RenderedView
        The picture it was found in.
    face : FaceFound
        Its box, score and 68 points in that picture's pixels (turn undone).
    turn : int
        Quarter turns of the picture the detector saw.
    pictures : int
        Pictures rendered until then.
    """
    view: RenderedView
    face: FaceFound
    turn: int
    pictures: int


def find_face(scene: SceneArrays, model: FaceModel, size: int) -> SearchResult | None:
    """Search the view directions for a frontal face (None when there is none).

    Parameters
    ----------
    scene : SceneArrays
    model : FaceModel
    size : int
        Pixels across each search picture.
    """
    V = scene.V
    center = (V.min(axis=0) + V.max(axis=0)) / 2
    pixel = np.linalg.norm(V.max(axis=0) - V.min(axis=0)) * _MARGIN / size
    directions = search_directions(V, scene.T)
    pictures = 0
    for d in directions:
        view = render_view(scene, _camera_looking_along(d, center, pixel, (size, size)))
        pictures += 1
        if not np.any(view.gray):
            continue
        best = None
        for k in range(4):
            faces = model.faces(np.rot90(view.gray, k))
            if faces and (best is None or faces[0].score > best[0].score):
                best = (faces[0], k)
        if best is not None:
            face, k = best
            pts = _unturn(face.points, k, size, size)
            corners = _unturn(face.box.reshape(2, 2), k, size, size)
            box = np.r_[corners.min(axis=0), corners.max(axis=0)]
            return SearchResult(view, FaceFound(box, face.score, pts), k, pictures)
    return None


def face_frame(points: np.ndarray, toward) -> tuple[np.ndarray, np.ndarray, float]:
    """The face's frame from its 68 points lifted onto the surface.

    Parameters
    ----------
    points : (68, 3) float64
        NaN where a point missed the surface (at least the eyes and mouth must hit).
    toward : (3,) float64
        A direction from the face toward the camera that saw it.

    Returns
    -------
    rotation : (3, 3) float64
        Rows: subject's right-to-left, up, front (a camera rotation looking at the
        face from the front).
    center : (3,) float64
        Middle of the points.
    eye_distance : float
        Between the eye centres, in model units.
    """
    eye_r = np.nanmean(points[_EYE_R], axis=0)
    eye_l = np.nanmean(points[_EYE_L], axis=0)
    mouth = np.nanmean(points[_MOUTH], axis=0)
    x = eye_l - eye_r
    eye_distance = float(np.linalg.norm(x))
    x /= eye_distance
    up = (eye_r + eye_l) / 2 - mouth
    up -= (up @ x) * x
    up /= np.linalg.norm(up)
    front = np.cross(x, up)
    if front @ toward < 0:      # a mirrored lift cannot be: keep the viewer's side
        front = -front
    ok = np.isfinite(points).all(axis=1)
    center = (points[ok].min(axis=0) + points[ok].max(axis=0)) / 2
    return np.stack([x, up, front]), center, eye_distance
