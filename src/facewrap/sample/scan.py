"""Synthetic scans of other faces, with the truth that relates them to the template.

A scan samples the same parametric surface (:mod:`facewrap.sample.surface`) for
another identity and expression at jittered points of its own topology, with
noise, holes, a crop and a similarity transform; its ground truth is the template's
parameter points on that face.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import Delaunay

from facewrap.geometry.normals import vertex_normals
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.sample.identity import face_identity
from facewrap.sample.layout import (BLINK_GAP, EYE_HALF_WIDTH, GRID_SPACING, LANDMARK_NAMES,
                                    MOUTH_HALF_WIDTH, MOUTH_T, S_MAX, S_MIN, T_MAX, T_MIN,
                                    cumulative_density, eye_local, in_slit, landmark_layout,
                                    lid_margins, relative_spacing_s, relative_spacing_t,
                                    slit_half_height, st_from_uv, uv_from_st)
from facewrap.sample.skin import skin_texture
from facewrap.sample.surface import checked_weights, posed_surface
from facewrap.sample.template import SampleTemplate, checked_resolution, make_template

__all__ = ["checked_transform", "SampleScan", "make_scan"]


def _stream(seed: int, purpose: int) -> np.random.Generator:
    """An independent random stream per purpose, so that e.g. ``noise=0`` and
    ``noise=0.2`` with one seed give the same topology and transform."""
    return np.random.default_rng([int(seed), purpose])


def _jittered_samples(h, rng) -> tuple[np.ndarray, np.ndarray]:
    """Irregular samples of the whole domain, denser at the face (spacing ~h there),
    with points along the domain boundary so that the samples cover it all.

    Returns s, t and a mask of the boundary points."""
    axes = []
    for lo, hi, rel in ((S_MIN, S_MAX, relative_spacing_s), (T_MIN, T_MAX, relative_spacing_t)):
        x, cum = cumulative_density(lo, hi, rel)
        axes.append((x, cum, max(2, int(math.ceil(cum[-1] / h)))))
    (xs, cs, ns), (xt, ct, nt) = axes
    i, j = np.meshgrid(np.arange(ns), np.arange(nt), indexing="xy")
    ju = rng.uniform(-0.35, 0.35, size=(2,) + i.shape)
    s = np.interp((i.ravel() + 0.5 + ju[0].ravel()) / ns * cs[-1], cs, xs)
    t = np.interp((j.ravel() + 0.5 + ju[1].ravel()) / nt * ct[-1], ct, xt)
    es = np.interp(np.linspace(0.0, cs[-1], ns + 1), cs, xs)
    et = np.interp(np.linspace(0.0, ct[-1], nt + 1), ct, xt)
    bs = np.concatenate([es, es, np.full(nt - 1, S_MIN), np.full(nt - 1, S_MAX)])
    bt = np.concatenate([np.full(ns + 1, T_MIN), np.full(ns + 1, T_MAX), et[1:-1], et[1:-1]])
    border = np.concatenate([np.zeros(len(s), bool), np.ones(len(bs), bool)])
    return np.concatenate([s, bs]), np.concatenate([t, bt]), border


def _keep_probability(s, t, weights):
    """Chance that a scanner sample survives at ``(s, t)``: a shut eye squeezes its
    opening to a thin strip, where a scanner sees few points (the posed/neutral area
    ratio there); 1 elsewhere."""
    w = weights.get("blink", 0.0)
    if w == 0.0:
        return np.ones_like(s)
    a, b = eye_local(s, t)
    up, lo, _ = lid_margins(a)
    inside = (b > lo) & (b < up) & (np.abs(a) < EYE_HALF_WIDTH)
    return np.where(inside, 1.0 - w * (1.0 - BLINK_GAP), 1.0)


def _slit_edge_points(h):
    """Points along both lips of the mouth slit (corners once), about ``h/2`` apart."""
    n = max(4, int(math.ceil(2 * MOUTH_HALF_WIDTH / (0.5 * h))))
    s = np.linspace(-MOUTH_HALF_WIDTH, MOUTH_HALF_WIDTH, n + 1)[1:-1]
    hh = slit_half_height(s)
    return (np.concatenate([s, s, [-MOUTH_HALF_WIDTH, MOUTH_HALF_WIDTH]]),
            np.concatenate([MOUTH_T + hh, MOUTH_T - hh, [MOUTH_T, MOUTH_T]]))


def _crop_region(rng):
    """Scanner coverage: a predicate ``inside(s, t)`` keeping the face and front of
    the head (no back, top or neck), its outline wobbling like a real scan's."""
    k = np.arange(1, 4)[:, None]
    amp, phase = rng.uniform(1.0, 3.0, (3, 1)), rng.uniform(0.0, 2.0 * np.pi, (3, 1))

    def inside(s, t, margin=0.0):
        ripple = (amp * np.sin(3.0 * k * np.arctan2(t + 10.0, s) + phase)).sum(axis=0)
        ripple = ripple + margin
        side = 140.0 + ripple
        top = 78.0 - 28.0 * (s / 140.0) ** 2 + ripple
        bottom = -104.0 + 45.0 * (np.abs(s) / 140.0) ** 2 - ripple
        return (np.abs(s) < side) & (t < top) & (t > bottom)
    return inside


