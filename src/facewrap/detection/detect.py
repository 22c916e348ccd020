"""``detect_landmarks``: the 68 iBUG points on a mesh, with no user input.

Steps (each in its own module): find the face from any direction
(:mod:`.search`), fit its frame, draw it from the front and turned to either side
(:mod:`.views`), detect the 68 points in each picture (:mod:`.backend`), lift them
onto the skin (through a template's lashes and tear films) and fuse the views
(:mod:`.fuse`), score down what the pictures fix poorly (the jaw contour's sides,
shaded brows), and snap the result onto the surface as triangle + barycentric
landmarks named :data:`~facewrap.landmarks.IBUG68_NAMES`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from facewrap.detection.backend import face_model
from facewrap.detection.fuse import Fused, fuse_views, seen_lifts
from facewrap.detection.search import face_frame, find_face, search_directions
from facewrap.detection.settings import DetectionSettings
from facewrap.detection.views import (Camera, SceneArrays, render_view, rotation_about,
                                      skin_triangles)
from facewrap.errors import InputError
from facewrap.geometry.checks import mesh_arrays
from facewrap.geometry.closest import ClosestPointTree
from facewrap.geometry.normals import trusted_face_normals
from facewrap.landmarks import IBUG68_NAMES, Landmarks

__all__ = ["DetectedLandmarks", "detect_landmarks"]

_FRAME_PASSES = 2        # frontal re-renders that settle the face frame
_NOSE_DEPTH = 0.125      # of the eye distance: least height of a nose tip
_REACH = 6.0             # pixels: a refined view's point off the surface's edge lifts
_SHADED_BROWS = 0.5      # confidence factor of the brows of an untextured picture
_BROWS = slice(17, 27)
_GRAZING = 0.6           # |cos| to the frontal view below which a point is less sure


@dataclass(frozen=True, eq=False)
class DetectedLandmarks:
    """The 68 landmarks found on a mesh.

    Attributes
    ----------
    landmarks : Landmarks
        68 surface landmarks (triangle + barycentric of the mesh's triangulation),
        named :data:`~facewrap.landmarks.IBUG68_NAMES`.
    positions : (68, 3) float64
        Their positions, on the surface.
    confidence : (68,) float64 in [0, 1]
        Share of the refined views that agree on the point times a Gaussian of their
        spread (see :mod:`facewrap.detection.fuse`), lowered where the surface turns
        away from the frontal view and for the brows of an untextured mesh (see
        :func:`_rescored`).
    low_confidence : (68,) bool
        ``confidence < settings.min_confidence``.
    reprojection : (68,) float64
        Mean distance, in pixels of the refined pictures, between each detected 2D
        point and the fused landmark projected into that view (NaN: seen nowhere).
    views : list of dict
        Every refined view: ``direction`` (3 floats, toward the camera, model
        coordinates), ``yaw`` and ``pitch`` (degrees from the frontal view),
        ``pixel_size`` (model units), ``found``.
    eye_distance : float
        Between the eye centres, model units.
    timings : dict of str to float
        Seconds: ``model`` (loading the detector, first call only), ``search``,
        ``refine``, ``fuse``, ``total``; ``pictures`` rendered.
    """
    landmarks: Landmarks
    positions: np.ndarray
    confidence: np.ndarray
    low_confidence: np.ndarray
    reprojection: np.ndarray
    views: list = field(default_factory=list)
    eye_distance: float = float("nan")
    timings: dict = field(default_factory=dict)


def _no_face(source, pictures: int) -> InputError:
    return InputError(f"no face found on the mesh ({pictures} picture"
                      f"{'' if pictures == 1 else 's'} from every direction); landmarks "
                      "can only be detected on a face scan", source)


def _face_like(points, rotation, eyes: float, views) -> bool:
    """Whether what was found is a face and not a pattern of shading: found in two
    refined views at least (when there are two), and a nose tip standing out of the
    eye corners' plane by an eighth of the eye distance (a real nose: about a third;
    a ball's curvature over the same span: under a tenth)."""
    if sum(v["found"] for v in views) < min(2, len(views)):
        return False
    depth = points @ rotation[2]
    corners = depth[[36, 39, 42, 45]]
    if not np.isfinite(depth[30]) or not np.isfinite(corners).any():
        return False
    return bool(depth[30] - np.nanmean(corners) > _NOSE_DEPTH * eyes)


def _frame_points(points) -> bool:
    """Whether lifted points hold what the face frame needs: some of each eye and
    of the mouth on the surface."""
    hit = np.isfinite(points).all(axis=1)
    return all(hit[s].sum() >= 2 for s in (slice(36, 42), slice(42, 48), slice(48, 68)))


def _central_face(model, view):
    """The face nearest the picture's centre, or None."""
    faces = model.faces(view.gray)
    if not faces:
        return None
    h, w = view.gray.shape
    centres = np.array([[(f.box[0] + f.box[2]) / 2, (f.box[1] + f.box[3]) / 2]
                        for f in faces])
    return faces[int(np.argmin(np.linalg.norm(centres - [w / 2, h / 2], axis=1)))]


def _face_camera(rotation, center, eye_distance, settings) -> Camera:
    """A refined camera: the face (about 2.6 eye distances wide) spans
    ``face_fraction`` of the picture."""
    size = settings.refine_size
    pixel = 2.6 * eye_distance / (settings.face_fraction * size)
    return Camera(rotation, center, pixel, (size, size))


def detect_landmarks(mesh, texture=None, *, settings: DetectionSettings | None = None,
                     tree: ClosestPointTree | None = None, source=None
                     ) -> DetectedLandmarks:
    """Detect the 68 iBUG landmarks on a face mesh in any orientation and unit.

    Parameters
    ----------
    mesh : Mesh or (V, T)
        The scan or template; a :class:`~facewrap.mesh.Mesh` with texture
        coordinates is drawn textured when ``texture`` is given, shaded otherwise.
    texture : (H, W, 3) uint8, optional
        The mesh's texture image (see :func:`mesh_texture`).
    settings : DetectionSettings, optional
    tree : ClosestPointTree, optional
        Of the same triangles, when the caller has one (it is built otherwise; a
        mesh of several pieces snaps onto its skin pieces, with a tree of its own).
    source : path, optional
        The mesh's file, named in errors.

    Returns
    -------
    DetectedLandmarks

    Raises
    ------
    InputError
        No face found (naming ``source``), or the optional extra is missing.

    Examples
    --------
    >>> from facewrap.sample import make_template                # doctest: +SKIP
    >>> found = detect_landmarks(make_template().mesh)           # doctest: +SKIP
    >>> found.positions.shape, found.landmarks.names[30]         # doctest: +SKIP
    ((68, 3), 'nose_base_...')
    """
    settings = settings or DetectionSettings()
    t0 = time.perf_counter()
    model = face_model()
    t_model = time.perf_counter() - t0
    V, T = mesh_arrays(mesh)
    uvs = getattr(mesh, "triangle_uvs", None)
    if texture is not None and getattr(mesh, "uvs", None) is None:
        raise InputError("a texture was given but the mesh has no texture coordinates",
                         source)
    corner_uvs = None if texture is None else mesh.uvs[uvs]
    scene = SceneArrays.of(V, T, corner_uvs, texture)
    t1 = time.perf_counter()
    found = find_face(scene, model, settings.search_size)
    if found is None:
        raise _no_face(source, len(search_directions(V, T)))
    pictures = found.pictures
    _, hit = found.view.lift(scene, found.face.points)
    skin = skin_triangles(V, T, hit)
    if skin is not None:        # lashes or tear films in front of the eyes: look through
        scene = replace(scene, skin=skin)
    # the frame's points with reach: an eye opening without an eyeball (a face-region
    # template, or scans made from one) shows the background behind the lid margins
    lifted, _ = found.view.lift(scene, found.face.points, _REACH)
    if not _frame_points(lifted):
        raise _no_face(source, pictures)
    rotation, center, eyes = face_frame(lifted, found.view.camera.direction)
    for _ in range(_FRAME_PASSES - 1):
        view = render_view(scene, _face_camera(rotation, center, eyes, settings))
        pictures += 1
        face = _central_face(model, view)
        if face is None:
            break
        pts, _ = view.lift(scene, face.points, _REACH)
        if not _frame_points(pts):
            break
        rotation, center, eyes = face_frame(pts, view.camera.direction)
    t2 = time.perf_counter()
    fused, views, reprojection, landed = _refined(scene, model, rotation, center, eyes,
                                                  settings)
    pictures += len(views)
    if scene.skin is None and (skin := skin_triangles(V, T, landed)) is not None:
        # the small search picture saw the skin, a refined one a lash or tear film
        # in front of it: look through those and refine again
        scene = replace(scene, skin=skin)
        fused, views, reprojection, _ = _refined(scene, model, rotation, center, eyes,
                                                 settings)
        pictures += len(views)
    if fused is None or not _face_like(fused.points, rotation, eyes, views):
        raise _no_face(source, pictures)
    t3 = time.perf_counter()
    result = _result(scene, fused, views, reprojection, eyes, settings, tree, source,
                     {"model": t_model, "search": t2 - t1, "refine": t3 - t2,
                      "pictures": pictures, "t1": t1, "t3": t3})
    return _rescored(result, scene, rotation[2], settings)


def _rescored(found: DetectedLandmarks, scene, front, settings) -> DetectedLandmarks:
    """Confidence times ``|cos|`` of the surface to the frontal view over
    :data:`_GRAZING` (at most 1), and times :data:`_SHADED_BROWS` for the brows of
    a mesh drawn without a texture.

    Where the face turns away from the front (the jaw contour's sides), a point a
    pixel off in the picture is ``1 / tan`` pixels off in depth: the detector's 2D
    jaw points on a turning cheek lift 10-20 mm from where an annotator clicks
    (measured on james and ICT's identities, ``bench_detection``), though every
    view agrees on them.  A brow is hair, not shape: shaded, the detector guesses
    it from the brow ridge, 6-8 mm off on every shaded case (james, ICT's template
    and identities, the sample template) against 3-4 mm textured, every view
    agreeing.  Those are flagged, not trusted.
    """
    lm = found.landmarks
    # the vertex normals' blend: smoother than one triangle's on a noisy scan
    normals = np.einsum("kj,kjd->kd", lm.barycentric, scene.normals[scene.T[lm.triangle]])
    length = np.maximum(np.linalg.norm(normals, axis=1), 1e-300)
    facing = np.abs(normals @ front) / length
    confidence = found.confidence * np.clip(facing / _GRAZING, 0.0, 1.0)
    if scene.texture is None:
        confidence[_BROWS] *= _SHADED_BROWS
    return replace(found, confidence=confidence,
                   low_confidence=confidence < settings.min_confidence)


def _refined(scene, model, rotation, center, eyes, settings):
    """Fused points of the frontal, yawed and pitched views, the views, reprojection
    (px), and the triangles the views' points landed on (-1: none)."""
    turns = [(0.0, 0.0)] + [(y, 0.0) for y in (settings.yaw, -settings.yaw) if y] \
        + [(0.0, p) for p in (settings.pitch, -settings.pitch) if p]
    normals = trusted_face_normals(scene.V, scene.T)
    normals = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
    lifts, pixels, cameras, views, landed = [], [], [], [], []
    for yaw, pitch in turns:
        turned = rotation @ rotation_about(rotation[1], yaw) @ rotation_about(rotation[0],
                                                                              pitch)
        cam = _face_camera(turned, center, eyes, settings)
        view = render_view(scene, cam)
        face = _central_face(model, view)
        views.append({"direction": cam.direction.tolist(), "yaw": yaw, "pitch": pitch,
                      "pixel_size": cam.pixel_size, "found": face is not None})
        if face is None:
            continue
        pts, tri = view.lift(scene, face.points, _REACH)
        landed.append(tri)
        lifts.append(seen_lifts(pts, tri, normals, cam.direction))
        pixels.append(face.points)
        cameras.append(cam)
    if not lifts:
        return None, views, None, np.zeros(0, dtype=np.int64)
    fused = fuse_views(np.stack(lifts), settings.agreement * eyes)
    errors = np.stack([np.linalg.norm(c.project(np.nan_to_num(fused.points)) - p, axis=1)
                       for c, p in zip(cameras, pixels)])
    reprojection = np.where(np.isfinite(fused.points).all(axis=1), errors.mean(axis=0),
                            np.nan)
    return fused, views, reprojection, np.concatenate(landed)


def _snapped(scene, points, tree, eyes: float):
    """Closest surface points (triangles, barycentric) of the fused points.

    Without the caller's tree, one is built over the triangles within a quarter eye
    distance of a point (the fused points lie within a millimetre or two of the
    surface): on a 200k-triangle scan a tree of all of them costs a second.
    """
    if tree is not None and scene.skin is None:
        found = tree.query(points)
        return found.triangles, found.barycentric
    from scipy.spatial import cKDTree

    kd = cKDTree(scene.V)
    near = np.zeros(len(scene.V), dtype=bool)
    near[np.concatenate([np.asarray(c, dtype=np.int64)
                         for c in kd.query_ball_point(points, 0.25 * eyes)])] = True
    near[kd.query(points)[1]] = True                        # at least the nearest vertex
    keep = np.flatnonzero(near[scene.T].any(axis=1))
    if scene.skin is not None:                        # never onto a lash or a tear film
        keep = np.intersect1d(keep, scene.skin)
    used, local = np.unique(scene.T[keep], return_inverse=True)
    found = ClosestPointTree(scene.V[used], local.reshape(-1, 3)).query(points)
    return keep[found.triangles], found.barycentric


def _result(scene, fused: Fused | None, views, reprojection, eyes, settings, tree,
            source, times) -> DetectedLandmarks:
    if fused is None:
        raise _no_face(source, times["pictures"])
    points = fused.points
    missing = ~np.isfinite(points).all(axis=1)
    if missing.all():
        raise _no_face(source, times["pictures"])
    if missing.any():
        # seen by no view: the middle of the others stands in (confidence 0, flagged)
        points = points.copy()
        points[missing] = points[~missing].mean(axis=0)
    triangles, bary = _snapped(scene, points, tree, eyes)
    confidence = np.where(missing, 0.0, fused.confidence)
    lm = Landmarks.from_barycentric(triangles, bary, IBUG68_NAMES)
    t_end = time.perf_counter()
    timings = {"model": times["model"], "search": times["search"],
               "refine": times["refine"], "fuse": t_end - times["t3"],
               "total": t_end - times["t1"] + times["model"],
               "pictures": times["pictures"]}
    return DetectedLandmarks(lm, lm.positions(scene.V, scene.T), confidence,
                             confidence < settings.min_confidence, reprojection, views,
                             float(eyes), timings)
