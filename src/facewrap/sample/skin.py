"""The procedural texture of a sample scan: skin, hair, brows, lips, lashes, eyes."""

from __future__ import annotations

import numpy as np

from facewrap.sample.layout import (EYE_HALF_WIDTH, MOUTH_HALF_WIDTH, MOUTH_T, eye_local,
                                    eye_opening, gaussian, lid_margins, lip_extent, smoothstep,
                                    st_from_uv)
from facewrap.sample.surface import ear_relief

__all__ = ["skin_texture"]


def _smooth_noise(rng, size, cells, order=3):
    """(size, size) smooth random field with about ``cells`` blobs across, std ~1."""
    from scipy.ndimage import zoom  # scipy.ndimage takes ~0.3 s to import; only scans need it

    coarse = rng.standard_normal((cells + 3, cells + 3))
    fine = zoom(coarse, size / cells, order=order, mode="grid-wrap")
    return fine[:size, :size]


def skin_texture(size, ident, rng, eyes_open=1.0) -> np.ndarray:
    """(size, size, 3) uint8 albedo over the parameter domain (row 0 at ``v = 1``);
    the eyeball shows in the eye openings in proportion to ``eyes_open``."""
    c = (np.arange(size) + 0.5) / size
    s, t = st_from_uv(np.stack(np.meshgrid(c, c[::-1], indexing="xy"), axis=-1))
    tone = np.clip(ident.skin, -1.0, 1.0)
    skin = np.array([0.87, 0.67, 0.55]) * (1.0 + 0.12 * tone)
    img = np.broadcast_to(skin, (size, size, 3)).copy()
    img *= (1.0 + 0.035 * _smooth_noise(rng, size, 10))[..., None]
    as_ = np.abs(s)

    def mix(colour, alpha):
        nonlocal img
        alpha = np.clip(alpha, 0.0, 1.0)[..., None]
        img = img * (1.0 - alpha) + np.asarray(colour) * alpha

    mix([0.85, 0.5, 0.47], 0.22 * gaussian(as_ - 42.0, t + 28.0, 15.0, 11.0))
    # shadow beyond the jaw line (the landmarks' jaw contour, see
    # layout.landmark_layout): a detector puts the jaw where the face's lit part ends
    jaw = (as_ / 74.0) ** (2 / 0.85) + (np.maximum(-6.0 - t, 0.0) / 92.0) ** (2 / 1.3)
    mix(np.array([0.3, 0.21, 0.18]), 0.85 * smoothstep((jaw - 1.0) / 0.15))
    # hair above the hairline and at the temples
    hairline = 66.0 - 76.0 * smoothstep((as_ - 60.0) / 90.0)
    strands = 0.8 + 0.2 * _smooth_noise(rng, size, size // 6 or 1, order=1)
    ears = ear_relief(as_, t) > 1.0
    mix(np.array([0.24, 0.17, 0.13]) * strands[..., None],
        smoothstep((t - hairline) / 4.0) * ~ears)
    # brows
    centre = 15.5 + 4.5 * np.exp(-((as_ - 33.0) / 14.0) ** 2)
    half = 4.0 - 2.2 * smoothstep((as_ - 15.0) / 38.0)
    ends = smoothstep((as_ - 10.0) / 4.0) * (1.0 - smoothstep((as_ - 52.0) / 5.0))
    brow = smoothstep((half - np.abs(t - centre)) / 1.2) * ends
    mix(np.array([0.16, 0.11, 0.09]) * strands[..., None], 0.95 * brow)
    # lips
    b = t - MOUTH_T
    eu, el = lip_extent(s)
    lip = (smoothstep((eu - b) / 1.2 + 0.5) * smoothstep((b + el) / 1.2 + 0.5)
           * (as_ < MOUTH_HALF_WIDTH + 1.0))
    mix([0.55, 0.24, 0.25], 0.9 * lip)
    # nostrils
    mix([0.35, 0.2, 0.18], smoothstep(1.0 - np.hypot((as_ - 6.0) / 2.6, (t + 41.0) / 1.7)))
    # eyes: white, iris and pupil inside the opening, lashes along the margins
    a, be = eye_local(s, t)
    # the socket's shadow around the eye: what a detector first sees of an eye
    mix([0.42, 0.28, 0.25], 0.45 * gaussian(a, be + 1.0, 0.8 * EYE_HALF_WIDTH, 5.5))
    opening = eye_opening(a, be, 0.0)
    r = np.hypot(a, be + 0.5)
    iris = np.array([0.38, 0.26, 0.16]) if ident.skin < 0.3 else np.array([0.3, 0.45, 0.6])
    eye = np.where((r < 5.4)[..., None], iris * (0.75 + 0.25 * (r / 5.4))[..., None],
                   np.array([0.93, 0.9, 0.87]))
    eye = np.where((r < 2.3)[..., None], np.array([0.05, 0.05, 0.06]), eye)
    mix(eye, opening * eyes_open)
    up, lo, _ = lid_margins(a)
    env = (np.abs(a) < EYE_HALF_WIDTH + 1.0)
    mix([0.08, 0.06, 0.05], env * smoothstep(1.0 - np.abs(be - up - 0.5) / 1.4))
    mix([0.2, 0.14, 0.12], 0.5 * env * smoothstep(1.0 - np.abs(be - lo + 0.2) / 0.6))
    img *= (1.0 + 0.03 * rng.standard_normal((size, size)))[..., None]     # pores
    return np.clip(np.round(img * 255.0), 0, 255).astype(np.uint8)