def _scan_triangles(s, t, crop):
    """Delaunay triangles in ``(s, t)``, counter-clockwise, without the ones that
    span the mouth slit or lie outside the cropped coverage."""
    st = np.stack([s, t], axis=1)
    T = Delaunay(st).simplices.astype(np.int64)
    e1, e2 = st[T[:, 1]] - st[T[:, 0]], st[T[:, 2]] - st[T[:, 0]]
    flip = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    T[flip] = T[flip][:, [0, 2, 1]]
    c = st[T].mean(axis=1)
    keep = ~in_slit(c[:, 0], c[:, 1])
    # no edge may cross the mouth line between the corners
    for a, b in ((0, 1), (1, 2), (2, 0)):
        pa, pb = st[T[:, a]], st[T[:, b]]
        da, db = pa[:, 1] - MOUTH_T, pb[:, 1] - MOUTH_T
        cross = da * db < 0
        w = np.divide(da, da - db, out=np.zeros_like(da), where=cross)
        sc = pa[:, 0] + w * (pb[:, 0] - pa[:, 0])
        keep &= ~(cross & (np.abs(sc) < MOUTH_HALF_WIDTH))
    if crop is not None:
        keep &= crop(c[:, 0], c[:, 1])
    return T[keep]


def _compact(T, n):
    """Drop unused vertices: new triangles and the old id of each kept vertex."""
    used = np.unique(T)
    remap = np.full(n, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return remap[T], used


def _scan_topology(h, seed, weights, crop):
    """Samples of a scan before damage: ``s``, ``t``, a standard-normal draw per
    point (its sensor noise) and counter-clockwise triangles.

    Every random draw is made on the full sample set, so one point gets the same
    position and noise whatever ``crop`` and ``holes`` remove around it.
    """
    s, t, border = _jittered_samples(h, _stream(seed, 1))
    chance = _keep_probability(s, t, weights)
    keep = border | (_stream(seed, 8).uniform(size=len(s)) < chance)
    local = h * relative_spacing_s(s) * relative_spacing_t(t)
    keep &= ~((np.abs(s) < MOUTH_HALF_WIDTH + 0.3 * local)
              & (np.abs(t - MOUTH_T) < slit_half_height(s) + 0.4 * local))
    es, et = _slit_edge_points(0.6 * h)
    s, t = np.concatenate([s[keep], es]), np.concatenate([t[keep], et])
    eta = _stream(seed, 4).standard_normal(len(s))
    inside = None
    if crop:
        inside = _crop_region(_stream(seed, 2))
        near = inside(s, t, margin=6.0 * h)       # a margin keeps the triangles local
        s, t, eta = s[near], t[near], eta[near]
    T, used = _compact(_scan_triangles(s, t, inside), len(s))
    return s[used], t[used], eta[used], T


def _hole_centres(count, radius, rng):
    """(count, 2) ``(s, t)`` centres on the cheeks and forehead, away from landmarks
    and from each other."""
    zones = np.array([[38.0, 62.0, -42.0, -18.0],     # |s| range, t range: cheeks
                      [8.0, 42.0, 33.0, 56.0],        # forehead
                      [55.0, 80.0, 8.0, 40.0]])       # temples
    order = [(0, -1), (1, 1), (0, 1), (1, -1), (2, -1), (2, 1)]
    landmarks, _ = landmark_layout()
    centres = []
    for k in range(count):
        zone, side = order[k % len(order)]
        for _ in range(200):
            s0, s1, t0, t1 = zones[zone]
            c = np.array([side * rng.uniform(s0, s1), rng.uniform(t0, t1)])
            far_lm = np.min(np.linalg.norm(landmarks - c, axis=1)) > radius + 4.0
            far_h = all(np.linalg.norm(c - o) > 2.0 * radius + 4.0 for o in centres)
            if far_lm and far_h:
                centres.append(c)
                break
        else:
            raise ValueError(f"holes: cannot place {count} holes of radius {radius} mm "
                             "on the cheeks and forehead; use fewer or smaller holes")
    return np.asarray(centres, dtype=np.float64).reshape(-1, 2)


def _rotation(axis, angle):
    axis = np.asarray(axis, dtype=np.float64) / np.linalg.norm(axis)
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]],
                  [-axis[1], axis[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * K @ K


def checked_transform(transform, seed) -> np.ndarray:
    """The scan's (4, 4) similarity: ``transform`` checked, or drawn from ``seed``.

    ``True`` draws a rotation of 10-20 degrees and a translation of 20-50 mm per
    axis; ``False`` is the identity; an array must be a finite (4, 4) affine matrix.
    """
    if isinstance(transform, (bool, np.bool_)):
        M = np.eye(4)
        if transform:
            rng = _stream(seed, 5)
            axis = rng.normal(size=3)
            angle = math.radians(rng.uniform(10.0, 20.0))
            M[:3, :3] = _rotation(axis, angle)
            M[:3, 3] = rng.uniform(20.0, 50.0, 3) * rng.choice([-1.0, 1.0], 3)
        return M
    M = np.asarray(transform, dtype=np.float64)
    if M.shape != (4, 4) or not np.isfinite(M).all():
        raise ValueError(f"transform must be a bool or a finite (4, 4) array, got "
                         f"shape {M.shape}")
    if not np.allclose(M[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError("transform: the last row must be [0, 0, 0, 1]")
    return M.copy()


def _apply(M, X):
    return X @ M[:3, :3].T + M[:3, 3]


@dataclass(frozen=True)
class SampleScan:
    """A synthetic scan and its truth (see :func:`make_scan`).

    Attributes
    ----------
    mesh : Mesh
        Triangles in a topology of their own, per-vertex UVs (normalised parameter
        coordinates, for :attr:`texture`), ``texture`` set to None.
    texture : (H, W, 3) uint8
        Procedural albedo for ``mesh.uvs`` (row 0 is the top, ``v = 1``): skin, hair,
        brows, lips, lashes, and eye whites and irises as far as the eyes are open.
    landmarks : Landmarks
        68 free points named :data:`LANDMARK_NAMES`: the true positions of the
        template's landmarks on this face, plus ``landmark_noise``.
    ground_truth : (n_template, 3) float64
        Where each template vertex truly lands on this scan (same face and
        expression at the vertex's parameters, in scan coordinates); NaN for the
        eyeballs.  Points in holes or cropped regions are off the scan surface.
    transform : (4, 4) float64
        Similarity applied to the canonical head: ``scan = transform @ canonical``.
    weights : dict of str to float
        The expression weights used.
    """

    mesh: Mesh
    texture: np.ndarray
    landmarks: Landmarks
    ground_truth: np.ndarray
    transform: np.ndarray
    weights: dict


def make_scan(template: SampleTemplate | None = None, *,
              weights: dict[str, float] | None = None, identity_seed: int = 1,
              resolution: int = 90, noise: float = 0.2, holes: int = 2,
              hole_radius: float = 8.0, crop: bool = True, landmark_noise: float = 0.0,
              transform: bool | np.ndarray = True, texture_size: int = 512,
              seed: int = 0) -> SampleScan:
    """A synthetic raw scan of face ``identity_seed`` with expression ``weights``.

    The domain is sampled irregularly (jittered, spacing about ``200 / resolution``
    mm at the face), triangulated in the parameter plane with points along both
    lips of the mouth slit and no triangle across it, mapped to 3-D through the
    posed face, then damaged like a real scan.

    Parameters
    ----------
    template : SampleTemplate, optional
        Template whose vertices :attr:`SampleScan.ground_truth` follows (default
        ``make_template()``).
    weights : dict of str to float, optional
        Expression weights in [0, 1] by name (:data:`EXPRESSIONS`).  Default
        ``{"jaw_open": 0.8, "blink": 1.0, "smile": 0.3}``: mouth open, eyes shut.
    identity_seed : int, default 1
        Face to scan; 0 is the template's own face.
    resolution : int, default 90
        Samples across the face (>= 8): about ``200 / resolution`` mm apart there.
    noise : float, default 0.2
        Sigma (mm) of Gaussian displacement along the surface normal.
    holes : int, default 2
        Disc-shaped holes cut on the cheeks and forehead, away from landmarks.
    hole_radius : float, default 8.0
        Their radius, mm.
    crop : bool, default True
        Keep only what a face scanner sees (no back or top of the head, no neck).
    landmark_noise : float, default 0.0
        Sigma (mm) of Gaussian noise added to the landmark points.
    transform : bool or (4, 4) array_like, default True
        True: a seeded rigid motion (rotation of 10-20 degrees, translation of
        20-50 mm per axis, scale 1); False: none; an array: that affine map.
    texture_size : int, default 512
        Texture height and width, pixels.
    seed : int, default 0
        Sampling, crop outline, hole places, noise and transform (each from its own
        stream: a point keeps its position and noise whatever ``crop``, ``holes``
        or ``noise`` change).  The texture's skin detail follows ``identity_seed``.

    Returns
    -------
    SampleScan

    Raises
    ------
    ValueError
        For an unknown expression or a weight outside [0, 1], a negative noise,
        radius or hole count, a bad transform, or holes that do not fit.

    Examples
    --------
    >>> tpl = make_template(24)
    >>> a = make_scan(tpl, resolution=30, texture_size=16, seed=3)
    >>> b = make_scan(tpl, resolution=30, texture_size=16, seed=3)
    >>> bool(np.array_equal(a.mesh.vertices, b.mesh.vertices))
    True
    >>> a.mesh.n_vertices != tpl.mesh.n_vertices, a.texture.shape
    (True, (16, 16, 3))
    """
    template = make_template() if template is None else template
    weights = checked_weights(weights)
    resolution = checked_resolution(resolution)
    texture_size = checked_resolution(texture_size, "texture_size", low=1)
    holes = checked_resolution(holes, "holes", low=0)
    for name, value in (("noise", noise), ("hole_radius", hole_radius),
                        ("landmark_noise", landmark_noise)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    M = checked_transform(transform, seed)
    ident = face_identity(identity_seed)

    # 1. irregular samples of the domain (and the slit's lips), triangulated
    s, t, eta, T = _scan_topology(GRID_SPACING / resolution, seed, weights, crop)
    # 2. the posed face, with holes
    X = posed_surface(s, t, ident, weights)
    if holes:
        centres = _hole_centres(holes, hole_radius, _stream(seed, 3))
        C = posed_surface(centres[:, 0], centres[:, 1], ident, weights)
        d = np.min(np.linalg.norm(X[:, None, :] - C[None, :, :], axis=2), axis=1)
        T, used = _compact(T[(d[T] >= hole_radius).all(axis=1)], len(s))
        s, t, X, eta = s[used], t[used], X[used], eta[used]
    # 3. sensor noise along the normal, rigid motion
    if noise > 0:
        X = X + noise * eta[:, None] * vertex_normals(X, T)
    X = _apply(M, X)

    # 4. truth: template vertices on this face, landmarks
    face = template.parts["face"]
    ts, tt = st_from_uv(template.params[face])
    truth = np.full((template.mesh.n_vertices, 3), np.nan)
    truth[face] = _apply(M, posed_surface(ts, tt, ident, weights))
    points = truth[template.landmarks.vertex]
    if landmark_noise > 0:
        points = points + landmark_noise * _stream(seed, 6).standard_normal(points.shape)
    truth.setflags(write=False)
    M.setflags(write=False)
    tex = skin_texture(texture_size, ident, _stream(identity_seed, 7),
                   eyes_open=1.0 - weights.get("blink", 0.0))
    tex.setflags(write=False)
    mesh = Mesh(X, T, uvs=uv_from_st(s, t))
    return SampleScan(mesh=mesh, texture=tex,
                      landmarks=Landmarks.from_points(points, LANDMARK_NAMES),
                      ground_truth=truth, transform=M, weights=weights)
