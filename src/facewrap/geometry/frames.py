"""The normalised frame: template centred, unit bounding-box diagonal.

Registration weights and tolerances (a scan-point distance of 0.05, a robust
scale, a node spacing) are fractions of the template's size, so that they mean the
same on a face in mm, cm or m.  Every stage that works in such a frame — the
non-rigid ICP, its models, the deformation graph, the transfer's correspondence —
takes it from here, so there is one definition of "normalised":
``x_scan = x * size + center``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry.checks import as_points

__all__ = ["NormalisedFrame"]


@dataclass(frozen=True, eq=False)
class NormalisedFrame:
    """A frame centred on a point set's centroid, scaled by its bounding-box diagonal.

    Attributes
    ----------
    center : (3,) float64
        Centroid (mean of the points), in the caller's units.
    size : float
        Bounding-box diagonal, in the caller's units.

    Examples
    --------
    >>> frame = NormalisedFrame.of(np.array([[0, 0, 0], [3, 4, 0.]]))
    >>> frame.center.tolist(), frame.size
    ([1.5, 2.0, 0.0], 5.0)
    >>> frame.to_frame([[3, 4, 0.]]).tolist()
    [[0.3, 0.4, 0.0]]
    >>> frame.from_frame(frame.to_frame([[3, 4, 0.]])).tolist()
    [[3.0, 4.0, 0.0]]
    """

    center: np.ndarray
    size: float

    @classmethod
    def of(cls, points) -> "NormalisedFrame":
        """The frame of ``points`` ((n, 3) float): their mean and bounding-box diagonal.

        Raises
        ------
        ValueError
            When ``points`` is not (n, 3) with n >= 1.
        """
        P = as_points(points, "points")
        if len(P) == 0:
            raise ValueError("points must hold at least one point")
        center = P.mean(axis=0)
        size = float(np.linalg.norm(P.max(axis=0) - P.min(axis=0)))
        return cls(center, size)

    def to_frame(self, x) -> np.ndarray:
        """Caller's units → frame: ``(x - center) / size`` for (..., 3) positions."""
        return (np.asarray(x, dtype=np.float64) - self.center) / self.size

    def from_frame(self, x) -> np.ndarray:
        """Frame → caller's units: ``x * size + center`` for (..., 3) positions."""
        return np.asarray(x, dtype=np.float64) * self.size + self.center
