"""Radial-basis-function warp from landmark displacements (SPEC §1.2).

``f(p) = Σ_i c_i φ(‖p − p_i‖) + M p + t`` with the side conditions
``Σ c_i = 0`` and ``Σ c_i p_iᵀ = 0``; one (k+4)×(k+4) system per fit, solved for
the three coordinates at once.  Kernels: biharmonic ``φ(r) = r`` (default; smooth,
no length scale), thin-plate ``r² log r``, the seed paper's exponential
``exp(−r/K)`` and a Gaussian ``exp(−(r/K)²)``, with ``K`` taken from the landmark
spacing unless given.  ``smoothing`` adds ``λI`` to the kernel block, so noisy
landmarks are approximated instead of interpolated.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry.quality import turned_triangles

__all__ = ["RBFWarp", "rbf_kernel", "pull_to_landmarks", "nearest_other_distances", "KERNELS"]

KERNELS = ("biharmonic", "thin_plate", "exponential", "gaussian")


def rbf_kernel(r: np.ndarray, kernel: str, width: float = 1.0) -> np.ndarray:
    """Evaluate φ(r) elementwise.

    Examples
    --------
    >>> rbf_kernel(np.array([0.0, 1.0, 2.0]), "thin_plate").round(4).tolist()
    [0.0, 0.0, 2.7726]
    """
    if kernel == "biharmonic":
        return r
    if kernel == "thin_plate":
        with np.errstate(divide="ignore", invalid="ignore"):
            out = r * r * np.log(r)
        return np.where(r > 0, out, 0.0)
    if kernel == "exponential":
        return np.exp(-r / width)
    if kernel == "gaussian":
        return np.exp(-(r / width) ** 2)
    raise ValueError(f"unknown kernel {kernel!r}; choose one of {KERNELS}")


class RBFWarp:
    """Interpolate (or approximate) displacements given at landmarks.

    Parameters
    ----------
    kernel : {"biharmonic", "thin_plate", "exponential", "gaussian"}
    smoothing : float
        λ ≥ 0 added to the kernel diagonal, in units of the kernel's values; 0
        interpolates exactly.
    width : float, optional
        Length scale K of the exponential/Gaussian kernels; default: twice the mean
        distance from a landmark to its nearest neighbour.
    chunk : int
        Points evaluated per block (bounds memory for large meshes).
    affine : bool
        Add the affine part ``M p + t`` (default).  Without it a decaying kernel
        (Gaussian, exponential) gives a *local* warp that vanishes far from the
        landmarks (:func:`pull_to_landmarks`); the kernel matrix alone must then
        be invertible, which it is for these two kernels and distinct landmarks.

    Attributes
    ----------
    centers_ : (k, 3) landmark positions
    coefficients_ : (k, 3) kernel weights c_i
    affine_ : (4, 3) ``[M | t]ᵀ``: ``f`` affine part is ``p @ affine_[:3] + affine_[3]``
    width_ : float

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> C = rng.normal(size=(20, 3))
    >>> D = C @ np.diag([0.1, 0.2, 0.3]) + 1.0      # an affine displacement field
    >>> warp = RBFWarp().fit(C, D)
    >>> P = rng.normal(size=(5, 3))
    >>> np.allclose(warp.displacement(P), P @ np.diag([0.1, 0.2, 0.3]) + 1.0)
    True
    """

    def __init__(self, kernel: str = "biharmonic", smoothing: float = 0.0,
                 width: float | None = None, chunk: int = 65536, affine: bool = True):
        self.kernel = kernel
        self.smoothing = smoothing
        self.width = width
        self.chunk = chunk
        self.affine = affine

    def fit(self, centers, displacements) -> "RBFWarp":
        """Solve for the warp that moves ``centers`` by ``displacements``.

        Parameters
        ----------
        centers : (k, 3) float
        displacements : (k, 3) float
        """
        if self.kernel not in KERNELS:
            raise ValueError(f"unknown kernel {self.kernel!r}; choose one of {KERNELS}")
        if self.smoothing < 0:
            raise ValueError("smoothing must be >= 0")
        C = np.asarray(centers, dtype=np.float64)
        D = np.asarray(displacements, dtype=np.float64)
        if C.ndim != 2 or C.shape[1] != 3 or D.shape != C.shape:
            raise ValueError(f"centers and displacements must both be (k, 3), got "
                             f"{C.shape} and {D.shape}")
        if not (np.isfinite(C).all() and np.isfinite(D).all()):
            raise ValueError("centers and displacements must be finite")
        k = len(C)
        if k == 0:
            raise ValueError("need at least one landmark")
        if len(np.unique(C.round(12), axis=0)) < k:
            raise ValueError("two landmarks are at the same position")
        if self.width is not None:
            width = float(self.width)
        elif k > 1:
            width = 2.0 * float(nearest_other_distances(C).mean())
        else:
            width = 1.0
        self.width_ = width
        Phi = rbf_kernel(np.linalg.norm(C[:, None] - C[None], axis=2), self.kernel, width)
        Phi[np.diag_indices(k)] += self.smoothing
        P = np.hstack([C, np.ones((k, 1))])
        # With fewer than 4 well-spread landmarks the affine part is not determined:
        # keep only the translation then.
        rank = np.linalg.matrix_rank(P - P.mean(axis=0)) + 1 if k > 1 else 1
        if not self.affine:
            P = np.zeros((k, 0))
        elif rank < 4:
            P = np.ones((k, 1))
        m = P.shape[1]
        A = np.zeros((k + m, k + m))
        A[:k, :k], A[:k, k:], A[k:, :k] = Phi, P, P.T
        rhs = np.vstack([D, np.zeros((m, 3))])
        try:
            sol = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError:
            sol = np.linalg.lstsq(A, rhs, rcond=None)[0]
        self.centers_ = C.copy()
        self.coefficients_ = sol[:k]
        affine = np.zeros((4, 3))
        if m == 4:
            affine[:] = sol[k:]
        elif m == 1:
            affine[3] = sol[k]
        self.affine_ = affine
        return self

    def displacement(self, points) -> np.ndarray:
        """f(p) for (n, 3) points, evaluated in blocks of ``chunk``."""
        X = np.asarray(points, dtype=np.float64)
        if X.ndim != 2 or X.shape[1] != 3:
            raise ValueError(f"points must be (n, 3), got {X.shape}")
        out = np.empty_like(X)
        for s in range(0, len(X), self.chunk):
            B = X[s:s + self.chunk]
            r = np.sqrt(np.maximum(
                (B * B).sum(1)[:, None] - 2 * B @ self.centers_.T
                + (self.centers_ ** 2).sum(1)[None], 0.0))
            out[s:s + self.chunk] = (rbf_kernel(r, self.kernel, self.width_)
                                     @ self.coefficients_
                                     + B @ self.affine_[:3] + self.affine_[3])
        return out

    def transform(self, points) -> np.ndarray:
        """Warped points ``p + f(p)``."""
        X = np.asarray(points, dtype=np.float64)
        return X + self.displacement(X)


#: rounds in which the pulls of the landmarks around a triangle the pull would turn
#: over are halved, before those landmarks are not pulled at all
_GUARD_ROUNDS = 6
#: a landmark is "around" a turned triangle within this many RBF widths
_GUARD_REACH = 2.0


def pull_to_landmarks(points, fitted, targets, tolerance: float, *, triangles=None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Move points so that no landmark ends farther than ``tolerance`` from its target.

    Each landmark's offset to its target is shortened by ``tolerance`` (a landmark
    already within it does not move, and holds its surroundings in place); a
    Gaussian RBF without affine part, as wide as the typical spacing of the
    landmarks (the median distance to the nearest one), carries these pulls to the
    points, so the correction stays local and vanishes far from the landmarks.
    Landmarks at the same position are merged (their pulls averaged).

    Given ``triangles``, the pull never turns one of them over: landmarks that
    disagree with each other or with the fitted surface (noisy or mis-clicked
    points, a few millimetres apart in opposite directions) would fold the skin
    between them, so the pulls of the landmarks around a triangle the pull turns
    past 90° from where it was are halved, round by round, and dropped after
    :data:`_GUARD_ROUNDS` rounds.  (Measured from where it was, not from the
    template: a small pull that tips a triangle already near 90° is left to the
    unfolding that follows in a wrap; on ICT's face -> james with clean
    landmarks no landmark is held back.)

    Parameters
    ----------
    points : (n, 3) float
        What moves (a fitted template's vertices).
    fitted : (k, 3) float
        The landmarks' current positions (on the fitted template).
    targets : (k, 3) float
        Where they should be.
    tolerance : float
        How far a landmark may stay from its target (same units; 0 pins exactly).
    triangles : (t, 3) int, optional
        Triangles over ``points`` the pull must not turn over.

    Returns
    -------
    moved : (n, 3) float64
    pulls : (k,) float64
        How far each landmark was pulled (0 within the tolerance); less than its
        distance beyond the tolerance where the guard held it back.

    Examples
    --------
    >>> P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [5, 5, 5]])
    >>> moved, pulls = pull_to_landmarks(P, P[:3], P[:3] + [[0.5, 0, 0], [0, 0, 0], [0, 0, 0]], 0.1)
    >>> pulls.round(3).tolist(), moved[0].round(3).tolist(), moved[3].round(3).tolist()
    ([0.4, 0.0, 0.0], [0.4, 0.0, 0.0], [5.0, 5.0, 5.0])

    Two neighbouring landmarks pulled across each other would turn the triangle
    between them over; the guard halves their pulls until it does not:

    >>> P = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    >>> swap = P[:2][::-1] + [[0, 0.01, 0], [0, -0.01, 0]]
    >>> pull_to_landmarks(P, P[:2], swap, 0.0)[1].round(2).tolist()
    [1.0, 1.0]
    >>> pull_to_landmarks(P, P[:2], swap, 0.0, triangles=[[0, 1, 2]])[1].round(2).tolist()
    [0.25, 0.25]
    """
    X = np.asarray(points, dtype=np.float64)
    F = np.asarray(fitted, dtype=np.float64)
    D = np.asarray(targets, dtype=np.float64) - F
    if not tolerance >= 0:
        raise ValueError(f"tolerance must be >= 0, got {tolerance!r}")
    length = np.linalg.norm(D, axis=1)
    keep = np.clip(1.0 - tolerance / np.maximum(length, 1e-300), 0.0, None)
    D = D * keep[:, None]
    pulls = length * keep
    if len(F) == 0 or not np.any(pulls > 0):
        return X.copy(), pulls
    centers, group = np.unique(F, axis=0, return_inverse=True)
    group = group.ravel()
    counts = np.bincount(group, minlength=len(centers))
    if len(centers) > 1:
        width = float(np.median(nearest_other_distances(centers)))
    else:
        width = float(np.linalg.norm(X.max(axis=0) - X.min(axis=0))) * 0.1 or 1.0
    warp = RBFWarp(kernel="gaussian", width=width, smoothing=1e-9, affine=False)

    def pulled(scale):
        shifts = np.stack([np.bincount(group, D[:, c] * scale, len(centers))
                           for c in range(3)], axis=1) / counts[:, None]
        return warp.fit(centers, shifts).transform(X)

    scale = np.ones(len(F))
    moved = pulled(scale)
    if triangles is None:
        return moved, pulls
    T = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    # after the halving rounds, each round drops at least one more landmark
    for round_ in range(_GUARD_ROUNDS + len(F) + 1):
        new = turned_triangles(moved, X, T)
        if not new.any():
            return moved, pulls * scale
        # the landmarks around each new turn, and at least the nearest pulled one
        gap = np.linalg.norm(X[T[new]].mean(axis=1)[:, None] - F[None], axis=2)
        gap[:, scale == 0] = np.inf
        if not np.isfinite(gap).any():
            break
        near = (gap < _GUARD_REACH * width).any(axis=0)
        near[np.argmin(gap, axis=1)] = True
        scale[near] = 0.0 if round_ >= _GUARD_ROUNDS else 0.5 * scale[near]
        moved = pulled(scale)
    return X.copy(), np.zeros_like(pulls)


#: below this many points a distance table beats building a KD-tree (and a wrap
#: then never imports scipy.spatial: 0.08 s of its start-up)
_TABLE_POINTS = 2000


def nearest_other_distances(C) -> np.ndarray:
    """(k,) distance from each of k >= 2 points to the nearest other one.

    Parameters
    ----------
    C : (k, 3) float64

    Returns
    -------
    (k,) float64

    Examples
    --------
    >>> nearest_other_distances(np.array([[0, 0, 0], [1, 0, 0], [3, 0, 0.]])).tolist()
    [1.0, 1.0, 2.0]
    """
    C = np.asarray(C, dtype=np.float64)
    if len(C) > _TABLE_POINTS:
        from scipy.spatial import cKDTree
        return cKDTree(C).query(C, k=2)[0][:, 1]
    D = np.linalg.norm(C[:, None] - C[None], axis=2)
    np.fill_diagonal(D, np.inf)
    return D.min(axis=1)
