"""The built-in synthetic sample: a procedural template head, scans of other faces,
and the truth that relates them.

Everything here is a pure, deterministic function of its arguments (fixed seeds,
``np.random.default_rng``), needs no data files and carries no licence.  It is the
default input of ``make demo`` and of every test that must run without real data.

Geometry
--------
Units are millimetres; +y is up, +z points out of the face (the face looks toward
+z) and +x is the subject's left.  The head is a **parametric surface**
``S(s, t; identity, expression)`` over a 2-D parameter domain:

* ``s = 100 * azimuth`` (radians about the vertical axis, 0 at the nose, positive
  toward the subject's left), ``t = 100 * elevation`` (0 at the eye line), both in
  "millimetres at 100 mm radius", so features can be laid out in millimetres;
* the normalised parameter ``(u, v) = ((s - s0) / (s1 - s0), (t - t0) / (t1 - t0))``
  in ``[0, 1]^2`` is what :attr:`SampleTemplate.params` and the UVs hold.

The radius about the head centre is a smooth base (front and side profiles blended
by a super-ellipse) plus Gaussian and smoothstep features: forehead, brow ridge, eye
sockets with an eyeball dome and upper/lower lids, nose (bridge, tip, alae,
nostrils), cheekbones, lips, chin, jaw and ears.  The **mouth slit** is a thin
lens-shaped cut of the domain (``|t - t_m| < h(s)`` for ``|s| < w_m``), so the two
lips are distinct points of the domain and can part.

Identity is a handful of feature parameters (head size, nose length/width/projection,
eye spacing, mouth width, lip fullness, jaw width, chin, cheekbones, brow ridge)
drawn from ``identity_seed``; seed 0 (or None) is the template's own face.  The
layout of the domain (where the eyes, lids and lips are in ``(s, t)``) never changes
with identity, so one parameter point means "the same place" on every face: that is
how :attr:`SampleScan.ground_truth` is defined.

Expressions are displacement fields on the domain (:data:`EXPRESSIONS`), combined
linearly like blendshapes: ``x = S(p) + sum_k w_k D_k(p)`` with weights in [0, 1].

Landmarks follow the iBUG-68 order of :data:`LANDMARK_NAMES`.  As in iBUG, "left" and
"right" in the *numbering* are the image's (a frontal photo): points 17-21 (the
``brow_r_*`` names) and 36-41 (``eye_r_*``) lie on the **subject's right** (-x,
image left); the ``r``/``l`` in the names are the subject's sides.

Examples
--------
>>> tpl = make_template(24)
>>> tpl.mesh.n_vertices == len(tpl.params), sorted(tpl.blendshapes) == sorted(EXPRESSIONS)
(True, True)
>>> scan = make_scan(tpl, resolution=30, texture_size=32)
>>> scan.mesh.is_triangle_mesh, scan.ground_truth.shape == (tpl.mesh.n_vertices, 3)
(True, True)
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from scipy.interpolate import PchipInterpolator
from scipy.spatial import Delaunay, cKDTree

from facewrap.geometry.normals import vertex_normals
from facewrap.io.atomic import atomic_write
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh

__all__ = ["EXPRESSIONS", "LANDMARK_NAMES", "SampleTemplate", "SampleScan",
           "make_template", "make_scan", "make_sequence", "write_sample"]

#: Expression (blendshape) names, in the order of :attr:`SampleTemplate.blendshapes`.
EXPRESSIONS: tuple[str, ...] = ("jaw_open", "smile", "blink", "brow_raise", "pucker")

#: The 68 iBUG landmark names in their standard order (see the module docstring for
#: the left/right convention): ``jaw_0..16``, ``brow_r_0..4`` (17-21),
#: ``brow_l_0..4`` (22-26), ``nose_bridge_0..3`` (27-30), ``nose_base_0..4``
#: (31-35), ``eye_r_0..5`` (36-41), ``eye_l_0..5`` (42-47), ``mouth_outer_0..11``
#: (48-59), ``mouth_inner_0..7`` (60-67).
LANDMARK_NAMES: tuple[str, ...] = IBUG68_NAMES

_DEFAULT_WEIGHTS = {"jaw_open": 0.8, "blink": 1.0, "smile": 0.3}

# ---------------------------------------------------------------------------------
# Parameter domain and layout (millimetres in (s, t); never depends on identity)
# ---------------------------------------------------------------------------------
_RHO = 100.0                                   # mm of (s, t) per radian
_S0, _S1 = -_RHO * math.radians(105.0), _RHO * math.radians(105.0)
_T0, _T1 = _RHO * math.radians(-68.0), _RHO * math.radians(72.0)

_EYE_S, _EYE_T = 32.0, 1.0         # eye centres at (+-_EYE_S, _EYE_T)
_EYE_HW = 14.0                     # half width of the eye opening (corner to centre)
_LID_UP, _LID_LO = 5.8, 4.2        # opening above / below the centre line
_CREASE = 5.5                      # upper-lid crease height above the lid margin
_EYE_TILT = 0.07                   # canthal tilt: lateral corner higher
_BLINK_GAP = 0.06                  # fraction of the opening left when the eye is shut
_EYE_RADIUS = 13.5                 # radius of the eyeball dome (mm of (s, t))

_MOUTH_T = -61.0                   # mouth line
_MOUTH_HW = 25.0                   # half width of the slit (corner to centre)
_SLIT = 0.6                        # half height of the slit at the centre

_SPACING = 200.0                   # spacing at the face centre is _SPACING / resolution
_JAW_AXIS = np.array([0.0, -18.0, 8.0])   # a point on the jaw hinge (x axis)
_JAW_ANGLE = 0.28                         # radians at full jaw_open
_JAW_SLIDE = np.array([0.0, -4.0, 10.0])   # the condyles glide forward as the jaw opens


def _uv_from_st(s, t) -> np.ndarray:
    return np.stack([(s - _S0) / (_S1 - _S0), (t - _T0) / (_T1 - _T0)], axis=-1)


def _st_from_uv(uv) -> tuple[np.ndarray, np.ndarray]:
    uv = np.asarray(uv, dtype=np.float64)
    return _S0 + uv[..., 0] * (_S1 - _S0), _T0 + uv[..., 1] * (_T1 - _T0)


def _smoothstep(x):
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _gauss(ds, dt, sx, sy):
    return np.exp(-0.5 * ((ds / sx) ** 2 + (dt / sy) ** 2))


def _odd_gauss(s, c, dt, sx, sy):
    """Smooth odd pair of bumps at ``s = +-c``: +1 near ``+c``, -1 near ``-c``."""
    return _gauss(s - c, dt, sx, sy) - _gauss(s + c, dt, sx, sy)


def _slit_half_height(s):
    """Half height of the mouth slit at ``s`` (0 outside the mouth)."""
    x = np.clip(np.abs(s) / _MOUTH_HW, 0.0, 1.0)
    return _SLIT * (1.0 - x * x)


def _in_slit(s, t):
    return (np.abs(s) < _MOUTH_HW) & (np.abs(t - _MOUTH_T) < _slit_half_height(s))


# ---------------------------------------------------------------------------------
# Identity
# ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class _Identity:
    """Feature parameters of one face (defaults = the template's face).

    Lengths in mm, the rest are multipliers of the default feature sizes.
    """

    width: float = 1.0          # head scale along x
    height: float = 1.0         # head scale along y
    depth: float = 1.0          # head scale along z
    eye_spacing: float = 0.0    # mm moved outward by each eye
    nose_length: float = 0.0    # mm moved down by the nose tip
    nose_width: float = 0.0     # mm moved outward by each ala
    nose_projection: float = 1.0
    mouth_width: float = 0.0    # mm moved outward by each mouth corner
    lip_fullness: float = 1.0
    jaw_width: float = 1.0
    chin: float = 1.0
    cheekbones: float = 1.0
    brow_ridge: float = 1.0
    skin: float = 0.0           # skin tone shift for the texture (-1 darker .. 1 lighter)


_IDENTITY_SD = _Identity(width=0.04, height=0.035, depth=0.04, eye_spacing=1.8,
                         nose_length=2.5, nose_width=1.5, nose_projection=0.12,
                         mouth_width=2.0, lip_fullness=0.2, jaw_width=0.25, chin=0.25,
                         cheekbones=0.25, brow_ridge=0.25, skin=0.5)


def _identity(seed: int | None) -> _Identity:
    """The face of ``seed``: defaults for 0/None, else drawn around them (+-2 sd)."""
    if seed is None or seed == 0:
        return _Identity()
    z = np.clip(np.random.default_rng(seed).standard_normal(len(fields(_Identity))),
                -2.0, 2.0)
    base = _Identity()
    return _Identity(**{f.name: getattr(base, f.name) + k * getattr(_IDENTITY_SD, f.name)
                        for f, k in zip(fields(_Identity), z.tolist())})


# ---------------------------------------------------------------------------------
# Base head: radius about the centre as a function of azimuth/elevation
# ---------------------------------------------------------------------------------
def _polar_profile(points_yz):
    pts = np.asarray(points_yz, dtype=np.float64)
    phi = np.arctan2(pts[:, 0], pts[:, 1])
    r = np.hypot(pts[:, 0], pts[:, 1])
    order = np.argsort(phi)
    return PchipInterpolator(phi[order], r[order], extrapolate=True)


# mid-sagittal front profile (y, z) and side profile (y, x) of the bare head
_FRONT = _polar_profile([(-112, 10), (-107, 40), (-103, 62), (-95, 80), (-80, 89),
                         (-60, 92), (-30, 95), (0, 95), (25, 95), (50, 90), (75, 78),
                         (95, 55), (108, 25), (112, 0)])
_SIDE = _polar_profile([(-118, 45), (-100, 48), (-78, 52), (-55, 61), (-30, 70),
                        (0, 76), (30, 76), (55, 72), (80, 58), (100, 30), (110, 5)])
_SUPER = 2.4


def _base_radius(theta, phi):
    """Radius of the bare head: the front and side profiles joined by a
    super-ellipse around the vertical axis (squarer at the face, round on top)."""
    rf, rs = _FRONT(phi), _SIDE(phi)
    c, sn = np.abs(np.cos(theta)), np.abs(np.sin(theta))
    p = 2.0 + (_SUPER - 2.0) * (1.0 - _smoothstep((phi - 0.4) / 0.6))   # round on top
    return ((c / rf) ** p + (sn / rs) ** p) ** (-1.0 / p)


# ---------------------------------------------------------------------------------
# Features (radial relief in mm, functions of (s, t))
# ---------------------------------------------------------------------------------
def _eye_local(s, t):
    """Eye-local coordinates: ``a`` (lateral positive) and ``b`` (up, tilt removed)."""
    a = np.abs(s) - _EYE_S
    return a, t - _EYE_T - _EYE_TILT * a


def _lid_margins(a):
    """Upper margin, lower margin and upper crease heights (in ``b``) along ``a``."""
    x = np.clip(a / _EYE_HW, -1.0, 1.0)
    f = (1.0 - x * x) ** 0.75
    up = _LID_UP * f * (1.0 - 0.15 * x)
    lo = -_LID_LO * f * (1.0 + 0.15 * x)
    xc = np.clip(a / (_EYE_HW + 3.0), -1.0, 1.0)
    crease = up + _CREASE * (1.0 - xc * xc)
    return up, lo, crease


def _blink_remap(s, t):
    """Where each domain point sits on the shut eye (``t`` changed near the eyes).

    The opening shrinks to ``_BLINK_GAP`` of its height at the lower margin and the
    upper lid (margin to crease) stretches down over it; monotone, so the surface
    stays valid.
    """
    a, b = _eye_local(s, t)
    up, lo, crease = _lid_margins(a)
    up_c = lo + _BLINK_GAP * (up - lo)
    inside = (b > lo) & (b < up)
    lid = (b >= up) & (b < crease)
    new_b = b.copy()
    h = np.maximum(up - lo, 1e-12)
    new_b[inside] = (lo + (b - lo) * (up_c - lo) / h)[inside]
    hl = np.maximum(crease - up, 1e-12)
    new_b[lid] = (up_c + (b - up) * (crease - up_c) / hl)[lid]
    return t + (new_b - b)


def _eye_opening(a, b, closure):
    """1 where the eyeball shows between the lid margins, 0 on the lids (smooth)."""
    up, lo, _ = _lid_margins(a)
    up = lo + (1.0 - closure * (1.0 - _BLINK_GAP)) * (up - lo)
    eps = 1.2
    return (_smoothstep((up - b) / eps + 0.5) * _smoothstep((b - lo) / eps + 0.5)
            * _smoothstep((up - lo) / (2.0 * eps)))


def _eye_relief(s, t, ident, closure):
    """Socket, eyeball bulge, lid margins and the upper-lid crease."""
    a, b = _eye_local(s, t)
    up, lo, crease = _lid_margins(a)
    socket = -14.0 * _gauss(a + 1.0, b - 1.0, 16.0, 13.0)
    rho2 = (a / 1.2) ** 2 + (b / 1.05) ** 2
    bulge = 9.0 * (1.0 - _smoothstep(rho2 / _EYE_RADIUS ** 2))
    env = np.clip(1.0 - (a / (_EYE_HW + 2.0)) ** 2, 0.0, 1.0)
    lid_up = 2.0 * env * np.exp(-0.5 * np.clip(b - up, 0.0, None) ** 2 / 3.0 ** 2)
    lid_lo = 0.9 * env * np.exp(-0.5 * np.clip(lo - b, 0.0, None) ** 2 / 2.0 ** 2)
    upper = _smoothstep((b - 0.5 * (up + lo)) / 3.0 + 0.5)
    lids = (lid_lo + (lid_up - lid_lo) * upper) * (1.0 - _eye_opening(a, b, closure))
    fold = -1.4 * env * np.exp(-0.5 * ((b - crease) / 2.0) ** 2)
    return socket + bulge + lids + fold


def _nose_relief(s, t, ident):
    """Bridge, tip, alae and nostrils."""
    p = ident.nose_projection
    as_ = np.abs(s)
    # dorsum: rises from the nasion to the tip, then turns under to the columella
    x = np.clip((6.0 - t) / 35.0, 0.0, 1.0)
    height = (1.5 + 19.0 * x ** 1.25) * (1.0 - _smoothstep((t - 6.0) / 9.0))
    height = height * (1.0 - _smoothstep((-29.0 - t) / 12.0))
    width = 5.0 + 4.0 * x ** 1.5
    dorsum = height * np.exp(-0.5 * (as_ / width) ** 2.4)
    tip = 4.0 * _gauss(s, t + 28.5, 6.5, 5.0)
    lobule = 6.0 * _gauss(s, t + 33.0, 7.0, 4.5) * (1.0 - _smoothstep((-37.0 - t) / 5.0))
    alae = 7.0 * _gauss(as_ - 11.5, t + 36.0, 4.0, 4.0)
    ring = np.hypot(as_ - 11.5, (t + 36.0) / 0.9)
    alar_crease = (-0.8 * np.exp(-0.5 * (ring - 5.5) ** 2)
                   * _smoothstep((t + 42.0) / 3.0))
    nostrils = -1.8 * _gauss(as_ - 6.0, t + 40.5, 2.2, 1.3)
    return p * (dorsum + tip + lobule + alae + nostrils) + alar_crease


def _lip_extent(s):
    """Heights of the upper and lower vermilion above/below the mouth line."""
    x = np.clip(np.abs(s) / _MOUTH_HW, 0.0, 1.0)
    bow = (0.9 * np.exp(-0.5 * ((np.abs(s) - 5.0) / 2.5) ** 2)      # cupid's bow
           - 0.6 * np.exp(-0.5 * (s / 1.8) ** 2))
    upper = (8.0 + bow) * (1.0 - x * x) ** 0.6
    lower = 10.0 * (1.0 - x * x) ** 0.5
    return upper, lower


def _mouth_relief(s, t, ident):
    """Lips (rolled in at the slit), philtrum, mouth corners, chin."""
    b = t - _MOUTH_T
    as_ = np.abs(s)
    full = ident.lip_fullness
    # the dental arch: the mouth region is a forward mound, the corners recede
    muzzle = 7.0 * _gauss(s, b + 4.0, 24.0, 14.0)
    eu, el = _lip_extent(s)
    xu = np.clip(b / np.maximum(eu, 1e-3), 0.0, 1.6)
    xl = np.clip(-b / np.maximum(el, 1e-3), 0.0, 1.6)
    upper = np.where(b > 0, np.sin(np.pi * np.minimum(xu, 1.0)) ** 1.3, 0.0)
    lower = np.where(b < 0, np.sin(np.pi * np.minimum(xl, 1.0)) ** 1.3, 0.0)
    width = np.clip(1.0 - (s / (_MOUTH_HW + 1.0)) ** 2, 0.0, 1.0) ** 0.7
    lips = full * width * (3.2 * upper + 3.8 * lower)
    roll = -3.0 * np.exp(-0.5 * (b / 1.2) ** 2) * width
    white_roll = 0.6 * np.exp(-0.5 * ((b - eu) / 0.8) ** 2) * _smoothstep(b) * width
    philtrum = (-0.7 * np.exp(-0.5 * (s / 2.5) ** 2)
                + 0.4 * np.exp(-0.5 * ((as_ - 5.0) / 1.8) ** 2)) \
        * np.exp(-0.5 * ((b - 12.5) / 3.0) ** 2)
    corners = -3.0 * _gauss(as_ - _MOUTH_HW - 1.0, b, 3.5, 3.0)
    sulcus = -2.5 * _gauss(s, t + 77.0, 16.0, 3.0)
    chin = 7.0 * ident.chin * _gauss(s, t + 88.0, 14.0, 8.0)
    return muzzle + lips + roll + white_roll + philtrum + corners + sulcus + chin


def _lip_squeeze(s, t):
    """Shift in t that closes the slit in 3-D at rest (the lips touch, almost)."""
    b = t - _MOUTH_T
    h = _slit_half_height(s)
    return -np.sign(b) * 0.8 * h * np.exp(-0.5 * (b / 1.5) ** 2)


def _face_relief(s, t, ident):
    """Brows, glabella, cheekbones, cheeks, nasolabial folds, temples, jaw, ears."""
    as_ = np.abs(s)
    brow = 5.0 * ident.brow_ridge * _gauss(as_ - 28.0, t - 16.0, 16.0, 5.5)
    glabella = 2.5 * _gauss(s, t - 13.0, 8.0, 6.0)
    nasion = -2.0 * _gauss(s, t - 6.0, 7.0, 4.0)
    cheekbone = 6.0 * ident.cheekbones * _gauss(as_ - 52.0, t + 10.0, 14.0, 10.0)
    cheek = 3.0 * _gauss(as_ - 40.0, t + 38.0, 14.0, 14.0)
    # nasolabial fold: a groove from beside the ala to beside the mouth corner
    p0, p1 = np.array([17.0, -38.0]), np.array([33.0, -68.0])
    d = p1 - p0
    w = np.clip(((as_ - p0[0]) * d[0] + (t - p0[1]) * d[1]) / (d @ d), 0.0, 1.0)
    dist = np.hypot(as_ - p0[0] - w * d[0], t - p0[1] - w * d[1])
    fold = -1.6 * np.exp(-0.5 * (dist / 2.2) ** 2) * np.sin(np.pi * w) ** 0.5
    temple = -4.0 * _gauss(as_ - 70.0, t - 22.0, 12.0, 14.0)
    jaw = 4.0 * ident.jaw_width * _gauss(as_ - 95.0, t + 58.0, 16.0, 10.0)
    ear = _ear_relief(as_, t)
    return brow + glabella + nasion + cheekbone + cheek + fold + temple + jaw + ear


def _ear_relief(as_, t):
    """Ears at the sides (evaluated only where they are)."""
    out = np.zeros(np.shape(as_))
    m = as_ > 135.0
    if m.any():
        out[m] = _ear_shape(as_[m], t[m])
    return out


def _ear_shape(as_, t):
    ds, dt = (as_ - 158.0) / 12.0, (t + 6.0) / 27.0
    rho = np.hypot(ds, dt)
    lobe = np.hypot(ds / 0.8, (dt + 0.75) / 0.35)
    body = np.exp(-0.5 * np.minimum(rho, lobe) ** 4)
    concha = -6.0 * np.exp(-0.5 * (np.hypot(ds + 0.2, dt + 0.1) / 0.4) ** 2)
    return body * (11.0 + concha)


# ---------------------------------------------------------------------------------
# Surface and expressions
# ---------------------------------------------------------------------------------
def _surface(s, t, ident: _Identity, closure: float = 0.0) -> np.ndarray:
    """(n, 3) points of the neutral face ``ident`` at ``(s, t)`` (lids ``closure``)."""
    theta, phi = s / _RHO, (t + _lip_squeeze(s, t)) / _RHO
    r = (_base_radius(theta, phi) + _eye_relief(s, t, ident, closure)
         + _nose_relief(s, t, ident) + _mouth_relief(s, t, ident)
         + _face_relief(s, t, ident))
    cphi = np.cos(phi)
    X = np.stack([r * cphi * np.sin(theta), r * np.sin(phi), r * cphi * np.cos(theta)],
                 axis=-1)
    # identity warps that move features sideways/down (smooth, small)
    dx = (ident.eye_spacing * _odd_gauss(s, _EYE_S, t - _EYE_T, 20.0, 16.0)
          + ident.nose_width * _odd_gauss(s, 12.0, t + 37.0, 8.0, 7.0)
          + ident.mouth_width * np.clip(s / _MOUTH_HW, -1.5, 1.5)
          * _gauss(s, t - _MOUTH_T, 30.0, 12.0))
    dy = -ident.nose_length * _gauss(s, t + 30.0, 12.0, 12.0)
    X[:, 0] += dx
    X[:, 1] += dy
    # wider/narrower lower face
    lower = _smoothstep((-20.0 - t) / 50.0)
    X[:, 0] *= 1.0 + 0.12 * (ident.jaw_width - 1.0) * lower
    return X * _scale(ident)


def _jaw_weight(s, t):
    """How much each point follows the jaw: 1 on the chin, 0 above the mouth.

    Below the mouth line the weight rises from ``g(s)`` at the lower lip (the
    opening's profile, 0 at the corners) to 1 within about 15 mm; beside the mouth the
    line climbs to the jaw hinge and the rise widens.  The weight jumps only across
    the mouth slit, which is cut out of the domain.
    """
    as_ = np.abs(s)
    out = np.maximum(as_ - _MOUTH_HW, 0.0)
    line = _MOUTH_T + 45.0 * _smoothstep(out / 110.0)
    width = 11.0 + 0.5 * out
    x = np.clip(as_ / _MOUTH_HW, 0.0, 1.0)
    g = 1.0 - x * x
    below = np.clip(line - t, 0.0, None)
    return np.where(t < line, 1.0 - (1.0 - g) * np.exp(-(below / width) ** 2), 0.0)


def _rot_x(P, angle, centre):
    c, sn = np.cos(angle), np.sin(angle)
    q = P - centre
    y = q[:, 1] * c - q[:, 2] * sn
    z = q[:, 1] * sn + q[:, 2] * c
    return np.stack([q[:, 0], y, z], axis=1) + centre


def _scale(ident):
    return np.array([ident.width, ident.height, ident.depth])


def _jaw_open(s, t, ident, X0):
    """Lower lip, chin and jaw turn down about the hinge (and slide forward)."""
    w = _jaw_weight(s, t)
    D = np.zeros_like(X0)
    m = w > 0
    D[m] = (_rot_x(X0[m], _JAW_ANGLE * w[m], _JAW_AXIS * _scale(ident)) - X0[m]
            + w[m, None] * _JAW_SLIDE)
    return D


def _blink(s, t, ident, X0):
    """Upper lids down to the lower ones: the shut-eye surface at remapped points."""
    return _surface(s, _blink_remap(s, t), ident, closure=1.0) - X0


def _smile(s, t, ident, X0):
    """Mouth corners up, out and back; cheeks and lower lids up."""
    corner = _gauss(np.abs(s) - _MOUTH_HW, t - _MOUTH_T, 10.0, 8.0)
    cheek = _gauss(np.abs(s) - 38.0, t + 30.0, 14.0, 12.0)
    # the eye region rises as a whole (a squint would fold a shut eye)
    a, b = _eye_local(s, t)
    lid = (np.exp(-0.5 * (a / 12.0) ** 2) * _smoothstep((b + 14.0) / 6.0)
           * (1.0 - _smoothstep((b - 8.0) / 8.0)))
    out = (2.5 * _odd_gauss(s, _MOUTH_HW, t - _MOUTH_T, 10.0, 8.0)
           + 1.0 * _odd_gauss(s, 38.0, t + 30.0, 14.0, 12.0))
    D = np.stack([out, 6.5 * corner + 4.0 * cheek + 1.5 * lid,
                  -3.5 * corner + 2.5 * cheek + 0.5 * lid], axis=1)
    return D * _scale(ident)


def _brow_raise(s, t, ident, X0):
    """Brows and forehead up; horizontal forehead folds."""
    band = (_smoothstep((t - 5.0) / 10.0) * (1.0 - _smoothstep((t - 45.0) / 35.0))
            * np.exp(-0.5 * (s / 55.0) ** 4))
    forehead = (_smoothstep((t - 28.0) / 6.0) * (1.0 - _smoothstep((t - 55.0) / 10.0))
                * np.exp(-0.5 * (s / 40.0) ** 4))
    folds = 0.5 * forehead * np.sin(2.0 * np.pi * (t - 28.0) / 9.0)
    return np.stack([np.zeros_like(s), 8.0 * band, folds], axis=1) * _scale(ident)


def _pucker(s, t, ident, X0):
    """Lips forward and narrowed (both lips alike, so the slit stays closed)."""
    g = _gauss(s, t - _MOUTH_T, 19.0, 9.0)
    return np.stack([-0.5 * s * g, np.zeros_like(s), 8.0 * g], axis=1) * _scale(ident)


_OFFSETS = {"jaw_open": _jaw_open, "smile": _smile, "blink": _blink,
            "brow_raise": _brow_raise, "pucker": _pucker}


def _offsets(s, t, ident, X0, names) -> dict[str, np.ndarray]:
    """Displacement field ``D_k`` (n, 3) of each expression in ``names`` at
    ``(s, t)``, given the neutral points ``X0`` there."""
    return {name: _OFFSETS[name](s, t, ident, X0) for name in names}


def _posed(s, t, ident, weights) -> np.ndarray:
    """(n, 3) points of face ``ident`` with expression ``weights`` at ``(s, t)``."""
    X0 = _surface(s, t, ident)
    active = [k for k in EXPRESSIONS if weights.get(k, 0.0) != 0.0]
    X = X0.copy()
    for name, D in _offsets(s, t, ident, X0, active).items():
        X += weights[name] * D
    return X


def _check_weights(weights) -> dict[str, float]:
    if weights is None:
        return dict(_DEFAULT_WEIGHTS)
    out = {}
    for k, w in dict(weights).items():
        if k not in EXPRESSIONS:
            raise ValueError(f"weights: unknown expression {k!r}; expected one of "
                             f"{', '.join(EXPRESSIONS)}")
        w = float(w)
        if not (0.0 <= w <= 1.0):
            raise ValueError(f"weights[{k!r}] must lie in [0, 1], got {w}")
        out[k] = w
    return out


# ---------------------------------------------------------------------------------
# Template
# ---------------------------------------------------------------------------------
def _relative_spacing_s(s):
    """Grid/sample spacing along ``s`` relative to the face centre."""
    x = np.abs(s)
    ears = np.exp(-0.5 * ((x - 158.0) / 14.0) ** 2)
    return (0.85 + 0.15 * _smoothstep((x - 30.0) / 30.0)
            + 1.2 * _smoothstep((x - 60.0) / 70.0) - 0.9 * ears)


def _relative_spacing_t(t):
    """Grid/sample spacing along ``t``: finer at the eyes and mouth, coarser on top."""
    fine = 0.42 * np.exp(-0.5 * ((t - _EYE_T - 2.0) / 8.0) ** 2) \
        + 0.3 * np.exp(-0.5 * ((t - _MOUTH_T) / 9.0) ** 2)
    return 1.0 - fine + 1.5 * _smoothstep((t - 55.0) / 60.0) \
        + 0.6 * _smoothstep((-95.0 - t) / 20.0)


def _cumulative_density(lo, hi, rel, n=4001):
    x = np.linspace(lo, hi, n)
    dens = 1.0 / rel(x)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(x))])
    return x, cum


def _grid_lines(anchors, rel, h0) -> np.ndarray:
    """Grid coordinates with local spacing ``h0 * rel(x)``, exact at ``anchors``."""
    out = [np.array([anchors[0]])]
    for a, b in zip(anchors[:-1], anchors[1:]):
        x, cum = _cumulative_density(a, b, rel)
        n = max(1, int(round(cum[-1] / h0)))
        out.append(np.interp(np.linspace(0.0, cum[-1], n + 1), cum, x)[1:])
    lines = np.concatenate(out)
    lines[[0, -1]] = anchors[0], anchors[-1]
    return lines


def _landmark_layout() -> tuple[np.ndarray, np.ndarray]:
    """(68, 2) (s, t) of the landmarks and (68,) kind: 0 nearest vertex, 1 vertex
    snapped onto the exact point (eye corners), 2/3 nearest on the upper/lower edge of
    the mouth slit, 4/5 nearest on the upper/lower lid margin."""
    pts, kind = [], []
    # jaw contour, subject's right (image left) to subject's left
    psi = np.pi * (np.arange(17) / 16.0 - 0.5)
    js = 74.0 * np.sign(psi) * np.abs(np.sin(psi)) ** 0.85
    jt = -6.0 - 92.0 * np.abs(np.cos(psi)) ** 1.3
    pts += list(zip(js, jt))
    kind += [0] * 17

    def brow_t(x):
        return 15.0 + 4.5 * np.exp(-((x - 33.0) / 14.0) ** 2)
    for x in (50.0, 42.0, 33.0, 24.0, 15.0):          # 17-21: subject's right
        pts.append((-x, brow_t(x)))
    for x in (15.0, 24.0, 33.0, 42.0, 50.0):          # 22-26: subject's left
        pts.append((x, brow_t(x)))
    kind += [0] * 10
    pts += [(0.0, 5.0), (0.0, -7.0), (0.0, -18.0), (0.0, -29.0)]
    pts += [(-11.0, -39.5), (-5.5, -42.0), (0.0, -43.5), (5.5, -42.0), (11.0, -39.5)]
    kind += [0] * 9

    def eye(side, seq):
        out = []
        for a, which in seq:
            up, lo, _ = _lid_margins(np.array(a))
            b = {"c": 0.0, "u": float(up), "l": float(lo)}[which]
            out.append((side * (_EYE_S + a), _EYE_T + _EYE_TILT * a + b))
        return out
    q = _EYE_HW / 3.0
    pts += eye(-1.0, [(_EYE_HW, "c"), (q, "u"), (-q, "u"), (-_EYE_HW, "c"), (-q, "l"),
                      (q, "l")])
    pts += eye(1.0, [(-_EYE_HW, "c"), (-q, "u"), (q, "u"), (_EYE_HW, "c"), (q, "l"),
                     (-q, "l")])
    kind += [1, 4, 4, 1, 5, 5] * 2
    m = _MOUTH_T
    pts += [(-_MOUTH_HW - 2.0, m), (-15.0, m + 6.5), (-5.5, m + 9.0), (0.0, m + 8.3),
            (5.5, m + 9.0), (15.0, m + 6.5), (_MOUTH_HW + 2.0, m), (15.0, m - 7.5),
            (6.0, m - 9.5), (0.0, m - 10.0), (-6.0, m - 9.5), (-15.0, m - 7.5)]
    kind += [0] * 12
    pts += [(-_MOUTH_HW, m), (-10.0, m), (0.0, m), (10.0, m), (_MOUTH_HW, m),
            (10.0, m), (0.0, m), (-10.0, m)]
    kind += [0, 2, 2, 2, 0, 3, 3, 3]
    return np.asarray(pts, dtype=np.float64), np.asarray(kind)


def _face_grid(resolution):
    """Structured quad grid over the domain, cut along the mouth slit.

    Returns (s, t) per vertex, (m, 4) quads, and the ids of the upper and lower slit
    edges (the two corners are shared by both).
    """
    h0 = _SPACING / resolution
    sl = _grid_lines(np.array([_S0, -_MOUTH_HW, 0.0, _MOUTH_HW, _S1]),
                     _relative_spacing_s, h0)
    tl = _grid_lines(np.array([_T0, _MOUTH_T, _T1]), _relative_spacing_t, h0)
    ns, nt = len(sl), len(tl)
    S, T = np.meshgrid(sl, tl, indexing="xy")          # (nt, ns)
    ids = np.arange(nt * ns).reshape(nt, ns)
    jm = int(np.flatnonzero(tl == _MOUTH_T)[0])
    cols = np.flatnonzero(np.abs(sl) < _MOUTH_HW)      # slit columns, corners excluded
    # the grid row on the mouth line is the upper lip; a copy of it is the lower lip
    lower_ids = ids[jm].copy()
    lower_ids[cols] = nt * ns + np.arange(len(cols))
    s = np.concatenate([S.ravel(), sl[cols]])
    t = np.concatenate([T.ravel(), np.full(len(cols), _MOUTH_T)])
    up = ids[jm, cols]
    t[up] += _slit_half_height(s[up])
    t[nt * ns:] -= _slit_half_height(s[nt * ns:])
    bottom, top = ids[:-1], ids[1:].copy()
    top[jm - 1] = lower_ids                            # the band under the mouth line
    quads = np.stack([bottom[:, :-1], bottom[:, 1:], top[:, 1:], top[:, :-1]],
                     axis=-1).reshape(-1, 4)
    edge = np.abs(sl) <= _MOUTH_HW
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
    a, b = _eye_local(s, t)
    up, lo, _ = _lid_margins(a)
    column = np.unique(s, return_inverse=True)[1]
    cand = np.flatnonzero(np.abs(a) < 0.85 * _EYE_HW)
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
    :func:`_landmark_layout`); eye corners then move that vertex exactly onto the
    corner (less than half a grid cell).
    """
    target, kind = _landmark_layout()
    st = np.stack([s, t], axis=1)
    trees = {k: cKDTree(st[v]) for k, v in pools.items()}
    chosen: set[int] = set()
    # the landmarks with few candidates first
    order = np.argsort(np.where(kind == 0, 1, 0), kind="stable")
    picked = np.empty(len(target), dtype=np.int64)
    for i in order.tolist():
        k = int(kind[i])
        _, cand = trees[k].query(target[i], k=min(8, len(pools[k])))
        free = [j for j in pools[k][np.atleast_1d(cand)].tolist() if j not in chosen]
        picked[i] = free[0]
        chosen.add(free[0])
    s, t = s.copy(), t.copy()
    snap = kind == 1
    s[picked[snap]], t[picked[snap]] = target[snap, 0], target[snap, 1]
    return picked, s, t


def _eyeball(ident, side, n_lon, n_lat):
    """Eyeball sphere behind the eye dome of ``side`` (+1 left, -1 right)."""
    s_c = np.array([side * _EYE_S])
    apex = _surface(s_c, np.array([_EYE_T]), ident)[0]
    direction = apex / np.linalg.norm(apex)
    radius = 11.0
    centre = apex - (radius + 1.2) * direction
    V, faces, uvs, face_uvs = _uv_sphere(n_lon, n_lat)
    return centre + radius * V, faces, uvs, face_uvs


def _check_resolution(resolution, name="resolution", low=8) -> int:
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


def make_template(resolution: int = 64) -> SampleTemplate:
    """The built-in template head: the default face, with blendshapes.

    Parameters
    ----------
    resolution : int, default 64
        Grid cells across the face (about ``200 / resolution`` mm apart at the face
        centre, finer at the eyes and mouth, coarser toward the back and top).  The
        default gives about 7,400 vertices (in 0.05 s).

    Returns
    -------
    SampleTemplate

    Raises
    ------
    ValueError
        If ``resolution`` is not an int >= 8.

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
    resolution = _check_resolution(resolution)
    s, t, quads, upper_edge, lower_edge = _face_grid(resolution)
    t, lid_up, lid_lo = _snap_lid_margins(s, t)
    every = np.arange(len(s))
    lm, s, t = _pick_landmarks(s, t, {0: every, 1: every, 2: upper_edge, 3: lower_edge,
                                      4: lid_up, 5: lid_lo})
    ident = _identity(0)
    X0 = _surface(s, t, ident)
    D = _offsets(s, t, ident, X0, EXPRESSIONS)
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
    uvs = np.concatenate([_uv_from_st(s, t), euv])
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
    params[:n_face] = _uv_from_st(s, t)
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


# ---------------------------------------------------------------------------------
# Scan
# ---------------------------------------------------------------------------------
def _stream(seed: int, purpose: int) -> np.random.Generator:
    """An independent random stream per purpose, so that e.g. ``noise=0`` and
    ``noise=0.2`` with one seed give the same topology and transform."""
    return np.random.default_rng([int(seed), purpose])


def _jittered_samples(h, rng) -> tuple[np.ndarray, np.ndarray]:
    """Irregular samples of the whole domain, denser at the face (spacing ~h there),
    with points along the domain boundary so that the samples cover it all.

    Returns s, t and a mask of the boundary points."""
    axes = []
    for lo, hi, rel in ((_S0, _S1, _relative_spacing_s), (_T0, _T1, _relative_spacing_t)):
        x, cum = _cumulative_density(lo, hi, rel)
        axes.append((x, cum, max(2, int(math.ceil(cum[-1] / h)))))
    (xs, cs, ns), (xt, ct, nt) = axes
    i, j = np.meshgrid(np.arange(ns), np.arange(nt), indexing="xy")
    ju = rng.uniform(-0.35, 0.35, size=(2,) + i.shape)
    s = np.interp((i.ravel() + 0.5 + ju[0].ravel()) / ns * cs[-1], cs, xs)
    t = np.interp((j.ravel() + 0.5 + ju[1].ravel()) / nt * ct[-1], ct, xt)
    es = np.interp(np.linspace(0.0, cs[-1], ns + 1), cs, xs)
    et = np.interp(np.linspace(0.0, ct[-1], nt + 1), ct, xt)
    bs = np.concatenate([es, es, np.full(nt - 1, _S0), np.full(nt - 1, _S1)])
    bt = np.concatenate([np.full(ns + 1, _T0), np.full(ns + 1, _T1), et[1:-1], et[1:-1]])
    border = np.concatenate([np.zeros(len(s), bool), np.ones(len(bs), bool)])
    return np.concatenate([s, bs]), np.concatenate([t, bt]), border


def _keep_probability(s, t, weights):
    """Chance that a scanner sample survives at ``(s, t)``: a shut eye squeezes its
    opening to a thin strip, where a scanner sees few points (the posed/neutral area
    ratio there); 1 elsewhere."""
    w = weights.get("blink", 0.0)
    if w == 0.0:
        return np.ones_like(s)
    a, b = _eye_local(s, t)
    up, lo, _ = _lid_margins(a)
    inside = (b > lo) & (b < up) & (np.abs(a) < _EYE_HW)
    return np.where(inside, 1.0 - w * (1.0 - _BLINK_GAP), 1.0)


def _slit_edge_points(h):
    """Points along both lips of the mouth slit (corners once), about ``h/2`` apart."""
    n = max(4, int(math.ceil(2 * _MOUTH_HW / (0.5 * h))))
    s = np.linspace(-_MOUTH_HW, _MOUTH_HW, n + 1)[1:-1]
    hh = _slit_half_height(s)
    return (np.concatenate([s, s, [-_MOUTH_HW, _MOUTH_HW]]),
            np.concatenate([_MOUTH_T + hh, _MOUTH_T - hh, [_MOUTH_T, _MOUTH_T]]))


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
    keep = ~_in_slit(c[:, 0], c[:, 1])
    # no edge may cross the mouth line between the corners
    for a, b in ((0, 1), (1, 2), (2, 0)):
        pa, pb = st[T[:, a]], st[T[:, b]]
        da, db = pa[:, 1] - _MOUTH_T, pb[:, 1] - _MOUTH_T
        cross = da * db < 0
        w = np.divide(da, da - db, out=np.zeros_like(da), where=cross)
        sc = pa[:, 0] + w * (pb[:, 0] - pa[:, 0])
        keep &= ~(cross & (np.abs(sc) < _MOUTH_HW))
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
    local = h * _relative_spacing_s(s) * _relative_spacing_t(t)
    keep &= ~((np.abs(s) < _MOUTH_HW + 0.3 * local)
              & (np.abs(t - _MOUTH_T) < _slit_half_height(s) + 0.4 * local))
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
    landmarks, _ = _landmark_layout()
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


def _check_transform(transform, seed) -> np.ndarray:
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
    weights = _check_weights(weights)
    resolution = _check_resolution(resolution)
    texture_size = _check_resolution(texture_size, "texture_size", low=1)
    holes = _check_resolution(holes, "holes", low=0)
    for name, value in (("noise", noise), ("hole_radius", hole_radius),
                        ("landmark_noise", landmark_noise)):
        if not (np.isfinite(value) and value >= 0):
            raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    M = _check_transform(transform, seed)
    ident = _identity(identity_seed)

    # 1. irregular samples of the domain (and the slit's lips), triangulated
    s, t, eta, T = _scan_topology(_SPACING / resolution, seed, weights, crop)
    # 2. the posed face, with holes
    X = _posed(s, t, ident, weights)
    if holes:
        centres = _hole_centres(holes, hole_radius, _stream(seed, 3))
        C = _posed(centres[:, 0], centres[:, 1], ident, weights)
        d = np.min(np.linalg.norm(X[:, None, :] - C[None, :, :], axis=2), axis=1)
        T, used = _compact(T[(d[T] >= hole_radius).all(axis=1)], len(s))
        s, t, X, eta = s[used], t[used], X[used], eta[used]
    # 3. sensor noise along the normal, rigid motion
    if noise > 0:
        X = X + noise * eta[:, None] * vertex_normals(X, T)
    X = _apply(M, X)

    # 4. truth: template vertices on this face, landmarks
    face = template.parts["face"]
    ts, tt = _st_from_uv(template.params[face])
    truth = np.full((template.mesh.n_vertices, 3), np.nan)
    truth[face] = _apply(M, _posed(ts, tt, ident, weights))
    points = truth[template.landmarks.vertex]
    if landmark_noise > 0:
        points = points + landmark_noise * _stream(seed, 6).standard_normal(points.shape)
    truth.setflags(write=False)
    M.setflags(write=False)
    tex = _texture(texture_size, ident, _stream(identity_seed, 7),
                   eyes_open=1.0 - weights.get("blink", 0.0))
    tex.setflags(write=False)
    mesh = Mesh(X, T, uvs=_uv_from_st(s, t))
    return SampleScan(mesh=mesh, texture=tex,
                      landmarks=Landmarks.from_points(points, LANDMARK_NAMES),
                      ground_truth=truth, transform=M, weights=weights)


# ---------------------------------------------------------------------------------
# Texture
# ---------------------------------------------------------------------------------
def _smooth_noise(rng, size, cells, order=3):
    """(size, size) smooth random field with about ``cells`` blobs across, std ~1."""
    from scipy.ndimage import zoom

    coarse = rng.standard_normal((cells + 3, cells + 3))
    fine = zoom(coarse, size / cells, order=order, mode="grid-wrap")
    return fine[:size, :size]


def _texture(size, ident, rng, eyes_open=1.0) -> np.ndarray:
    """(size, size, 3) uint8 albedo over the parameter domain (row 0 at ``v = 1``);
    the eyeball shows in the eye openings in proportion to ``eyes_open``."""
    c = (np.arange(size) + 0.5) / size
    s, t = _st_from_uv(np.stack(np.meshgrid(c, c[::-1], indexing="xy"), axis=-1))
    tone = np.clip(ident.skin, -1.0, 1.0)
    skin = np.array([0.87, 0.67, 0.55]) * (1.0 + 0.12 * tone)
    img = np.broadcast_to(skin, (size, size, 3)).copy()
    img *= (1.0 + 0.035 * _smooth_noise(rng, size, 10))[..., None]
    as_ = np.abs(s)

    def mix(colour, alpha):
        nonlocal img
        alpha = np.clip(alpha, 0.0, 1.0)[..., None]
        img = img * (1.0 - alpha) + np.asarray(colour) * alpha

    mix([0.85, 0.5, 0.47], 0.22 * _gauss(as_ - 42.0, t + 28.0, 15.0, 11.0))
    # hair above the hairline and at the temples
    hairline = 66.0 - 76.0 * _smoothstep((as_ - 60.0) / 90.0)
    strands = 0.8 + 0.2 * _smooth_noise(rng, size, size // 6 or 1, order=1)
    ears = _ear_relief(as_, t) > 1.0
    mix(np.array([0.24, 0.17, 0.13]) * strands[..., None],
        _smoothstep((t - hairline) / 4.0) * ~ears)
    # brows
    centre = 15.5 + 4.5 * np.exp(-((as_ - 33.0) / 14.0) ** 2)
    half = 3.0 - 1.8 * _smoothstep((as_ - 15.0) / 38.0)
    ends = _smoothstep((as_ - 10.0) / 4.0) * (1.0 - _smoothstep((as_ - 52.0) / 5.0))
    brow = _smoothstep((half - np.abs(t - centre)) / 1.2) * ends
    mix(np.array([0.3, 0.21, 0.16]) * strands[..., None], 0.9 * brow)
    # lips
    b = t - _MOUTH_T
    eu, el = _lip_extent(s)
    lip = (_smoothstep((eu - b) / 1.2 + 0.5) * _smoothstep((b + el) / 1.2 + 0.5)
           * (as_ < _MOUTH_HW + 1.0))
    mix([0.72, 0.36, 0.36], 0.85 * lip)
    # nostrils
    mix([0.35, 0.2, 0.18], _smoothstep(1.0 - np.hypot((as_ - 6.0) / 2.6, (t + 41.0) / 1.7)))
    # eyes: white, iris and pupil inside the opening, lashes along the margins
    a, be = _eye_local(s, t)
    opening = _eye_opening(a, be, 0.0)
    r = np.hypot(a, be + 0.5)
    iris = np.array([0.38, 0.26, 0.16]) if ident.skin < 0.3 else np.array([0.3, 0.45, 0.6])
    eye = np.where((r < 5.4)[..., None], iris * (0.75 + 0.25 * (r / 5.4))[..., None],
                   np.array([0.93, 0.9, 0.87]))
    eye = np.where((r < 2.3)[..., None], np.array([0.05, 0.05, 0.06]), eye)
    mix(eye, opening * eyes_open)
    up, lo, _ = _lid_margins(a)
    env = (np.abs(a) < _EYE_HW + 1.0)
    mix([0.12, 0.09, 0.08], 0.9 * env * _smoothstep(1.0 - np.abs(be - up - 0.3) / 0.9))
    mix([0.2, 0.14, 0.12], 0.5 * env * _smoothstep(1.0 - np.abs(be - lo + 0.2) / 0.6))
    img *= (1.0 + 0.03 * rng.standard_normal((size, size)))[..., None]     # pores
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)


# ---------------------------------------------------------------------------------
# Sequences and files
# ---------------------------------------------------------------------------------
def make_sequence(template: SampleTemplate | None = None, frames: int = 10,
                  peak: dict[str, float] | None = None, **scan_kwargs) -> list[SampleScan]:
    """An expression ramp from neutral to ``peak``, one scan per frame (4-D capture).

    Frame ``f`` of ``frames`` has weights ``peak * f / (frames - 1)`` and is sampled
    with seed ``seed + f``, so every frame has its own topology.  The head pose is
    the same in every frame (``transform=True`` is drawn once, from ``seed``).

    Parameters
    ----------
    template : SampleTemplate, optional
        Default ``make_template()``.
    frames : int, default 10
        Number of scans, >= 2.
    peak : dict of str to float, optional
        Weights of the last frame (default: :func:`make_scan`'s default).
    **scan_kwargs
        Passed to :func:`make_scan` (``identity_seed``, ``resolution``, ``noise``,
        ``seed``...); not ``weights``.

    Returns
    -------
    list of SampleScan

    Examples
    --------
    >>> seq = make_sequence(make_template(24), frames=3, peak={"smile": 1.0},
    ...                     resolution=24, texture_size=8)
    >>> [s.weights["smile"] for s in seq]
    [0.0, 0.5, 1.0]
    >>> len({s.mesh.n_vertices for s in seq}) > 1
    True
    """
    if "weights" in scan_kwargs:
        raise ValueError("make_sequence: give the last frame's weights as peak=, "
                         "not weights=")
    frames = _check_resolution(frames, "frames", low=2)
    peak = _check_weights(peak)
    template = make_template() if template is None else template
    seed = int(scan_kwargs.pop("seed", 0))
    transform = _check_transform(scan_kwargs.pop("transform", True), seed)
    out = []
    for f in range(frames):
        k = f / (frames - 1)
        w = {name: value * k for name, value in peak.items()}
        out.append(make_scan(template, weights=w, seed=seed + f, transform=transform,
                             **scan_kwargs))
    return out


_MTL = "newmtl skin\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\nmap_Kd scan_texture.png\n"


def write_sample(folder, template: SampleTemplate | None = None,
                 scan: SampleScan | None = None) -> dict[str, Path]:
    """Write the sample as plain files that any tool (or the CLI) can read.

    Files: ``template.obj``, ``template_landmarks.txt`` (0-based vertex ids, one per
    line), ``blendshapes/<name>.obj``, ``scan.obj`` (``mtllib scan.mtl``, UVs),
    ``scan.mtl`` and ``scan_texture.png``, ``scan_landmarks.txt`` (``x y z`` lines,
    in :data:`LANDMARK_NAMES` order) and ``ground_truth.npy`` ((n_template, 3),
    NaN for the eyeballs).  Each file is replaced atomically.

    Parameters
    ----------
    folder : str or os.PathLike
        Created if missing.
    template : SampleTemplate, optional
        Default ``make_template()``.
    scan : SampleScan, optional
        Default ``make_scan(template)``.

    Returns
    -------
    dict of str to Path
        ``"template"``, ``"template_landmarks"``, ``"blendshapes/<name>"`` for each
        expression, ``"scan"``, ``"scan_mtl"``, ``"scan_texture"``,
        ``"scan_landmarks"``, ``"ground_truth"``.

    Examples
    --------
    >>> import tempfile
    >>> tpl = make_template(24)
    >>> paths = write_sample(tempfile.mkdtemp(), tpl,
    ...                      make_scan(tpl, resolution=24, texture_size=8))
    >>> paths["scan"].read_text().splitlines()[1]
    'mtllib scan.mtl'
    >>> paths["blendshapes/blink"].relative_to(paths["scan"].parent).as_posix()
    'blendshapes/blink.obj'
    """
    import io

    from PIL import Image

    from facewrap.io.landmarks import write_points, write_vertex_indices
    from facewrap.io.obj import write_obj

    folder = Path(os.fspath(folder))
    (folder / "blendshapes").mkdir(parents=True, exist_ok=True)
    template = make_template() if template is None else template
    scan = make_scan(template) if scan is None else scan
    paths = {"template": folder / "template.obj",
             "template_landmarks": folder / "template_landmarks.txt"}
    write_obj(paths["template"], template.mesh, header="facewrap sample template")
    write_vertex_indices(paths["template_landmarks"], template.landmarks)
    for name, V in template.blendshapes.items():
        paths[f"blendshapes/{name}"] = folder / "blendshapes" / f"{name}.obj"
        write_obj(paths[f"blendshapes/{name}"], template.mesh.with_vertices(V),
                  header=f"facewrap sample blendshape {name}")
    m = scan.mesh
    textured = Mesh(m.vertices, (m.face_offsets, m.face_indices), uvs=m.uvs,
                    mtllib=("scan.mtl",), materials=("skin",),
                    face_materials=np.zeros(m.n_faces, dtype=np.int64))
    paths.update(scan=folder / "scan.obj", scan_mtl=folder / "scan.mtl",
                 scan_texture=folder / "scan_texture.png",
                 scan_landmarks=folder / "scan_landmarks.txt",
                 ground_truth=folder / "ground_truth.npy")
    write_obj(paths["scan"], textured, header="facewrap sample scan")
    with atomic_write(paths["scan_mtl"], "w", encoding="utf-8", newline="\n") as fh:
        fh.write(_MTL)
    png = io.BytesIO()
    Image.fromarray(np.asarray(scan.texture, dtype=np.uint8), "RGB").save(png, "PNG")
    with atomic_write(paths["scan_texture"], "wb") as fh:
        fh.write(png.getvalue())
    write_points(paths["scan_landmarks"], scan.landmarks.points)
    with atomic_write(paths["ground_truth"], "wb") as fh:
        np.save(fh, np.asarray(scan.ground_truth))
    return paths
