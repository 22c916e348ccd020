"""Quadratic energies with some unknowns fixed: factor once, solve many times.

Minimising ``½ xᵀ A x − bᵀ x`` with ``x[known] = y`` is the linear system
``A_ff x_f = b_f − A_fk y`` over the free unknowns ``f``.  Every "solve with some
unknowns fixed" in facewrap is this system: the projection's smooth extension
(known displacements), the transfer anchor (one vertex kept at rest), the marker
constraints of the correspondence deformation and the flip repair's local
re-solve (everything outside a few vertex rings kept).  :class:`FixedSystem` cuts
the two blocks out once and factors ``A_ff`` once; :meth:`FixedSystem.solve` is one
sparse product and one back-substitution for any number of right-hand sides and
known values (gpytoolbox's ``min_quad_with_fixed_precompute`` is the model).

:func:`split_fixed` gives the two blocks alone, for callers whose free block
changes between solves (the correspondence deformation re-weights it every step).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facewrap.solve.factor import Factor, factorize

__all__ = ["FixedSystem", "split_fixed", "known_mask"]


def known_mask(known, n: int) -> np.ndarray:
    """(n,) bool from a boolean mask or an index list of known unknowns.

    Raises
    ------
    ValueError
        When a mask has the wrong length or an index is out of range.
    """
    k = np.asarray(known)
    if k.dtype == bool:
        if k.shape != (n,):
            raise ValueError(f"known mask must have shape ({n},), got {k.shape}")
        return k.copy()
    ids = k.astype(np.int64).reshape(-1)
    if len(ids) and (ids.min() < -n or ids.max() >= n):
        raise ValueError(f"known index out of range for {n} unknowns")
    mask = np.zeros(n, dtype=bool)
    mask[ids] = True
    return mask


def _columns(rows: sp.csr_matrix, local: np.ndarray, m: int) -> sp.csr_matrix:
    """The columns of ``rows`` with ``local >= 0``, renumbered ``local`` (m of them).

    One pass over the stored entries: cheaper than fancy column indexing when only
    a few rows were taken from a large matrix (the flip repair's region).
    """
    cols = local[rows.indices]
    inside = cols >= 0
    indptr = np.r_[0, np.cumsum(inside)][rows.indptr]
    return sp.csr_matrix((rows.data[inside], cols[inside], indptr),
                         shape=(rows.shape[0], m))


def split_fixed(A, known) -> tuple[np.ndarray, np.ndarray, sp.csr_matrix, sp.csr_matrix]:
    """The free and known blocks of a square sparse matrix.

    Parameters
    ----------
    A : (n, n) scipy.sparse matrix
    known : (n,) bool or (m,) int
        Known unknowns, as a mask or indices.

    Returns
    -------
    free, known : (n - m,) and (m,) int64
        Sorted indices.
    A_ff : (n - m, n - m) scipy.sparse.csr_matrix
        Rows and columns of the free unknowns.
    A_fk : (n - m, m) scipy.sparse.csr_matrix
        Rows of the free unknowns, columns of the known ones: the known values
        enter the free rows' right-hand side as ``− A_fk y``.

    Examples
    --------
    >>> A = sp.csr_matrix(np.array([[2., -1, 0], [-1, 2, -1], [0, -1, 2]]))
    >>> free, known, A_ff, A_fk = split_fixed(A, [1])
    >>> free.tolist(), A_ff.toarray().tolist(), A_fk.toarray().tolist()
    ([0, 2], [[2.0, 0.0], [0.0, 2.0]], [[-1.0], [-1.0]])
    """
    A = sp.csr_matrix(A)
    n = A.shape[0]
    if A.shape != (n, n):
        raise ValueError(f"matrix must be square, got {A.shape}")
    mask = known_mask(known, n)
    return _split_rows(A[np.flatnonzero(~mask)], mask)


def _split_rows(rows: sp.csr_matrix, mask: np.ndarray):
    """:func:`split_fixed` from the free unknowns' rows alone."""
    n = len(mask)
    free, fixed = np.flatnonzero(~mask), np.flatnonzero(mask)
    local_free = np.full(n, -1, dtype=np.int64)
    local_free[free] = np.arange(len(free))
    local_known = np.full(n, -1, dtype=np.int64)
    local_known[fixed] = np.arange(len(fixed))
    return (free, fixed, _columns(rows, local_free, len(free)),
            _columns(rows, local_known, len(fixed)))


class FixedSystem:
    """``min ½ xᵀ A x − bᵀ x`` subject to ``x[known] = y``, factored once.

    Parameters
    ----------
    A : (n, n) scipy.sparse matrix
        Symmetric; positive definite on the free unknowns.
    known : (n,) bool or (m,) int
        Known unknowns, as a mask or indices.
    solves : {"many", "few"}
        What the factor is for (see :func:`~facewrap.solve.factorize`): many
        back-substitutions (poses, shapes) or a few (a local repair, one round of
        an iteration).
    check : bool
        Verify the factor and fall back to a regularised LU when it is not accurate
        (:func:`~facewrap.solve.factorize`).
    ridge : float
        Added to the free block's diagonal, times its largest absolute entry: keeps
        pieces that no known unknown reaches well posed (they stay near 0).

    Attributes
    ----------
    n : int
    free, known : (n - m,) and (m,) int64
        Sorted indices.
    free_block : (n - m, n - m) scipy.sparse.csr_matrix
        ``A_ff`` as factored (ridge included).
    factor : Factor
        Of ``free_block``.

    Examples
    --------
    The 1-D Laplacian with both ends known interpolates linearly:

    >>> L = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()
    >>> system = FixedSystem(L, [0, 4])
    >>> system.solve(None, [0.0, 4.0]).round(12).tolist()
    [0.0, 1.0, 2.0, 3.0, 4.0]
    """

    def __init__(self, A, known, *, solves: str = "many", check: bool = True,
                 ridge: float = 0.0):
        self._setup(split_fixed(A, known), solves, check, ridge)

    @classmethod
    def from_free_rows(cls, rows, known, *, solves: str = "many", check: bool = True,
                       ridge: float = 0.0) -> "FixedSystem":
        """The same system given only the free unknowns' rows of ``A``.

        A local re-solve inside a large system (the flip repair: a few vertex rings
        free, everything else known) builds just these rows.

        Parameters
        ----------
        rows : (n - m, n) scipy.sparse matrix
            Rows of ``A`` for the free unknowns, in increasing order.
        known : (n,) bool
            Known unknowns (``n`` is its length).
        solves, check, ridge
            As for the constructor.

        Returns
        -------
        FixedSystem
        """
        rows = sp.csr_matrix(rows)
        mask = known_mask(known, rows.shape[1])
        if rows.shape[0] != int((~mask).sum()):
            raise ValueError(f"rows has {rows.shape[0]} rows for "
                             f"{int((~mask).sum())} free unknowns")
        system = cls.__new__(cls)
        system._setup(_split_rows(rows, mask), solves, check, ridge)
        return system

    def _setup(self, blocks, solves, check, ridge) -> None:
        self.free, self.known, A_ff, self._A_fk = blocks
        self.n = len(self.free) + len(self.known)
        if ridge:
            scale = float(abs(A_ff).max()) if A_ff.nnz else 0.0
            A_ff = (A_ff + sp.identity(A_ff.shape[0]) * ridge * (scale or 1.0)).tocsr()
        self.free_block = A_ff
        self.factor: Factor = factorize(A_ff, check=check, solves=solves)

    def free_rhs(self, b=None, known_values=None) -> np.ndarray:
        """``b_f − A_fk y``: the right-hand side of the free unknowns.

        Parameters
        ----------
        b : (n,) or (n, k) float64, optional
            Linear term of the energy (rows of known unknowns are ignored);
            default zero.
        known_values : (m,) or (m, k) float64, optional
            ``y`` in the order of :attr:`known`; default zero.

        Returns
        -------
        (n - m,) or (n - m, k) float64
        """
        y = None if known_values is None else np.asarray(known_values, dtype=np.float64)
        if y is not None and y.shape[0] != len(self.known):
            raise ValueError(f"known_values has {y.shape[0]} rows, the system has "
                             f"{len(self.known)} known unknowns")
        if b is None:
            if y is None:
                return np.zeros(len(self.free))
            return -(self._A_fk @ y)
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.n:
            raise ValueError(f"b has {b.shape[0]} rows, the system has {self.n} unknowns")
        if y is None:
            return b[self.free]
        if y.ndim < b.ndim:                     # the same known values for every column
            y = y[:, None]
        return b[self.free] - self._A_fk @ y

    def solve(self, b=None, known_values=None) -> np.ndarray:
        """The minimiser, every unknown included.

        Parameters
        ----------
        b : (n,) or (n, k) float64, optional
            Linear term of the energy, one column per right-hand side; default zero.
        known_values : (m,) or (m, k) float64, optional
            Values of the known unknowns (order of :attr:`known`); default zero.

        Returns
        -------
        x : (n,) or (n, k) float64
            ``x[known] = known_values``; ``k`` columns when either argument has them.
        """
        rhs = self.free_rhs(b, known_values)
        y = np.zeros(len(self.known)) if known_values is None else np.asarray(
            known_values, dtype=np.float64)
        shape = (self.n,) + np.broadcast_shapes(rhs.shape[1:], y.shape[1:])
        if y.ndim < len(shape):
            y = y[:, None]
        x = np.empty(shape)
        if rhs.shape[1:] != shape[1:]:          # zero b, known values with columns
            rhs = np.array(np.broadcast_to(rhs, (len(self.free),) + shape[1:]))
        x[self.free] = self.factor.solve(rhs)
        x[self.known] = y
        return x
