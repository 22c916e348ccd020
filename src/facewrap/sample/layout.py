"""The parameter domain of the sample face and where its features lie in it.

Units are millimetres.  The head is a parametric surface over a 2-D domain
(:mod:`facewrap.sample.surface`):

* ``s = 100 * azimuth`` (radians about the vertical axis, 0 at the nose, positive
  toward the subject's left), ``t = 100 * elevation`` (0 at the eye line), both in
  "millimetres at 100 mm radius" (:data:`MM_PER_RADIAN`), so features can be laid
  out in millimetres;
* the normalised parameter ``(u, v) = ((s - S_MIN) / (S_MAX - S_MIN), (t - T_MIN) /
  (T_MAX - T_MIN))`` in ``[0, 1]^2`` (:func:`uv_from_st`, :func:`st_from_uv`) is
  what :attr:`~facewrap.sample.SampleTemplate.params` and the UVs hold.

The layout (eye centres :data:`EYE_S`, :data:`EYE_T`, lid margins, the mouth line
:data:`MOUTH_T` and its slit, the grid density, the landmarks) never changes with
identity, so one parameter point means "the same place" on every face: that is how
:attr:`~facewrap.sample.SampleScan.ground_truth` is defined.  The **mouth slit** is a
thin lens-shaped cut of the domain (``|t - MOUTH_T| < h(s)`` for ``|s| <
MOUTH_HALF_WIDTH``), so the two lips are distinct points of the domain and can part.

Landmarks follow the iBUG-68 order of :data:`LANDMARK_NAMES`.  As in iBUG, "left" and
"right" in the *numbering* are the image's (a frontal photo): points 17-21 (the
``brow_r_*`` names) and 36-41 (``eye_r_*``) lie on the **subject's right** (-x,
image left); the ``r``/``l`` in the names are the subject's sides.
"""

from __future__ import annotations

import math

import numpy as np

from facewrap.landmarks import IBUG68_NAMES

__all__ = ["LANDMARK_NAMES", "MM_PER_RADIAN", "S_MIN", "S_MAX", "T_MIN", "T_MAX",
           "EYE_S", "EYE_T", "EYE_HALF_WIDTH", "BLINK_GAP", "EYE_RADIUS", "MOUTH_T",
           "MOUTH_HALF_WIDTH", "GRID_SPACING", "uv_from_st", "st_from_uv", "smoothstep",
           "gaussian", "slit_half_height", "in_slit", "eye_local", "lid_margins",
           "eye_opening", "lip_extent", "relative_spacing_s", "relative_spacing_t",
           "cumulative_density", "landmark_layout"]

#: The 68 iBUG landmark names in their standard order (see the module docstring for
#: the left/right convention): ``jaw_0..16``, ``brow_r_0..4`` (17-21),
#: ``brow_l_0..4`` (22-26), ``nose_bridge_0..3`` (27-30), ``nose_base_0..4``
#: (31-35), ``eye_r_0..5`` (36-41), ``eye_l_0..5`` (42-47), ``mouth_outer_0..11``
#: (48-59), ``mouth_inner_0..7`` (60-67).
LANDMARK_NAMES: tuple[str, ...] = IBUG68_NAMES

#: Millimetres of ``(s, t)`` per radian of azimuth / elevation.
MM_PER_RADIAN = 100.0
#: The domain: ``S_MIN <= s <= S_MAX``, ``T_MIN <= t <= T_MAX`` (mm).
S_MIN, S_MAX = -MM_PER_RADIAN * math.radians(105.0), MM_PER_RADIAN * math.radians(105.0)
T_MIN, T_MAX = MM_PER_RADIAN * math.radians(-68.0), MM_PER_RADIAN * math.radians(72.0)

EYE_S, EYE_T = 32.0, 1.0           # eye centres at (+-EYE_S, EYE_T)
EYE_HALF_WIDTH = 14.0              # half width of the eye opening (corner to centre)
_LID_UP, _LID_LO = 5.8, 4.2        # opening above / below the centre line
_CREASE = 5.5                      # upper-lid crease height above the lid margin
_EYE_TILT = 0.07                   # canthal tilt: lateral corner higher
BLINK_GAP = 0.06                   # fraction of the opening left when the eye is shut
EYE_RADIUS = 13.5                  # radius of the eyeball dome (mm of (s, t))

MOUTH_T = -61.0                    # mouth line
MOUTH_HALF_WIDTH = 25.0            # half width of the slit (corner to centre)
_SLIT = 0.6                        # half height of the slit at the centre

GRID_SPACING = 200.0               # spacing at the face centre is GRID_SPACING / resolution


def uv_from_st(s, t) -> np.ndarray:
    """Normalised parameters ``(u, v)`` in [0, 1]^2 of domain points.

    Parameters
    ----------
    s, t : (...) float
        Domain coordinates, mm.

    Returns
    -------
    (..., 2) float64
    """
    return np.stack([(s - S_MIN) / (S_MAX - S_MIN), (t - T_MIN) / (T_MAX - T_MIN)], axis=-1)


def st_from_uv(uv) -> tuple[np.ndarray, np.ndarray]:
    """Domain points ``(s, t)`` of normalised parameters (inverse of :func:`uv_from_st`).

    Parameters
    ----------
    uv : (..., 2) float

    Returns
    -------
    s, t : (...) float64
    """
    uv = np.asarray(uv, dtype=np.float64)
    return S_MIN + uv[..., 0] * (S_MAX - S_MIN), T_MIN + uv[..., 1] * (T_MAX - T_MIN)


