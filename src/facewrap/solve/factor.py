"""Sparse linear solves shared by every fitting and transfer step.

Most of facewrap's work ends in a sparse symmetric positive definite system
``A x = b`` (normal equations of a least-squares energy).  :func:`factorize`
factors ``A`` once and returns a :class:`Factor` whose :meth:`Factor.solve` is a
cheap back-substitution for any number of right-hand sides — the "set up once,
solve many times" pattern (one factor, three coordinates; one factor, many poses).

Two Cholesky back ends (both wheels), chosen by what the factor is for:

* ``solves="many"`` (default): cholespy.  Its back-substitution is fast (several
  times SuperLU's and CHOLMOD-through-cvxopt's on the systems here), its
  factorisation slow.  For factors used for many solves: transfer poses, avatar
  shapes.
* ``solves="few"``: CHOLMOD's supernodal factorisation from cvxopt, with
  OpenBLAS: several times faster to factor and slower to back-substitute
  (figures in docs/benchmarks.md).  For a factor per step: correspondence steps,
  ICP iterations, local repairs.

Where the matrix is not positive definite (an energy with a null space, e.g. no
translation fixed) both refuse it (cholespy's CHOLMOD prints a warning on stderr);
the factor is also checked on a random right-hand side; either way the solve falls
back to SuperLU on a slightly regularised matrix, which always gives a finite
answer.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

# Both back ends are dependencies; without one the other (or SuperLU) is used.
try:
    from cholespy import CholeskySolverD, MatrixType
except ImportError:  # pragma: no cover - cholespy is a dependency
    CholeskySolverD = MatrixType = None
try:
    from cvxopt import cholmod, matrix as cvxopt_matrix, spmatrix as cvxopt_spmatrix
except ImportError:  # pragma: no cover - cvxopt is a dependency
    cholmod = None

__all__ = ["Factor", "factorize", "refactorize", "solve_spd"]


class Factor:
    """A factored sparse SPD matrix; call :meth:`solve` as often as needed.

    Build with :func:`factorize`.  Attributes: ``n`` (size), ``method``
    ("cholesky": cholespy, "cholmod": cvxopt's CHOLMOD, or "lu": SuperLU).
    """

    def __init__(self, n: int, method: str, solver, pattern=None):
        self.n = n
        self.method = method
        self._solver = solver
        self._pattern = pattern       # CHOLMOD's input, for refactorize

    def solve(self, b) -> np.ndarray:
        """Solve ``A x = b``.

        Parameters
        ----------
        b : (n,) or (n, k) float
            One or ``k`` right-hand sides.

        Returns
        -------
        x : same shape as ``b``, float64
        """
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise ValueError(f"right-hand side has {b.shape[0]} rows, matrix has {self.n}")
        if self.method == "cholesky":
            rhs = np.ascontiguousarray(b)
            x = np.empty_like(rhs)
            self._solver.solve(rhs, x)
            return x
        if self.method == "cholmod":
            x = cvxopt_matrix(np.asfortranarray(b.reshape(self.n, -1)))
            cholmod.solve(self._solver, x)
            return np.array(x).reshape(b.shape)
        return self._solver.solve(b)

    def forward(self, b) -> np.ndarray | None:
        """Half a solve: ``Y = L⁻¹ P b`` of the factor ``A = Pᵀ L Lᵀ P``, so that
        ``YᵀY = bᵀ A⁻¹ b`` (a Schur complement from half the work of a solve); None
        when the back end does not split its solves (only CHOLMOD does).

        Parameters
        ----------
        b : (n, k) float
        """
        if self.method != "cholmod":
            return None
        y = cvxopt_matrix(np.asfortranarray(np.asarray(b, dtype=np.float64)))
        cholmod.solve(self._solver, y, sys=7)          # P
        cholmod.solve(self._solver, y, sys=4)          # L
        return np.array(y)

    def backward(self, y) -> np.ndarray:
        """The other half, ``x = Pᵀ L⁻ᵀ y``: ``backward(forward(b)) = A⁻¹ b``
        (only after :meth:`forward` gave an answer).

        Parameters
        ----------
        y : (n,) float
        """
        x = cvxopt_matrix(np.asfortranarray(np.asarray(y, dtype=np.float64)))
        cholmod.solve(self._solver, x, sys=5)          # Lᵀ
        cholmod.solve(self._solver, x, sys=8)          # Pᵀ
        return np.array(x).reshape(np.shape(y))


def refactorize(factor: Factor, A, *, check: bool = True) -> Factor:
    """Factor ``A`` reusing ``factor``'s ordering and symbolic analysis when ``A``
    has exactly the sparsity pattern of the matrix ``factor`` was made from
    (CHOLMOD: the analysis and the conversion to its format are most of a
    factorisation on the ICP's graph blocks).

    ``factor`` is used up (its storage may hold the new factor); use the returned
    one.  Any other factor, or a matrix of another pattern, is factored afresh with
    ``solves="few"`` (CHOLMOD itself does not notice another pattern: it returns a
    wrong factor, so the pattern is compared here).

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> f = factorize(sp.diags([2.0, 3.0]).tocsr(), solves="few")
    >>> refactorize(f, sp.diags([4.0, 6.0]).tocsr()).solve([4.0, 6.0])
    array([1., 1.])
    """
    if factor.method == "cholmod" and factor._pattern is not None:
        A = _canonical_csr(A)
        if factor._pattern.matches(A):
            try:
                factor._pattern.refill(A)
                cholmod.numeric(factor._pattern.lower, factor._solver)
            except (ArithmeticError, ValueError):    # not positive definite
                pass
            else:
                if not check or _accurate(A, factor):
                    return factor
    return factorize(A, check=check, solves="few")


def factorize(A, *, check: bool = True, solves: str = "many") -> Factor:
    """Factor a sparse symmetric positive (semi-)definite matrix.

    Parameters
    ----------
    A : (n, n) scipy.sparse matrix
        Symmetric.  Only positive definite matrices use Cholesky.
    check : bool
        Verify the Cholesky factor on a random right-hand side and fall back to a
        regularised LU when it is not accurate (semi-definite or indefinite ``A``).
    solves : {"many", "few"}
        What the factor is for: many back-substitutions (cholespy) or a few
        (cvxopt's CHOLMOD, faster to factor; cholespy when cvxopt is missing).
        See the module's docstring.

    Returns
    -------
    Factor

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> A = sp.diags([2.0, 3.0, 4.0]).tocsr()
    >>> factorize(A).solve([2.0, 3.0, 4.0])
    array([1., 1., 1.])
    """
    A = sp.csr_matrix(A, dtype=np.float64)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"matrix must be square, got {A.shape}")
    if solves not in ("many", "few"):
        raise ValueError(f"solves must be 'many' or 'few', got {solves!r}")
    if solves == "few" and n > 0:
        factor = _cholmod(A)
        if factor is not None and (not check or _accurate(A, factor)):
            return factor
    if CholeskySolverD is not None and n > 0:
        coo = A.tocoo()
        try:
            solver = CholeskySolverD(n, coo.row.astype(np.int32),
                                     coo.col.astype(np.int32), coo.data, MatrixType.COO)
        except ValueError:  # "Matrix is not positive definite!"
            solver = None
        if solver is not None:
            factor = Factor(n, "cholesky", solver)
            if not check or _accurate(A, factor):
                return factor
    # Semi-definite systems (a free translation, an unused vertex): a tiny ridge
    # relative to the diagonal makes them solvable and barely changes the answer.
    ridge = 1e-10 * max(float(abs(A.diagonal()).max(initial=0.0)), 1e-300)
    import scipy.sparse.linalg as spla      # the rare fallback: its import costs ~0.05 s
    lu = spla.splu((A + ridge * sp.identity(n, format="csr")).tocsc())
    return Factor(n, "lu", lu)


def _canonical_csr(A) -> sp.csr_matrix:
    """``A`` as float64 csr with sorted, unique indices (the pattern compared and
    refilled by :class:`_LowerPattern`)."""
    A = sp.csr_matrix(A, dtype=np.float64)
    if not A.has_canonical_format:
        A = A.copy()
        A.sum_duplicates()
    return A


class _LowerPattern:
    """The lower triangle of a symmetric csr pattern as a cvxopt ``spmatrix``,
    refilled in place from any matrix of the same pattern.

    CHOLMOD reads only the lower triangle.  Column-major order of the lower triangle
    is row-major order of the upper one, so a refill is one gather of the csr
    values (``spmatrix.V`` is assignable: same pattern, new values), where building
    the ``spmatrix`` anew sorts triplets — more than the factorisation itself on the
    ICP's graph blocks.
    """

    def __init__(self, A: sp.csr_matrix):
        n = A.shape[0]
        self.indptr, self.indices = A.indptr.copy(), A.indices.copy()
        rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(A.indptr))
        self.upper = np.flatnonzero(A.indices >= rows)    # (entries in csr order)
        # the lower triangle's (row, column) = the upper one's (column, row)
        self.lower = cvxopt_spmatrix(A.data[self.upper],
                                     A.indices[self.upper].astype(np.int64),
                                     rows[self.upper], A.shape)

    def matches(self, A: sp.csr_matrix) -> bool:
        """Whether canonical csr ``A`` has exactly this pattern."""
        return (np.array_equal(A.indptr, self.indptr)
                and np.array_equal(A.indices, self.indices))

    def refill(self, A: sp.csr_matrix) -> None:
        """The values of canonical csr ``A`` (of this pattern) into :attr:`lower`."""
        self.lower.V = cvxopt_matrix(A.data[self.upper])


def _cholmod(A) -> Factor | None:
    """CHOLMOD's supernodal Cholesky through cvxopt, or None (no cvxopt, or ``A``
    not positive definite); the factor keeps its pattern for :func:`refactorize`."""
    if cholmod is None:  # pragma: no cover - cvxopt is a dependency
        return None
    pattern = _LowerPattern(_canonical_csr(A))
    try:
        F = cholmod.symbolic(pattern.lower)
        cholmod.numeric(pattern.lower, F)
    except (ArithmeticError, ValueError):  # not positive definite
        return None
    return Factor(A.shape[0], "cholmod", F, pattern)


def _accurate(A, factor: Factor) -> bool:
    rng = np.random.default_rng(0)
    x = rng.standard_normal(A.shape[0])
    b = A @ x
    with np.errstate(all="ignore"):
        y = factor.solve(b)
        if not np.all(np.isfinite(y)):
            return False
        return float(np.linalg.norm(A @ y - b)) <= 1e-6 * max(float(np.linalg.norm(b)),
                                                               1e-300)


def solve_spd(A, b) -> np.ndarray:
    """One-shot :func:`factorize` then :meth:`Factor.solve`."""
    return factorize(A).solve(b)
