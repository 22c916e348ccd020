"""Points from several views made one: lifted, compared, averaged, scored.

Each refined view gives 68 surface points (its 2D points lifted through the raster,
:meth:`~facewrap.detection.views.RenderedView.lift`); a point counts as *seen* in a
view when its surface faces that camera (a jaw point that the detector puts on the
silhouette of a turned face does not).  Per landmark, the lifts that lie within the
agreement radius of their median are averaged; the confidence is the share of the
views that agree times a Gaussian of their spread, so a point two views disagree on
(the jaw contour of a cropped scan) or that only a few views see scores low.  All of
it is vectorised over views and landmarks.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

__all__ = ["ViewPoints", "Fused", "seen_lifts", "fuse_views"]

_FACING = 0.05          # |cos| between a lift's surface normal and its view: seen


@dataclass(frozen=True, eq=False)
class ViewPoints:
    """The 68 points one view found.

    Attributes
    ----------
    pixels : (68, 2) float64
        Detected points in the view's picture.
    points : (68, 3) float64
        Their lifts onto the surface; NaN where not seen.
    """
    pixels: np.ndarray
    points: np.ndarray


@dataclass(frozen=True, eq=False)
class Fused:
    """Fused landmarks (before they are snapped onto the surface).

    Attributes
    ----------
    points : (68, 3) float64
    confidence : (68,) float64 in [0, 1]
    agreeing : (68,) int64
        Views whose lift lies within the agreement radius.
    seen : (68,) int64
        Views that see the point.
    spread : (68,) float64
        RMS distance of the agreeing lifts to the fused point, model units.
    """
    points: np.ndarray
    confidence: np.ndarray
    agreeing: np.ndarray
    seen: np.ndarray
    spread: np.ndarray


def seen_lifts(points, triangles, face_normals, direction) -> np.ndarray:
    """``points`` (68, 3) with NaN where the triangle (-1: none) does not face the view.

    Examples
    --------
    >>> P = np.zeros((2, 3)); N = np.array([[0, 0, 1.], [1, 0, 0.]])
    >>> np.isnan(seen_lifts(P, np.array([0, 1]), N, [0, 0, 1])[:, 0]).tolist()
    [False, True]
    """
    out = np.array(points, dtype=np.float64)
    tri = np.asarray(triangles)
    facing = np.zeros(len(tri), dtype=bool)
    hit = tri >= 0
    facing[hit] = np.abs(face_normals[tri[hit]] @ np.asarray(direction, float)) > _FACING
    out[~facing] = np.nan
    return out


def fuse_views(lifts: np.ndarray, radius: float) -> Fused:
    """Robust mean of each landmark over views, with a confidence.

    Parameters
    ----------
    lifts : (v, k, 3) float64
        Lifted points per view, NaN where a view does not see a point.
    radius : float
        Lifts within this distance of the per-landmark median agree.

    Returns
    -------
    Fused
        ``points`` NaN where no view sees a landmark (its confidence is 0).

    Examples
    --------
    Three views agree on the first point, one is off on the second:

    >>> L = np.zeros((3, 2, 3)); L[2, 1] = [5.0, 0, 0]
    >>> f = fuse_views(L, radius=1.0)
    >>> f.agreeing.tolist(), np.round(f.confidence, 2).tolist()
    ([3, 2], [1.0, 0.67])
    """
    v = lifts.shape[0]
    seen = np.isfinite(lifts).all(axis=2)                          # (v, k)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)            # all-NaN columns
        median = np.nanmedian(lifts, axis=0)                       # (k, 3)
    dist = np.linalg.norm(lifts - median, axis=2)
    agree = seen & (dist <= radius)
    n_agree = agree.sum(axis=0)
    w = agree[..., None].astype(np.float64)
    total = np.where(agree[..., None], lifts, 0.0).sum(axis=0)
    with np.errstate(all="ignore"):
        points = np.where(n_agree[:, None] > 0, total / np.maximum(n_agree, 1)[:, None],
                          median)
        sq = (np.linalg.norm(np.where(agree[..., None], lifts - points, 0.0), axis=2)
              ** 2 * w[..., 0]).sum(axis=0)
    spread = np.sqrt(sq / np.maximum(n_agree, 1))
    sigma = 0.5 * radius
    confidence = (n_agree / v) * np.exp(-0.5 * (spread / sigma) ** 2) if radius > 0 \
        else n_agree / v
    confidence = np.where(n_agree > 0, confidence, 0.0)
    return Fused(points, np.clip(confidence, 0.0, 1.0), n_agree.astype(np.int64),
                 seen.sum(axis=0).astype(np.int64), spread)
