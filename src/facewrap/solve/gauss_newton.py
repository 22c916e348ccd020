"""Damped Gauss–Newton steps for stacked weighted least-squares terms.

:func:`gauss_newton_step` is the one linear solve of every ICP iteration: it
weights and stacks the terms' residuals and Jacobians
(:class:`~facewrap.solve.BlockJacobian`: sparse graph columns beside dense blend
columns) and picks a solve by size.  Small systems are assembled densely from
:func:`gram_matrix` (Jacobian rows come in triples sharing their columns, so
``JᵀJ`` is a sum of small dense blocks); graphs of a few hundred nodes with blend
columns take a sparse Cholesky of the graph block and a dense Schur complement of
the rest; large systems are one sparse product, solved by preconditioned
conjugate gradients (:mod:`.krylov`) or a factorisation (:mod:`.factor`).
:func:`normal_equations` assembles a system once so that a Levenberg–Marquardt
retry with more damping only solves it again.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from facewrap.solve.block_jacobian import BlockJacobian
from facewrap.solve.factor import factorize, refactorize
from facewrap.solve.krylov import block_jacobi, conjugate_gradients

__all__ = ["gauss_newton_step", "normal_equations", "NormalEquations", "gram_matrix",
           "sparse_gram_matrix", "DENSE_LIMIT", "BORDERED_FROM"]


#: systems with at most this many unknowns are solved directly: assembled
#: densely up to :data:`BORDERED_FROM` sparse unknowns, above that by a sparse
#: Cholesky of the sparse block and a dense Schur complement of the rest
DENSE_LIMIT = 2500
#: (with blend columns beside a graph of a few hundred nodes the bordered solve
#: is faster; at a few dozen nodes the dense one is as fast: docs/benchmarks.md)
BORDERED_FROM = 600


#: unknowns per graph node: vertex rows whose columns come in whole runs of this
#: many take the block-sparse Gram product
_NODE_BLOCK = 6


def _row_triples(S):
    """``(vals (r, 3, q), cols (r, q))`` when the rows of ``S`` come in triples
    sharing their ``q`` columns (the coordinates of a vertex or of a graph
    edge), else None."""
    R = S.shape[0]
    q = np.diff(S.indptr)
    if not (R and R % 3 == 0 and q[0] > 0 and (q == q[0]).all()):
        return None
    idx = S.indices.reshape(R // 3, 3, q[0])
    if not (idx == idx[:, :1]).all():
        return None
    return S.data.reshape(R // 3, 3, q[0]), idx[:, 0, :]


def _node_blocks(cols, P: int, b: int = _NODE_BLOCK):
    """(r, k) block-column ids when every row's columns are ``k ≥ 2`` aligned
    runs of ``b`` (a vertex skinned by k graph nodes), else None."""
    q = cols.shape[1]
    if P % b or q % b or q < 2 * b:
        return None
    runs = cols.reshape(len(cols), -1, b)
    if not ((runs[..., :1] % b == 0).all() and (runs == runs[..., :1] + np.arange(b)).all()):
        return None
    return runs[..., 0] // b


def gram_matrix(S) -> np.ndarray:
    """Dense ``SᵀS`` of a sparse matrix.

    Jacobian rows come in triples (the three coordinates of a vertex, or of a
    graph edge) that share their columns; then ``SᵀS`` is a sum of small dense
    blocks, accumulated with one ``bincount`` — several times faster than a
    sparse-sparse product — or, for vertex rows spanning several graph nodes, a
    block-sparse product (faster again).  Other matrices take the sparse
    product.

    Parameters
    ----------
    S : (r, P) scipy.sparse matrix

    Returns
    -------
    (P, P) float64

    Examples
    --------
    >>> S = sp.csr_matrix(np.arange(12.0).reshape(3, 4))
    >>> bool(np.allclose(gram_matrix(S), S.toarray().T @ S.toarray()))
    True
    """
    S = sp.csr_matrix(S)
    P = S.shape[1]
    triples = _row_triples(S)
    if triples is None:
        return (S.T @ S).toarray()
    vals, cols = triples
    blocks = _node_blocks(cols, P)
    if blocks is not None:
        return _block_gram(vals, blocks, _NODE_BLOCK, P).toarray()
    G = np.matmul(vals.transpose(0, 2, 1), vals)
    flat = (cols[:, :, None] * P + cols[:, None, :]).ravel()
    return np.bincount(flat, G.ravel(), minlength=P * P).reshape(P, P)


def _block_gram(vals, blocks, b: int, P: int) -> sp.bsr_matrix:
    """``SᵀS`` (BSR) for rows in triples whose columns are whole ``b``-blocks:
    ``vals`` (r, 3, k·b), ``blocks`` (r, k) block-column ids."""
    r, k = blocks.shape
    # (block columns need not be sorted within a row: the product accumulates)
    data = vals.reshape(r, 3, k, b).transpose(0, 2, 1, 3)          # (r, k, 3, b)
    B = sp.bsr_matrix((data.reshape(r * k, 3, b), blocks.ravel(),
                       np.arange(0, r * k + 1, k)), shape=(3 * r, P))
    return B.T.tobsr(blocksize=(b, 3)) @ B


def sparse_gram_matrix(S) -> sp.csr_matrix:
    """Sparse ``SᵀS``, by blocks where the rows allow it (see :func:`gram_matrix`).

    Parameters
    ----------
    S : (r, P) scipy.sparse matrix

    Returns
    -------
    (P, P) scipy.sparse.csr_matrix
    """
    S = sp.csr_matrix(S)
    triples = _row_triples(S)
    if triples is not None:
        blocks = _node_blocks(triples[1], S.shape[1])
        if blocks is not None:
            return _block_gram(triples[0], blocks, _NODE_BLOCK, S.shape[1]).tocsr()
    return (S.T.tocsr() @ S).tocsr()


class NormalEquations:
    """The damped normal equations of stacked weighted terms, assembled once.

    ``JᵀWJ`` and ``JᵀWr`` do not depend on the damping: a Levenberg–Marquardt
    iteration that retries a rejected step with more damping only changes the
    diagonal, so it solves these again (:meth:`step`) instead of re-assembling
    them.  Build with :func:`normal_equations`.

    Attributes
    ----------
    n_params : int
        Unknowns P.
    energy : float
        ``Σ_t Σ_r w_r r_r²`` at the linearisation point (the objective before the
        step, from the very residuals the step uses).
    path : {"zero", "dense", "bordered", "sparse"}
        How the system is solved (see :func:`gauss_newton_step`).
    factor : Factor or None
        The bordered path's last factor (None before a bordered :meth:`step`): give
        it to the next iteration's :func:`normal_equations` as ``analysis``.
    """

    def __init__(self, n_params: int, energy: float, path: str, parts: dict,
                 method: str = "cg", block: int = 1, max_cg: int = 400,
                 cg_rtol: float = 1e-3, analysis=None):
        self.n_params = n_params
        self.energy = energy
        self.path = path
        self._parts = parts
        self._method = method
        self._block = block
        self._max_cg = max_cg
        self._cg_rtol = cg_rtol
        # the bordered path's factor: its symbolic analysis is reused by the next
        # factorisation of the same pattern (another damping, the next iteration)
        self._factor = analysis

    @property
    def factor(self):
        return self._factor

    def step(self, damping: float = 0.0, x0=None) -> np.ndarray:
        """The step ``δ`` (P,) minimising the linearised energy plus
        ``damping · δᵀ diag(JᵀWJ) δ``.

        Parameters
        ----------
        damping : float
        x0 : (P,) float, optional
            Starting guess for conjugate gradients (the sparse path).
        """
        if self.path == "zero":
            return np.zeros(self.n_params)
        if self.path == "dense":
            return _dense_solve(self._parts["H"], self._parts["g"], damping)
        if self.path == "bordered":
            return self._bordered_solve(damping)
        return self._sparse_solve(damping, x0)

    def _bordered_solve(self, damping: float) -> np.ndarray:
        """``[A B; Bᵀ C]`` by one sparse Cholesky of ``A`` and the Schur complement
        ``C − Bᵀ A⁻¹ B`` (K×K, dense).  For graphs of a few hundred nodes ``A`` is
        only a few per cent full, so this beats assembling and factoring densely.
        A second damping has the pattern of the first, and so, mostly, has the next
        ICP iteration: their symbolic analysis is reused."""
        A, g1, Bm, C, g2 = (self._parts[k] for k in ("A", "g1", "B", "C", "g2"))
        K = C.shape[0]
        dA, dC = A.diagonal(), np.diag(C).copy()
        floor = 1e-9 * max(float(dA.max(initial=0.0)), float(dC.max(initial=0.0)), 1e-300)
        Ad = (A + sp.diags(damping * dA + floor)).tocsr()
        Cd = C.copy()
        Cd[np.diag_indices(K)] += damping * dC + floor
        self._factor = (factorize(Ad, check=False, solves="few") if self._factor is None
                        else refactorize(self._factor, Ad, check=False))
        halves = self._half_solves(Ad, g1, Bm, Cd, g2)
        if halves is not None:
            return halves
        X = self._factor.solve(np.column_stack([g1, Bm]))
        Ainv_g, Ainv_B = X[:, 0], X[:, 1:]
        if K:
            x2 = _solve_small(Cd - Bm.T @ Ainv_B, g2 - Bm.T @ Ainv_g)
            x1 = Ainv_g - Ainv_B @ x2
        else:
            x1, x2 = Ainv_g, np.zeros(0)
        return -np.concatenate([x1, x2])

    def _half_solves(self, Ad, g1, Bm, Cd, g2):
        """The bordered step from a forward solve of ``[g1 B]`` and one backward
        solve: ``C − Bᵀ A⁻¹ B = C − YᵀY`` with ``Y = L⁻¹ P B`` (half the triangular
        work of solving for ``A⁻¹ B``, K+1 columns).  None when the factor does not
        split its solves, or the answer does not solve the system (then the caller
        solves it whole)."""
        Y = self._factor.forward(np.column_stack([g1, Bm]))
        if Y is None or not Bm.shape[1]:
            return None
        y_g, Y_B = Y[:, 0], Y[:, 1:]
        x2 = _solve_small(Cd - Y_B.T @ Y_B, g2 - Y_B.T @ y_g)
        x1 = self._factor.backward(y_g - Y_B @ x2)
        # the first block row, A x1 + B x2 = g1, checks the halves (a matrix-vector
        # product: cheap beside the solves)
        scale = max(float(np.linalg.norm(g1)) + float(np.linalg.norm(Bm @ x2)), 1e-300)
        if not float(np.linalg.norm(Ad @ x1 + Bm @ x2 - g1)) <= 1e-8 * scale:
            return None
        return -np.concatenate([x1, x2])

    def _sparse_solve(self, damping: float, x0) -> np.ndarray:
        """One sparse system: conjugate gradients or a factorisation."""
        H, g = self._parts["H"], self._parts["g"]
        d = H.diagonal()
        # damping keeps the system definite where a parameter sees no data (a node
        # in a hole): its diagonal floor is relative to the largest diagonal entry
        floor = 1e-9 * max(float(d.max(initial=0.0)), 1e-300)
        Hd = (H + sp.diags(damping * d + floor)).tocsr()
        if self._method in ("cg", "inexact"):
            n_sparse = self._parts["n_sparse"]
            M = block_jacobi(Hd, self._block,
                             n_blocked=n_sparse - n_sparse % self._block)
            x, _, converged = conjugate_gradients(Hd, -g, x0, M, rtol=self._cg_rtol,
                                                  max_iterations=self._max_cg)
            if np.all(np.isfinite(x)) and (converged or self._method == "inexact"):
                return x
        return -factorize(Hd, check=False, solves="few").solve(g)


def _bordered_parts(S_rows, D_rows, b_rows) -> dict:
    """The blocks of the bordered system: sparse ``A = SᵀS``, ``B = SᵀD``,
    dense ``C = DᵀD`` and the gradients ``g1 = Sᵀb``, ``g2 = Dᵀb``, summed term
    by term (the terms' rows are never stacked)."""
    n_sparse, K = S_rows[0].shape[1], D_rows[0].shape[1]
    A = None
    g1, Bm = np.zeros(n_sparse), np.zeros((n_sparse, K))
    C, g2 = np.zeros((K, K)), np.zeros(K)
    for S, D, b in zip(S_rows, D_rows, b_rows):
        if S.nnz:
            gram = sparse_gram_matrix(S)
            A = gram if A is None else A + gram
            St = S.T
            g1 += St @ b
            if K:
                Bm += St @ D
        if K:
            C += D.T @ D
            g2 += D.T @ b
    if A is None:
        A = sp.csr_matrix((n_sparse, n_sparse))
    return {"A": A, "g1": g1, "B": Bm, "C": C, "g2": g2}


def _dense_parts(S_rows, D_rows, b_rows) -> dict:
    """``H = JᵀJ`` and ``g = Jᵀb`` assembled densely (small parameter counts),
    term by term."""
    n_sparse, K = S_rows[0].shape[1], D_rows[0].shape[1]
    H = np.zeros((n_sparse + K, n_sparse + K))
    g = np.zeros(n_sparse + K)
    for S, D, b in zip(S_rows, D_rows, b_rows):
        if S.nnz:
            H[:n_sparse, :n_sparse] += gram_matrix(S)
            g[:n_sparse] += S.T @ b
            if K:
                H[:n_sparse, n_sparse:] += S.T @ D
        if K:
            H[n_sparse:, n_sparse:] += D.T @ D
            g[n_sparse:] += D.T @ b
    if K:
        H[n_sparse:, :n_sparse] = H[:n_sparse, n_sparse:].T
    return {"H": H, "g": g}


def _solve_small(M, rhs) -> np.ndarray:
    """A small dense system (a Schur complement); least squares if singular."""
    try:
        return np.linalg.solve(M, rhs)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(M, rhs, rcond=None)[0]


def _dense_solve(H, g, damping: float) -> np.ndarray:
    """The damped dense system by Cholesky (least squares if it is singular)."""
    P = len(g)
    d = np.diag(H).copy()
    floor = 1e-9 * max(float(d.max(initial=0.0)), 1e-300)
    Hd = H.copy()
    Hd[np.diag_indices(P)] += damping * d + floor
    try:
        return -sla.cho_solve(sla.cho_factor(Hd, lower=True, check_finite=False), g,
                              check_finite=False)
    except np.linalg.LinAlgError:
        return -np.linalg.lstsq(Hd, g, rcond=None)[0]


def _sparse_parts(S_rows, D_rows, b_rows) -> dict:
    """One stacked least-squares system: a single sparse product for the sparse
    block, BLAS for the dense (blend) block."""
    S = sp.vstack(S_rows, format="csr")
    D, b = np.vstack(D_rows), np.concatenate(b_rows)
    St = S.T.tocsr()
    H = (St @ S).tocsr()
    g = St @ b
    if D.shape[1]:
        Hsd = sp.csr_matrix(St @ D)
        H = sp.bmat([[H, Hsd], [Hsd.T, sp.csr_matrix(D.T @ D)]], format="csr")
        g = np.concatenate([g, D.T @ b])
    return {"H": H, "g": np.asarray(g, dtype=np.float64), "n_sparse": S.shape[1]}


def normal_equations(terms, n_params: int | None = None, method: str = "cg",
                     block: int = 1, max_cg: int = 400,
                     cg_rtol: float = 1e-3, analysis=None) -> NormalEquations:
    """Assemble the normal equations of weighted terms once, for any damping.

    Parameters are those of :func:`gauss_newton_step` (less ``damping`` and
    ``x0``, which go to :meth:`NormalEquations.step`), and:

    analysis : Factor, optional
        An earlier system's :attr:`NormalEquations.factor`: the bordered path
        reuses its ordering and symbolic analysis where the sparse block has the
        same pattern (:func:`~facewrap.solve.refactorize`), and uses it up.

    Returns
    -------
    NormalEquations

    Examples
    --------
    >>> J = sp.csr_matrix(np.eye(2))
    >>> system = normal_equations([(1.0, np.array([1.0, -2.0]), J, None)])
    >>> system.energy, system.step(0.0).round(6).tolist()
    (5.0, [-1.0, 2.0])
    >>> bool(np.abs(system.step(1.0)).max() < 1.01)   # more damping, a shorter step
    True
    """
    S_rows, D_rows, b_rows = [], [], []
    for weight, r, J, rw in terms:
        J = BlockJacobian.of(J)
        if weight == 0 or J.shape[0] == 0:
            continue
        w = np.full(len(r), float(weight)) if rw is None else weight * np.asarray(rw)
        sw = np.sqrt(w)
        Jw = J.scale_rows(sw)
        S_rows.append(Jw.sparse)
        D_rows.append(Jw.dense)
        b_rows.append(sw * np.asarray(r, dtype=np.float64))
    options = dict(method=method, block=block, max_cg=max_cg, cg_rtol=cg_rtol,
                   analysis=analysis)
    if not S_rows:
        return NormalEquations(n_params or 0, 0.0, "zero", {}, **options)
    n_sparse = S_rows[0].shape[1]
    P = n_sparse + D_rows[0].shape[1]
    if P <= DENSE_LIMIT:
        path = "bordered" if n_sparse >= BORDERED_FROM else "dense"
        parts = (_bordered_parts if path == "bordered" else _dense_parts)(S_rows, D_rows,
                                                                          b_rows)
    else:
        path, parts = "sparse", _sparse_parts(S_rows, D_rows, b_rows)
    energy = float(sum(b @ b for b in b_rows))
    return NormalEquations(P, energy, path, parts, **options)


def gauss_newton_step(terms, damping: float = 0.0, n_params: int | None = None,
                      method: str = "cg", x0=None, block: int = 1,
                      max_cg: int = 400, cg_rtol: float = 1e-3):
    """One damped Gauss–Newton (Levenberg–Marquardt) step for weighted terms.

    Minimises ``Σ_t Σ_r w_r (r_r + J_r δ)²`` plus ``damping · δᵀ diag(H) δ``
    (one-shot :func:`normal_equations` then :meth:`NormalEquations.step`; keep
    the system to retry with other dampings).

    Parameters
    ----------
    terms : iterable of (weight, r, J, row_weights)
        ``weight`` a float, ``r`` (k,), ``J`` (k, P) sparse, ``row_weights`` (k,)
        or None (IRLS weights).
    damping : float
        Levenberg–Marquardt factor on the diagonal of ``JᵀWJ``.
    n_params : int, optional
        P, for the zero step when no term has rows.
    method : {"cg", "inexact", "direct"}
        For systems of more than :data:`DENSE_LIMIT` unknowns (smaller ones are
        solved directly by Cholesky, whatever ``method`` says: dense for small
        ones, sparse + Schur complement (:data:`BORDERED_FROM`) for graphs of
        100+ nodes).  "cg": conjugate gradients with a block-Jacobi
        preconditioner, falling back to a direct factorisation if they do not
        converge — a Gauss–Newton step does not need a solve to machine
        precision, and on deformation-graph systems CG is several times faster
        than a fresh sparse Cholesky.  "inexact": CG capped at ``max_cg``
        iterations, its result used as it is (the caller's Levenberg–Marquardt
        test rejects a bad step); for large, Laplacian-like systems where a
        factorisation is slow.  "direct": always factor.
    block : int
        Block size of the preconditioner (unknowns per node / vertex).
    max_cg, cg_rtol : int, float
        CG iteration cap and relative residual tolerance.  An inexact
        Gauss–Newton step (residual reduced 1000×) is as good as an exact one
        for ICP, whose correspondences change after every step anyway.
    x0 : (P,) float, optional
        Starting guess for CG (e.g. the previous step).

    Returns
    -------
    delta : (P,) float64

    Examples
    --------
    >>> J = sp.csr_matrix(np.eye(2))
    >>> gauss_newton_step([(1.0, np.array([1.0, -2.0]), J, None)]).round(6).tolist()
    [-1.0, 2.0]
    """
    return normal_equations(terms, n_params, method=method, block=block, max_cg=max_cg,
                            cg_rtol=cg_rtol).step(damping, x0)