def smoothstep(x):
    """``3 x^2 - 2 x^3`` of ``x`` clipped to [0, 1]: a smooth 0-to-1 ramp, any shape."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def gaussian(ds, dt, sx, sy):
    """Gaussian bump ``exp(-((ds / sx)^2 + (dt / sy)^2) / 2)`` of offsets from its centre."""
    return np.exp(-0.5 * ((ds / sx) ** 2 + (dt / sy) ** 2))


def slit_half_height(s):
    """Half height of the mouth slit at ``s`` (0 outside the mouth)."""
    x = np.clip(np.abs(s) / MOUTH_HALF_WIDTH, 0.0, 1.0)
    return _SLIT * (1.0 - x * x)


def in_slit(s, t):
    """Whether domain points ``(s, t)`` (any shape) fall inside the mouth slit."""
    return (np.abs(s) < MOUTH_HALF_WIDTH) & (np.abs(t - MOUTH_T) < slit_half_height(s))


def eye_local(s, t):
    """Eye-local coordinates: ``a`` (lateral positive) and ``b`` (up, tilt removed)."""
    a = np.abs(s) - EYE_S
    return a, t - EYE_T - _EYE_TILT * a


def lid_margins(a):
    """Upper margin, lower margin and upper crease heights (in ``b``) along ``a``."""
    x = np.clip(a / EYE_HALF_WIDTH, -1.0, 1.0)
    f = (1.0 - x * x) ** 0.75
    up = _LID_UP * f * (1.0 - 0.15 * x)
    lo = -_LID_LO * f * (1.0 + 0.15 * x)
    xc = np.clip(a / (EYE_HALF_WIDTH + 3.0), -1.0, 1.0)
    crease = up + _CREASE * (1.0 - xc * xc)
    return up, lo, crease


def eye_opening(a, b, closure):
    """1 where the eyeball shows between the lid margins, 0 on the lids (smooth)."""
    up, lo, _ = lid_margins(a)
    up = lo + (1.0 - closure * (1.0 - BLINK_GAP)) * (up - lo)
    eps = 1.2
    return (smoothstep((up - b) / eps + 0.5) * smoothstep((b - lo) / eps + 0.5)
            * smoothstep((up - lo) / (2.0 * eps)))


def lip_extent(s):
    """Heights of the upper and lower vermilion above/below the mouth line."""
    x = np.clip(np.abs(s) / MOUTH_HALF_WIDTH, 0.0, 1.0)
    bow = (0.9 * np.exp(-0.5 * ((np.abs(s) - 5.0) / 2.5) ** 2)      # cupid's bow
           - 0.6 * np.exp(-0.5 * (s / 1.8) ** 2))
    upper = (8.0 + bow) * (1.0 - x * x) ** 0.6
    lower = 10.0 * (1.0 - x * x) ** 0.5
    return upper, lower


def relative_spacing_s(s):
    """Grid/sample spacing along ``s`` relative to the face centre."""
    x = np.abs(s)
    ears = np.exp(-0.5 * ((x - 158.0) / 14.0) ** 2)
    return (0.85 + 0.15 * smoothstep((x - 30.0) / 30.0)
            + 1.2 * smoothstep((x - 60.0) / 70.0) - 0.9 * ears)


def relative_spacing_t(t):
    """Grid/sample spacing along ``t``: finer at the eyes and mouth, coarser on top."""
    fine = 0.42 * np.exp(-0.5 * ((t - EYE_T - 2.0) / 8.0) ** 2) \
        + 0.3 * np.exp(-0.5 * ((t - MOUTH_T) / 9.0) ** 2)
    return 1.0 - fine + 1.5 * smoothstep((t - 55.0) / 60.0) \
        + 0.6 * smoothstep((-95.0 - t) / 20.0)


def cumulative_density(lo, hi, rel, n=4001):
    """Cumulative sample density ``int 1 / rel`` over ``[lo, hi]`` on ``n`` points.

    Returns
    -------
    x, cum : (n,) float64
        The points and the integral up to each; sampling ``cum`` evenly spaces
        points at ``rel(x)`` relative spacing.
    """
    x = np.linspace(lo, hi, n)
    dens = 1.0 / rel(x)
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (dens[1:] + dens[:-1]) * np.diff(x))])
    return x, cum


def landmark_layout() -> tuple[np.ndarray, np.ndarray]:
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
            up, lo, _ = lid_margins(np.array(a))
            b = {"c": 0.0, "u": float(up), "l": float(lo)}[which]
            out.append((side * (EYE_S + a), EYE_T + _EYE_TILT * a + b))
        return out
    w, q = EYE_HALF_WIDTH, EYE_HALF_WIDTH / 3.0
    pts += eye(-1.0, [(w, "c"), (q, "u"), (-q, "u"), (-w, "c"), (-q, "l"), (q, "l")])
    pts += eye(1.0, [(-w, "c"), (-q, "u"), (q, "u"), (w, "c"), (q, "l"), (-q, "l")])
    kind += [1, 4, 4, 1, 5, 5] * 2
    m = MOUTH_T
    pts += [(-MOUTH_HALF_WIDTH - 2.0, m), (-15.0, m + 6.5), (-5.5, m + 9.0), (0.0, m + 8.3),
            (5.5, m + 9.0), (15.0, m + 6.5), (MOUTH_HALF_WIDTH + 2.0, m), (15.0, m - 7.5),
            (6.0, m - 9.5), (0.0, m - 10.0), (-6.0, m - 9.5), (-15.0, m - 7.5)]
    kind += [0] * 12
    pts += [(-MOUTH_HALF_WIDTH, m), (-10.0, m), (0.0, m), (10.0, m), (MOUTH_HALF_WIDTH, m),
            (10.0, m), (0.0, m), (-10.0, m)]
    kind += [0, 2, 2, 2, 0, 3, 3, 3]
    return np.asarray(pts, dtype=np.float64), np.asarray(kind)
