"""Preconditioned conjugate gradients: the one Krylov solver of facewrap.

Two callers, two stopping rules, one recurrence:

* the Gauss–Newton steps of large wrap models (:func:`~facewrap.solve.gauss_newton_step`)
  stop on the relative residual ``‖r‖ ≤ rtol ‖b‖`` (scipy's rule; an inexact step
  is as good as an exact one when correspondences change after every step), with
  a block-Jacobi preconditioner (:func:`block_jacobi`);
* the correspondence deformation re-solves a system whose diagonal changed since
  its last factorisation, preconditioned by that factor, and stops on the
  preconditioned residual (an estimate of the remaining error) relative to the
  largest coordinate; it gives up early when the convergence rate so far says the
  iteration budget will not do, because factoring afresh is then cheaper.

Columns of a right-hand side run independent recurrences (their own step lengths)
but share each preconditioner application (one back-substitution for all).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

__all__ = ["block_jacobi", "conjugate_gradients", "CGResult"]

#: iterations before the convergence rate is trusted to predict the rest
_RATE_AFTER = 6


class CGResult(NamedTuple):
    """What :func:`conjugate_gradients` returns.

    Attributes
    ----------
    x : (f,) or (f, k) float64
        The last iterate (also when not converged).
    iterations : int
    converged : bool
        False when the iterations ran out, gave up, or broke down (non-finite
        values, negative curvature).
    """

    x: np.ndarray
    iterations: int
    converged: bool


def _column_dots(a: np.ndarray, b: np.ndarray):
    # np.dot for one column: the same arithmetic as scipy's cg, which the wrap
    # models' steps were tuned with
    return np.dot(a, b) if a.ndim == 1 else np.einsum("ij,ij->j", a, b)


def _preconditioner(M):
    if M is None:
        return lambda r: r
    if hasattr(M, "solve"):                    # a Factor of a nearby matrix
        return M.solve
    if hasattr(M, "matvec"):                   # a LinearOperator (block_jacobi)
        return M.matvec
    return M


def conjugate_gradients(A, b, x0=None, preconditioner=None, *, rtol: float = 1e-5,
                        max_iterations: int | None = None, stop: str = "residual",
                        give_up: bool = False) -> CGResult:
    """Preconditioned conjugate gradients for ``A x = b``.

    Parameters
    ----------
    A : (f, f) scipy.sparse matrix or LinearOperator
        Symmetric positive definite.
    b : (f,) or (f, k) float64
        One or ``k`` right-hand sides (solved together).
    x0 : same shape as ``b``, optional
        Starting guess (default zero); not modified.
    preconditioner : Factor, LinearOperator or callable, optional
        Applies an approximate inverse of ``A`` (``.solve``, ``.matvec`` or a call).
    rtol : float
        Tolerance of the stopping rule.
    max_iterations : int, optional
        Default ``10 f``.
    stop : {"residual", "error"}
        "residual": every column's ``‖r‖₂ < rtol ‖b‖₂``.  "error": the largest
        entry of the preconditioned residual (an estimate of the error) at most
        ``rtol`` times the largest entry of ``x``.
    give_up : bool
        ("error" only) stop as soon as the mean convergence rate so far says more
        than ``max_iterations`` would be needed.

    Returns
    -------
    CGResult

    Examples
    --------
    >>> A = sp.diags([-1.0, 4.0, -1.0], [-1, 0, 1], shape=(50, 50)).tocsr()
    >>> res = conjugate_gradients(A, np.ones(50), rtol=1e-10)
    >>> res.converged, bool(np.allclose(A @ res.x, 1.0))
    (True, True)
    """
    if stop not in ("residual", "error"):
        raise ValueError(f"stop must be 'residual' or 'error', got {stop!r}")
    b = np.asarray(b, dtype=np.float64)
    max_iterations = 10 * b.shape[0] if max_iterations is None else int(max_iterations)
    apply = _preconditioner(preconditioner)
    x = np.zeros_like(b) if x0 is None else np.array(x0, dtype=np.float64)
    r = b - A @ x if x.any() else b.copy()
    if stop == "residual":
        atol = rtol * np.linalg.norm(b, axis=0)
        if not np.any(atol):
            return CGResult(np.zeros_like(b), 0, True)
    errors = []
    p = rz_old = None
    for it in range(max_iterations + 1):
        if stop == "residual":
            if np.all(np.linalg.norm(r, axis=0) < atol):
                return CGResult(x, it, True)
            if it == max_iterations:
                return CGResult(x, it, False)
            z = apply(r)
        else:
            z = apply(r)
            err = float(np.abs(z).max()) / max(float(np.abs(x).max()), 1e-300)
            if not np.isfinite(err):
                return CGResult(x, it, False)
            if err <= rtol:
                return CGResult(x, it, True)
            errors.append(err)
            if it == max_iterations or (give_up and _hopeless(errors, it, rtol,
                                                              max_iterations)):
                return CGResult(x, it, False)
        rz = _column_dots(r, z)
        p = z.copy() if p is None else z + np.divide(rz, rz_old, out=np.zeros_like(rz),
                                                     where=rz_old != 0) * p
        rz_old = rz
        Ap = A @ p
        pAp = _column_dots(p, Ap)
        if np.any(pAp < 0):
            return CGResult(x, it, False)
        alpha = np.divide(rz, pAp, out=np.zeros_like(rz), where=pAp > 0)
        x += alpha * p
        r -= alpha * Ap
    return CGResult(x, max_iterations, False)  # pragma: no cover - loop returns


def _hopeless(errors: list, it: int, rtol: float, budget: int) -> bool:
    """Whether the mean rate so far predicts more than ``budget`` iterations (the
    estimate oscillates and CG slows down rather than speeds up here, so the
    prediction is optimistic)."""
    if it < _RATE_AFTER:
        return False
    best = min(errors)
    rate = (best / errors[0]) ** (1.0 / it)
    return bool(rate >= 1 or it + np.log(rtol / best) / np.log(rate) > budget)


def block_jacobi(H, block: int, n_blocked: int | None = None):
    """Block-Jacobi preconditioner of a sparse SPD matrix.

    Parameters
    ----------
    H : (P, P) sparse
    block : int
        Size of the diagonal blocks over the first ``n_blocked`` unknowns (e.g. 6
        per graph node: rotation and translation); the rest use the diagonal.
    n_blocked : int, optional
        Default ``P`` rounded down to a multiple of ``block``.

    Returns
    -------
    scipy.sparse.linalg.LinearOperator applying the inverse blocks.
    """
    # (imported here: scipy.sparse.linalg and the scipy.linalg it loads cost a
    # process ~0.05 s, and only the sparse path of a large system comes here)
    import scipy.sparse.linalg as spla
    H = sp.csr_matrix(H)
    P = H.shape[0]
    nb = (P if n_blocked is None else n_blocked) // block
    k = nb * block
    diag = H.diagonal()
    if nb == 0 or block == 1:
        inv = 1.0 / diag
        return spla.LinearOperator((P, P), matvec=lambda x: inv * x.ravel(), dtype=float)
    base = (np.arange(nb) * block)[:, None, None]
    rows = np.broadcast_to(base + np.arange(block)[:, None], (nb, block, block)).ravel()
    cols = np.broadcast_to(base + np.arange(block)[None, :], (nb, block, block)).ravel()
    blocks = np.asarray(H[rows, cols]).reshape(nb, block, block)
    inv_blocks = np.linalg.inv(blocks)
    Binv = sp.bsr_matrix((inv_blocks, np.arange(nb), np.arange(nb + 1)),
                         shape=(k, k)).tocsr()
    rest = 1.0 / diag[k:]

    def apply(x):
        x = x.ravel()
        return np.concatenate([Binv @ x[:k], rest * x[k:]])
    return spla.LinearOperator((P, P), matvec=apply, dtype=float)


