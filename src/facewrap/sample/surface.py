"""The parametric sample head ``S(s, t; identity, expression)`` and its expressions.

Units are millimetres; +y is up, +z points out of the face (the face looks toward
+z) and +x is the subject's left.  The radius about the head centre, a function of
the domain point ``(s, t)`` (:mod:`facewrap.sample.layout`), is a smooth base (front
and side profiles blended by a super-ellipse) plus Gaussian and smoothstep features:
forehead, brow ridge, eye sockets with an eyeball dome and upper/lower lids, nose
(bridge, tip, alae, nostrils), cheekbones, lips, chin, jaw and ears.

Expressions are displacement fields on the domain (:data:`EXPRESSIONS`), combined
linearly like blendshapes: ``x = S(p) + sum_k w_k D_k(p)`` with weights in [0, 1].
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator

from facewrap.sample.identity import Identity
from facewrap.sample.layout import (BLINK_GAP, EYE_HALF_WIDTH, EYE_RADIUS, EYE_S, EYE_T,
                                    MM_PER_RADIAN, MOUTH_HALF_WIDTH, MOUTH_T, eye_local,
                                    eye_opening, gaussian, lid_margins, lip_extent,
                                    slit_half_height, smoothstep)

__all__ = ["EXPRESSIONS", "ear_relief", "head_surface", "expression_offsets",
           "posed_surface", "checked_weights"]

#: Expression (blendshape) names, in the order of :attr:`SampleTemplate.blendshapes`.
EXPRESSIONS: tuple[str, ...] = ("jaw_open", "smile", "blink", "brow_raise", "pucker")

_DEFAULT_WEIGHTS = {"jaw_open": 0.8, "blink": 1.0, "smile": 0.3}
_JAW_AXIS = np.array([0.0, -18.0, 8.0])   # a point on the jaw hinge (x axis)
_JAW_ANGLE = 0.28                         # radians at full jaw_open
_JAW_SLIDE = np.array([0.0, -4.0, 10.0])   # the condyles glide forward as the jaw opens


def _odd_gauss(s, c, dt, sx, sy):
    """Smooth odd pair of bumps at ``s = +-c``: +1 near ``+c``, -1 near ``-c``."""
    return gaussian(s - c, dt, sx, sy) - gaussian(s + c, dt, sx, sy)


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
    p = 2.0 + (_SUPER - 2.0) * (1.0 - smoothstep((phi - 0.4) / 0.6))   # round on top
    return ((c / rf) ** p + (sn / rs) ** p) ** (-1.0 / p)


def _blink_remap(s, t):
    """Where each domain point sits on the shut eye (``t`` changed near the eyes).

    The opening shrinks to ``BLINK_GAP`` of its height at the lower margin and the
    upper lid (margin to crease) stretches down over it; monotone, so the surface
    stays valid.
    """
    a, b = eye_local(s, t)
    up, lo, crease = lid_margins(a)
    up_c = lo + BLINK_GAP * (up - lo)
    inside = (b > lo) & (b < up)
    lid = (b >= up) & (b < crease)
    new_b = b.copy()
    h = np.maximum(up - lo, 1e-12)
    new_b[inside] = (lo + (b - lo) * (up_c - lo) / h)[inside]
    hl = np.maximum(crease - up, 1e-12)
    new_b[lid] = (up_c + (b - up) * (crease - up_c) / hl)[lid]
    return t + (new_b - b)


def _eye_relief(s, t, ident, closure):
    """Socket, eyeball bulge, lid margins and the upper-lid crease."""
    a, b = eye_local(s, t)
    up, lo, crease = lid_margins(a)
    socket = -14.0 * gaussian(a + 1.0, b - 1.0, 16.0, 13.0)
    rho2 = (a / 1.2) ** 2 + (b / 1.05) ** 2
    bulge = 9.0 * (1.0 - smoothstep(rho2 / EYE_RADIUS ** 2))
    env = np.clip(1.0 - (a / (EYE_HALF_WIDTH + 2.0)) ** 2, 0.0, 1.0)
    lid_up = 2.0 * env * np.exp(-0.5 * np.clip(b - up, 0.0, None) ** 2 / 3.0 ** 2)
    lid_lo = 0.9 * env * np.exp(-0.5 * np.clip(lo - b, 0.0, None) ** 2 / 2.0 ** 2)
    upper = smoothstep((b - 0.5 * (up + lo)) / 3.0 + 0.5)
    lids = (lid_lo + (lid_up - lid_lo) * upper) * (1.0 - eye_opening(a, b, closure))
    fold = -1.4 * env * np.exp(-0.5 * ((b - crease) / 2.0) ** 2)
    return socket + bulge + lids + fold


def _nose_relief(s, t, ident):
    """Bridge, tip, alae and nostrils."""
    p = ident.nose_projection
    as_ = np.abs(s)
    # dorsum: rises from the nasion to the tip, then turns under to the columella
    x = np.clip((6.0 - t) / 35.0, 0.0, 1.0)
    height = (1.5 + 19.0 * x ** 1.25) * (1.0 - smoothstep((t - 6.0) / 9.0))
    height = height * (1.0 - smoothstep((-29.0 - t) / 12.0))
    width = 5.0 + 4.0 * x ** 1.5
    dorsum = height * np.exp(-0.5 * (as_ / width) ** 2.4)
    tip = 4.0 * gaussian(s, t + 28.5, 6.5, 5.0)
    lobule = 6.0 * gaussian(s, t + 33.0, 7.0, 4.5) * (1.0 - smoothstep((-37.0 - t) / 5.0))
    alae = 7.0 * gaussian(as_ - 11.5, t + 36.0, 4.0, 4.0)
    ring = np.hypot(as_ - 11.5, (t + 36.0) / 0.9)
    alar_crease = (-0.8 * np.exp(-0.5 * (ring - 5.5) ** 2)
                   * smoothstep((t + 42.0) / 3.0))
    nostrils = -1.8 * gaussian(as_ - 6.0, t + 40.5, 2.2, 1.3)
    return p * (dorsum + tip + lobule + alae + nostrils) + alar_crease


def _mouth_relief(s, t, ident):
    """Lips (rolled in at the slit), philtrum, mouth corners, chin."""
    b = t - MOUTH_T
    as_ = np.abs(s)
    full = ident.lip_fullness
    # the dental arch: the mouth region is a forward mound, the corners recede
    muzzle = 7.0 * gaussian(s, b + 4.0, 24.0, 14.0)
    eu, el = lip_extent(s)
    xu = np.clip(b / np.maximum(eu, 1e-3), 0.0, 1.6)
    xl = np.clip(-b / np.maximum(el, 1e-3), 0.0, 1.6)
    upper = np.where(b > 0, np.sin(np.pi * np.minimum(xu, 1.0)) ** 1.3, 0.0)
    lower = np.where(b < 0, np.sin(np.pi * np.minimum(xl, 1.0)) ** 1.3, 0.0)
    width = np.clip(1.0 - (s / (MOUTH_HALF_WIDTH + 1.0)) ** 2, 0.0, 1.0) ** 0.7
    lips = full * width * (3.2 * upper + 3.8 * lower)
    roll = -3.0 * np.exp(-0.5 * (b / 1.2) ** 2) * width
    white_roll = 0.6 * np.exp(-0.5 * ((b - eu) / 0.8) ** 2) * smoothstep(b) * width
    philtrum = (-0.7 * np.exp(-0.5 * (s / 2.5) ** 2)
                + 0.4 * np.exp(-0.5 * ((as_ - 5.0) / 1.8) ** 2)) \
        * np.exp(-0.5 * ((b - 12.5) / 3.0) ** 2)
    corners = -3.0 * gaussian(as_ - MOUTH_HALF_WIDTH - 1.0, b, 3.5, 3.0)
    sulcus = -2.5 * gaussian(s, t + 77.0, 16.0, 3.0)
    chin = 7.0 * ident.chin * gaussian(s, t + 88.0, 14.0, 8.0)
    return muzzle + lips + roll + white_roll + philtrum + corners + sulcus + chin


def _lip_squeeze(s, t):
    """Shift in t that closes the slit in 3-D at rest (the lips touch, almost)."""
    b = t - MOUTH_T
    h = slit_half_height(s)
    return -np.sign(b) * 0.8 * h * np.exp(-0.5 * (b / 1.5) ** 2)


def _face_relief(s, t, ident):
    """Brows, glabella, cheekbones, cheeks, nasolabial folds, temples, jaw, ears."""
    as_ = np.abs(s)
    brow = 5.0 * ident.brow_ridge * gaussian(as_ - 28.0, t - 16.0, 16.0, 5.5)
    glabella = 2.5 * gaussian(s, t - 13.0, 8.0, 6.0)
    nasion = -2.0 * gaussian(s, t - 6.0, 7.0, 4.0)
    cheekbone = 6.0 * ident.cheekbones * gaussian(as_ - 52.0, t + 10.0, 14.0, 10.0)
    cheek = 3.0 * gaussian(as_ - 40.0, t + 38.0, 14.0, 14.0)
    # nasolabial fold: a groove from beside the ala to beside the mouth corner
    p0, p1 = np.array([17.0, -38.0]), np.array([33.0, -68.0])
    d = p1 - p0
    w = np.clip(((as_ - p0[0]) * d[0] + (t - p0[1]) * d[1]) / (d @ d), 0.0, 1.0)
    dist = np.hypot(as_ - p0[0] - w * d[0], t - p0[1] - w * d[1])
    fold = -1.6 * np.exp(-0.5 * (dist / 2.2) ** 2) * np.sin(np.pi * w) ** 0.5
    temple = -4.0 * gaussian(as_ - 70.0, t - 22.0, 12.0, 14.0)
    jaw = 4.0 * ident.jaw_width * gaussian(as_ - 95.0, t + 58.0, 16.0, 10.0)
    ear = ear_relief(as_, t)
    return brow + glabella + nasion + cheekbone + cheek + fold + temple + jaw + ear


def ear_relief(as_, t):
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


def head_surface(s, t, ident: Identity, closure: float = 0.0) -> np.ndarray:
    """(n, 3) points of the neutral face ``ident`` at ``(s, t)`` (lids ``closure``)."""
    theta, phi = s / MM_PER_RADIAN, (t + _lip_squeeze(s, t)) / MM_PER_RADIAN
    r = (_base_radius(theta, phi) + _eye_relief(s, t, ident, closure)
         + _nose_relief(s, t, ident) + _mouth_relief(s, t, ident)
         + _face_relief(s, t, ident))
    cphi = np.cos(phi)
    X = np.stack([r * cphi * np.sin(theta), r * np.sin(phi), r * cphi * np.cos(theta)],
                 axis=-1)
    # identity warps that move features sideways/down (smooth, small)
    dx = (ident.eye_spacing * _odd_gauss(s, EYE_S, t - EYE_T, 20.0, 16.0)
          + ident.nose_width * _odd_gauss(s, 12.0, t + 37.0, 8.0, 7.0)
          + ident.mouth_width * np.clip(s / MOUTH_HALF_WIDTH, -1.5, 1.5)
          * gaussian(s, t - MOUTH_T, 30.0, 12.0))
    dy = -ident.nose_length * gaussian(s, t + 30.0, 12.0, 12.0)
    X[:, 0] += dx
    X[:, 1] += dy
    # wider/narrower lower face
    lower = smoothstep((-20.0 - t) / 50.0)
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
    out = np.maximum(as_ - MOUTH_HALF_WIDTH, 0.0)
    line = MOUTH_T + 45.0 * smoothstep(out / 110.0)
    width = 11.0 + 0.5 * out
    x = np.clip(as_ / MOUTH_HALF_WIDTH, 0.0, 1.0)
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
    return head_surface(s, _blink_remap(s, t), ident, closure=1.0) - X0


def _smile(s, t, ident, X0):
    """Mouth corners up, out and back; cheeks and lower lids up."""
    corner = gaussian(np.abs(s) - MOUTH_HALF_WIDTH, t - MOUTH_T, 10.0, 8.0)
    cheek = gaussian(np.abs(s) - 38.0, t + 30.0, 14.0, 12.0)
    # the eye region rises as a whole (a squint would fold a shut eye)
    a, b = eye_local(s, t)
    lid = (np.exp(-0.5 * (a / 12.0) ** 2) * smoothstep((b + 14.0) / 6.0)
           * (1.0 - smoothstep((b - 8.0) / 8.0)))
    out = (2.5 * _odd_gauss(s, MOUTH_HALF_WIDTH, t - MOUTH_T, 10.0, 8.0)
           + 1.0 * _odd_gauss(s, 38.0, t + 30.0, 14.0, 12.0))
    D = np.stack([out, 6.5 * corner + 4.0 * cheek + 1.5 * lid,
                  -3.5 * corner + 2.5 * cheek + 0.5 * lid], axis=1)
    return D * _scale(ident)


def _brow_raise(s, t, ident, X0):
    """Brows and forehead up; horizontal forehead folds."""
    band = (smoothstep((t - 5.0) / 10.0) * (1.0 - smoothstep((t - 45.0) / 35.0))
            * np.exp(-0.5 * (s / 55.0) ** 4))
    forehead = (smoothstep((t - 28.0) / 6.0) * (1.0 - smoothstep((t - 55.0) / 10.0))
                * np.exp(-0.5 * (s / 40.0) ** 4))
    folds = 0.5 * forehead * np.sin(2.0 * np.pi * (t - 28.0) / 9.0)
    return np.stack([np.zeros_like(s), 8.0 * band, folds], axis=1) * _scale(ident)


def _pucker(s, t, ident, X0):
    """Lips forward and narrowed (both lips alike, so the slit stays closed)."""
    g = gaussian(s, t - MOUTH_T, 19.0, 9.0)
    return np.stack([-0.5 * s * g, np.zeros_like(s), 8.0 * g], axis=1) * _scale(ident)


_OFFSETS = {"jaw_open": _jaw_open, "smile": _smile, "blink": _blink,
            "brow_raise": _brow_raise, "pucker": _pucker}


def expression_offsets(s, t, ident, X0, names) -> dict[str, np.ndarray]:
    """Displacement field ``D_k`` (n, 3) of each expression in ``names`` at
    ``(s, t)``, given the neutral points ``X0`` there."""
    return {name: _OFFSETS[name](s, t, ident, X0) for name in names}


def posed_surface(s, t, ident, weights) -> np.ndarray:
    """(n, 3) points of face ``ident`` with expression ``weights`` at ``(s, t)``."""
    X0 = head_surface(s, t, ident)
    active = [k for k in EXPRESSIONS if weights.get(k, 0.0) != 0.0]
    X = X0.copy()
    for name, D in expression_offsets(s, t, ident, X0, active).items():
        X += weights[name] * D
    return X


def checked_weights(weights) -> dict[str, float]:
    """Expression weights checked (known names, values in [0, 1]); None gives the default."""
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
