"""The built-in template head: a quad grid over the domain, eyeballs, blendshapes.

The grid follows the layout's density (finer at the eyes and mouth), is cut along
the mouth slit and snapped to the lid margins, so that landmarks fall on vertices;
two UV-sphere eyeballs close the eye sockets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.sample.identity import face_identity
from facewrap.sample.layout import (EYE_HALF_WIDTH, EYE_S, EYE_T, GRID_SPACING, LANDMARK_NAMES,
                                    MOUTH_HALF_WIDTH, MOUTH_T, S_MAX, S_MIN, T_MAX, T_MIN,
                                    cumulative_density, eye_local, landmark_layout, lid_margins,
                                    relative_spacing_s, relative_spacing_t, slit_half_height,
                                    uv_from_st)
from facewrap.sample.surface import EXPRESSIONS, expression_offsets, head_surface

__all__ = ["checked_resolution", "SampleTemplate", "make_template"]


def _grid_lines(anchors, rel, h0) -> np.ndarray:
    """Grid coordinates with local spacing ``h0 * rel(x)``, exact at ``anchors``."""
    out = [np.array([anchors[0]])]
    for a, b in zip(anchors[:-1], anchors[1:]):
        x, cum = cumulative_density(a, b, rel)
        n = max(1, int(round(cum[-1] / h0)))
        out.append(np.interp(np.linspace(0.0, cum[-1], n + 1), cum, x)[1:])
    lines = np.concatenate(out)
    lines[[0, -1]] = anchors[0], anchors[-1]
    return lines


def _face_grid(resolution):
    """Structured quad grid over the domain, cut along the mouth slit.

    Returns (s, t) per vertex, (m, 4) quads, and the ids of the upper and lower slit
    edges (the two corners are shared by both).
    """
    h0 = GRID_SPACING / resolution
    sl = _grid_lines(np.array([S_MIN, -MOUTH_HALF_WIDTH, 0.0, MOUTH_HALF_WIDTH, S_MAX]),
                     relative_spacing_s, h0)
    tl = _grid_lines(np.array([T_MIN, MOUTH_T, T_MAX]), relative_spacing_t, h0)
    ns, nt = len(sl), len(tl)
    S, T = np.meshgrid(sl, tl, indexing="xy")          # (nt, ns)
    ids = np.arange(nt * ns).reshape(nt, ns)
    jm = int(np.flatnonzero(tl == MOUTH_T)[0])
    cols = np.flatnonzero(np.abs(sl) < MOUTH_HALF_WIDTH)      # slit columns, corners excluded
    # the grid row on the mouth line is the upper lip; a copy of it is the lower lip
    lower_ids = ids[jm].copy()
    lower_ids[cols] = nt * ns + np.arange(len(cols))
    s = np.concatenate([S.ravel(), sl[cols]])
    t = np.concatenate([T.ravel(), np.full(len(cols), MOUTH_T)])
    up = ids[jm, cols]
    t[up] += slit_half_height(s[up])
    t[nt * ns:] -= slit_half_height(s[nt * ns:])
    bottom, top = ids[:-1], ids[1:].copy()
    top[jm - 1] = lower_ids                            # the band under the mouth line
    quads = np.stack([bottom[:, :-1], bottom[:, 1:], top[:, 1:], top[:, :-1]],
                     axis=-1).reshape(-1, 4)
    edge = np.abs(sl) <= MOUTH_HALF_WIDTH
    return s, t, quads, ids[jm, edge], lower_ids[edge]


def _uv_sphere(n_lon, n_lat):
    """Unit UV sphere around +z (pole at the front).

    Returns vertices (n, 3), flat faces ``(offsets, indices)`` (quads, triangle fans at
    the two poles), a UV table and per-corner UV indices (seam at longitude 0).
    """
    pol = np.pi * np.arange(1, n_lat) / n_lat
    lon = 2.0 * np.pi * np.arange(n_lon) / n_lon
    P, L = np.meshgrid(pol, lon, indexing="ij")
    ring = np.stack([np.sin(P) * np.cos(L), np.sin(P) * np.sin(L), np.cos(P)], axis=-1)
    nr = n_lat - 1
    V = np.concatenate([[[0.0, 0.0, 1.0]], ring.reshape(-1, 3), [[0.0, 0.0, -1.0]]])
    rid = 1 + np.arange(nr * n_lon).reshape(nr, n_lon)
    south = 1 + nr * n_lon
    k = np.arange(n_lon)
    k1 = (k + 1) % n_lon
    # UV table: rings with a seam column, then one corner per pole triangle
    uv_ring = np.stack(np.meshgrid(np.arange(n_lon + 1) / n_lon, 1.0 - pol / np.pi,
                                   indexing="xy"), axis=-1).reshape(-1, 2)
    uid = np.arange(nr * (n_lon + 1)).reshape(nr, n_lon + 1)
    npole = len(uv_ring)
    uvs = np.concatenate([uv_ring, np.stack([(k + 0.5) / n_lon, np.ones(n_lon)], 1),
                          np.stack([(k + 0.5) / n_lon, np.zeros(n_lon)], 1)])
    north = np.stack([np.zeros(n_lon, int), rid[0, k], rid[0, k1]], 1)
    north_uv = np.stack([npole + k, uid[0, k], uid[0, k + 1]], 1)
    quads = np.stack([rid[:-1, k], rid[1:, k], rid[1:, k1], rid[:-1, k1]],
                     -1).reshape(-1, 4)
    quads_uv = np.stack([uid[:-1, k], uid[1:, k], uid[1:, k + 1], uid[:-1, k + 1]],
                        -1).reshape(-1, 4)
    south_f = np.stack([np.full(n_lon, south), rid[-1, k1], rid[-1, k]], 1)
    south_uv = np.stack([npole + n_lon + k, uid[-1, k + 1], uid[-1, k]], 1)
    sizes = np.concatenate([np.full(n_lon, 3), np.full(len(quads), 4), np.full(n_lon, 3)])
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    faces = np.concatenate([north.ravel(), quads.ravel(), south_f.ravel()])
    face_uvs = np.concatenate([north_uv.ravel(), quads_uv.ravel(), south_uv.ravel()])
    return V, (offsets, faces), uvs, face_uvs


def _snap_lid_margins(s, t):
    """Move, in each grid column across an eye, the vertex nearest to each lid margin
    onto it, so that the margins are mesh edges (a blink then folds no quad).

    Returns the new ``t`` and the ids of the upper and lower margin vertices.
    """
    t = t.copy()
    a, b = eye_local(s, t)
    up, lo, _ = lid_margins(a)
    column = np.unique(s, return_inverse=True)[1]
    cand = np.flatnonzero(np.abs(a) < 0.85 * EYE_HALF_WIDTH)
    ids = []
    for margin in (up, lo):
        order = cand[np.lexsort((np.abs(b - margin)[cand], column[cand]))]
        nearest = order[np.r_[True, np.diff(column[order]) != 0]]
        t[nearest] += (margin - b)[nearest]
        ids.append(nearest)
    return t, ids[0], ids[1]


def _pick_landmarks(s, t, pools):
    """Vertex ids of the 68 landmarks, and (s, t) with the eye-corner vertices snapped.

    Each landmark takes the nearest unused vertex in ``(s, t)`` from its pool (see
    :func:`landmark_layout`); eye corners then move that vertex exactly onto the
    corner (less than half a grid cell).
    """
    target, kind = landmark_layout()
    st = np.stack([s, t], axis=1)
    trees = {k: cKDTree(st[v]) for k, v in pools.items()}
    chosen: set[int] = set()
    # the landmarks with few candidates first
    order = np.argsort(np.where(kind == 0, 1, 0), kind="stable")
    picked = np.empty(len(target), dtype=np.int64)
    for i in order.tolist():
        k = int(kind[i])
        free = []
        # the 8 nearest first; on a coarse grid they can all be taken: then all
        for many in sorted({min(8, len(pools[k])), len(pools[k])}):
            _, cand = trees[k].query(target[i], k=many)
            free = [j for j in pools[k][np.atleast_1d(cand)].tolist() if j not in chosen]
            if free:
                break
        if not free:
            raise ValueError("the grid is too coarse for 68 distinct landmark vertices: "
                             "use a higher resolution")
        picked[i] = free[0]
        chosen.add(free[0])
    s, t = s.copy(), t.copy()
    snap = kind == 1
    s[picked[snap]], t[picked[snap]] = target[snap, 0], target[snap, 1]
    return picked, s, t


def _eyeball(ident, side, n_lon, n_lat):
    """Eyeball sphere behind the eye dome of ``side`` (+1 left, -1 right)."""
    s_c = np.array([side * EYE_S])
    apex = head_surface(s_c, np.array([EYE_T]), ident)[0]
    direction = apex / np.linalg.norm(apex)
    radius = 11.0
    centre = apex - (radius + 1.2) * direction
    V, faces, uvs, face_uvs = _uv_sphere(n_lon, n_lat)
    return centre + radius * V, faces, uvs, face_uvs


def checked_resolution(resolution, name="resolution", low=8) -> int:
    """``resolution`` as an int, checked to be an integer >= ``low`` (``name`` in errors)."""
    if isinstance(resolution, (bool, np.bool_)) or not isinstance(
            resolution, (int, np.integer)):
        raise ValueError(f"{name} must be an int, got {resolution!r}")
    if resolution < low:
        raise ValueError(f"{name} must be at least {low}, got {resolution}")
    return int(resolution)


@dataclass(frozen=True)
class SampleTemplate:
    """The built-in template head (see :func:`make_template`).

    Attributes
    ----------
    mesh : Mesh
        Quads: a structured grid over the parameter domain cut along the mouth slit,
        plus two closed UV-sphere eyeballs (quads with triangle fans at their poles).
        UVs are per corner: the face's are its normalised parameter coordinates, the
        eyeballs' a longitude/latitude map with a seam.  ``face_groups`` index
        ``groups = ("face", "eyeball_left", "eyeball_right")``.
    landmarks : Landmarks
        68 vertex landmarks named :data:`LANDMARK_NAMES`, on the face part.
    blendshapes : dict of str to (n, 3) float64
        Vertex positions of each expression in :data:`EXPRESSIONS` at weight 1, in
        template topology; the eyeballs do not move.
    parts : dict of str to (k,) int64
        Vertex ids of ``"face"``, ``"eyeball_left"``, ``"eyeball_right"``,
        ``"mouth_lips"`` (both edges of the mouth slit, corners once) and
        ``"eyelids"`` (face vertices that move when the eyes blink: lids and the
        eye opening).
    params : (n, 2) float64
        Normalised parameter coordinates ``(u, v)`` of each vertex, NaN for the
        eyeballs.
    """

    mesh: Mesh
    landmarks: Landmarks
    blendshapes: dict
    parts: dict
    params: np.ndarray


#: the coarsest grid with 68 distinct landmark vertices
MIN_TEMPLATE_RESOLUTION = 16


def make_template(resolution: int = 64) -> SampleTemplate:
    """The built-in template head: the default face, with blendshapes.

    Parameters
    ----------
    resolution : int, default 64
        Grid cells across the face (about ``200 / resolution`` mm apart at the face
        centre, finer at the eyes and mouth, coarser toward the back and top).  The
        default gives about 7,400 vertices; at least :data:`MIN_TEMPLATE_RESOLUTION`.

    Returns
    -------
    SampleTemplate

    Raises
    ------
    ValueError
        If ``resolution`` is not an int >= :data:`MIN_TEMPLATE_RESOLUTION`.

    Examples
    --------
    >>> tpl = make_template(32)
    >>> tpl.mesh.groups
    ('face', 'eyeball_left', 'eyeball_right')
    >>> len(tpl.landmarks), tpl.landmarks.names[30]
    (68, 'nose_bridge_3')
    >>> bool(np.isnan(tpl.params[tpl.parts["eyeball_left"]]).all())
    True
    """
    # below 16 cells the grid has too few vertices for 68 distinct landmarks
    resolution = checked_resolution(resolution, low=MIN_TEMPLATE_RESOLUTION)
    s, t, quads, upper_edge, lower_edge = _face_grid(resolution)
    t, lid_up, lid_lo = _snap_lid_margins(s, t)
    every = np.arange(len(s))
    lm, s, t = _pick_landmarks(s, t, {0: every, 1: every, 2: upper_edge, 3: lower_edge,
                                      4: lid_up, 5: lid_lo})
    ident = face_identity(0)
    X0 = head_surface(s, t, ident)
    D = expression_offsets(s, t, ident, X0, EXPRESSIONS)
    n_face = len(s)

    n_lon = max(8, 2 * (resolution // 8))
    n_lat = max(6, n_lon // 2 + 2)
    eyes = [_eyeball(ident, side, n_lon, n_lat) for side in (1.0, -1.0)]
    n_eye = len(eyes[0][0])
    V = np.concatenate([X0, eyes[0][0], eyes[1][0]])
    (eo, ei), euv, efuv = eyes[0][1], eyes[0][2], eyes[0][3]
    m_face, m_eye = len(quads), len(eo) - 1
    offsets = np.concatenate([np.arange(m_face + 1) * 4,
                              m_face * 4 + eo[1:], m_face * 4 + ei.size + eo[1:]])
    indices = np.concatenate([quads.ravel(), n_face + ei, n_face + n_eye + ei])
    uvs = np.concatenate([uv_from_st(s, t), euv])
    face_uvs = np.concatenate([quads.ravel(), n_face + efuv, n_face + efuv])
    groups = np.repeat([0, 1, 2], [m_face, m_eye, m_eye])
    mesh = Mesh(V, (offsets, indices), uvs=uvs, face_uvs=(offsets, face_uvs),
                face_groups=groups, groups=("face", "eyeball_left", "eyeball_right"))

    blend = {}
    for name in EXPRESSIONS:
        B = V.copy()
        B[:n_face] += D[name]
        B.setflags(write=False)
        blend[name] = B
    params = np.full((len(V), 2), np.nan)
    params[:n_face] = uv_from_st(s, t)
    params.setflags(write=False)
    moved = np.linalg.norm(D["blink"], axis=1) > 1e-6
    parts = {"face": np.arange(n_face, dtype=np.int64),
             "eyeball_left": n_face + np.arange(n_eye, dtype=np.int64),
             "eyeball_right": n_face + n_eye + np.arange(n_eye, dtype=np.int64),
             "mouth_lips": np.unique(np.concatenate([upper_edge, lower_edge])),
             "eyelids": np.flatnonzero(moved).astype(np.int64)}
    for a in parts.values():
        a.setflags(write=False)
    return SampleTemplate(mesh=mesh, landmarks=Landmarks.from_vertices(lm, LANDMARK_NAMES),
                          blendshapes=blend, parts=parts, params=params)
