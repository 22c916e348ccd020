"""Checks of a wrap's inputs that are legal but odd, for :mod:`facewrap.jobs.wrap_job`.

Each returns one line per oddity (counts; nothing is changed), or refuses what
cannot be fitted with an :class:`~facewrap.errors.InputError` naming the file:
:func:`survey_mesh` (repeated vertices, zero-area triangles, non-manifold edges,
loose pieces), :func:`weld_duplicates` (exact duplicate scan vertices merged, so
seams split by an exporter do not read as holes), :func:`check_landmark_spread`,
:func:`check_landmarks_on_scan`.
"""

from __future__ import annotations

import numpy as np

from facewrap.errors import InputError
from facewrap.geometry import connected_components
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh

__all__ = ["duplicate_map", "survey_mesh", "weld_duplicates", "check_landmark_spread",
           "check_landmarks_on_scan"]


def duplicate_map(V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First occurrence of each distinct position: (unique_index, inverse)."""
    rows = np.ascontiguousarray(V).view(np.dtype((np.void, V.dtype.itemsize * 3)))[:, 0]
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    return first, inverse.reshape(-1)


def survey_mesh(mesh, path, what: str, pieces: bool = True) -> list[str]:
    """One line per oddity of a mesh's triangles (counts; nothing is changed).

    ``pieces``: also report disconnected pieces (not for templates, whose eyes and
    teeth are separate pieces by design).
    """
    out = []
    T = mesh.triangles
    V = mesh.vertices
    repeated = (T[:, 0] == T[:, 1]) | (T[:, 1] == T[:, 2]) | (T[:, 0] == T[:, 2])
    if repeated.any():
        out.append(f"{path}: {what} has {int(repeated.sum())} triangle(s) with a "
                   "repeated vertex")
    e1, e2 = V[T[:, 1]] - V[T[:, 0]], V[T[:, 2]] - V[T[:, 0]]
    area2 = np.linalg.norm(np.cross(e1, e2), axis=1)
    scale = mesh.scale()
    flat = (area2 <= 1e-12 * scale * scale) & ~repeated
    if flat.any():
        out.append(f"{path}: {what} has {int(flat.sum())} zero-area triangle(s)")
    good = T[~repeated]
    if len(good):
        E = np.sort(np.concatenate([good[:, [0, 1]], good[:, [1, 2]], good[:, [2, 0]]]),
                    axis=1)
        key = E[:, 0] * np.int64(mesh.n_vertices) + E[:, 1]
        _, counts = np.unique(key, return_counts=True)
        nm = int((counts > 2).sum())
        if nm:
            out.append(f"{path}: {what} has {nm} non-manifold edge(s) (shared by more "
                       "than two triangles)")
    if not pieces:
        return out
    used = np.zeros(mesh.n_vertices, dtype=bool)
    used[T.ravel()] = True
    labels = connected_components(T, mesh.n_vertices)[used]
    pieces = len(np.unique(labels))
    if pieces > 1:
        sizes = np.bincount(labels)
        sizes = sizes[sizes > 0]
        out.append(f"{path}: {what} has {pieces} disconnected pieces (the largest "
                   f"has {int(sizes.max())} of {int(used.sum())} vertices)")
    return out


def weld_duplicates(mesh, landmarks, path):
    """Merge exactly coincident scan vertices; returns (mesh, landmarks, warning).

    Triangle count and order, UVs and normals per corner are kept, so triangle ids
    of surface landmarks and texture baking are unaffected.
    """
    first, inverse = duplicate_map(mesh.vertices)
    dupes = mesh.n_vertices - len(first)
    if dupes == 0:
        return mesh, landmarks, None
    offsets = mesh.face_offsets
    kw = mesh.corner_attributes()
    if mesh.vertex_colors is not None:
        kw.update(vertex_colors=mesh.vertex_colors[first])
    welded = Mesh(mesh.vertices[first], (offsets, inverse[mesh.face_indices]),
                  face_materials=mesh.face_materials, materials=mesh.materials,
                  face_groups=mesh.face_groups, groups=mesh.groups, mtllib=mesh.mtllib,
                  texture=mesh.texture, **kw)
    if np.any(landmarks.vertex >= 0):
        v = np.where(landmarks.vertex >= 0, inverse[np.maximum(landmarks.vertex, 0)], -1)
        landmarks = Landmarks(v, landmarks.triangle, landmarks.barycentric,
                              landmarks.points, landmarks.names)
    return welded, landmarks, (f"{path}: scan has {dupes} duplicate vertices (same "
                               "position); merged for fitting")


def check_landmark_spread(points: np.ndarray, path) -> None:
    """Landmarks must span a plane at least, or the alignment is undetermined."""
    P = points - points.mean(axis=0)
    s = np.linalg.svd(P, compute_uv=False)
    if len(points) < 3 or s[0] == 0 or s[1] <= 1e-6 * s[0]:
        raise InputError("landmarks are all at one point or on one line; the "
                         "alignment needs at least three landmarks not in a line", path)


def check_landmarks_on_scan(points: np.ndarray, names, tree, scale: float, path) -> list[str]:
    """Scan landmarks should lie on (or near) the scan surface."""
    d = tree.query(points).distances
    far = d > 0.05 * scale
    if np.median(d) > 0.1 * scale:
        raise InputError(f"landmarks are not on the scan: median distance to its "
                         f"surface {np.median(d):.4g}, scan size {scale:.4g} (wrong "
                         "landmark file, or other units?)", path)
    if far.any():
        worst = int(np.argmax(d))
        label = names[worst] if names is not None else str(worst)
        return [f"{path}: {int(far.sum())} landmark(s) lie off the scan surface "
                f"(farthest: {label}, {d[worst]:.4g} away; scan size {scale:.4g})"]
    return []
