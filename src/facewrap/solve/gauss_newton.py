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
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

from facewrap.solve.block_jacobian import BlockJacobian
from facewrap.solve.factor import factorize
from facewrap.solve.krylov import block_jacobi, conjugate_gradients

__all__ = ["gauss_newton_step", "gram_matrix", "sparse_gram_matrix", "DENSE_LIMIT",
           "BORDERED_FROM"]


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


def _bordered_step(S_rows, D, b, damping: float) -> np.ndarray:
    """Gauss–Newton step of a sparse system with a few dense columns (blend
    weights): ``[A B; Bᵀ C]`` solved by one sparse Cholesky of ``A`` and the
    Schur complement ``C − Bᵀ A⁻¹ B`` (K×K, dense).  For graphs of a few hundred
    nodes ``A`` is only a few per cent full, so this beats assembling and
    factoring densely."""
    n_sparse, K = S_rows[0].shape[1], D.shape[1]
    A = sp.csr_matrix((n_sparse, n_sparse))
    g1 = np.zeros(n_sparse)
    Bm = np.zeros((n_sparse, K))
    start = 0
    for S in S_rows:
        rows = slice(start, start + S.shape[0])
        start += S.shape[0]
        if S.nnz:
            A = A + sparse_gram_matrix(S)
            St = S.T
            g1 += St @ b[rows]
            if K:
                Bm += St @ D[rows]
    C, g2 = D.T @ D, D.T @ b
    dA, dC = A.diagonal(), np.diag(C).copy()
    floor = 1e-9 * max(float(dA.max(initial=0.0)), float(dC.max(initial=0.0)), 1e-300)
    A = (A + sp.diags(damping * dA + floor)).tocsr()
    C[np.diag_indices(K)] += damping * dC + floor
    X = factorize(A, check=False, solves="few").solve(np.column_stack([g1, Bm]))
    Ainv_g, Ainv_B = X[:, 0], X[:, 1:]
    if K:
        Sc, rhs = C - Bm.T @ Ainv_B, g2 - Bm.T @ Ainv_g
        try:
            x2 = np.linalg.solve(Sc, rhs)
        except np.linalg.LinAlgError:
            x2 = np.linalg.lstsq(Sc, rhs, rcond=None)[0]
        x1 = Ainv_g - Ainv_B @ x2
    else:
        x1, x2 = Ainv_g, np.zeros(0)
    return -np.concatenate([x1, x2])


def _dense_step(S_rows, D, b, damping: float) -> np.ndarray:
    """Gauss–Newton step assembled and solved densely (small parameter counts)."""
    n_sparse = S_rows[0].shape[1]
    P = n_sparse + D.shape[1]
    H = np.zeros((P, P))
    g = np.zeros(P)
    start = 0
    for S in S_rows:
        rows = slice(start, start + S.shape[0])
        start += S.shape[0]
        if S.nnz:
            H[:n_sparse, :n_sparse] += gram_matrix(S)
            g[:n_sparse] += S.T @ b[rows]
            if D.shape[1]:
                H[:n_sparse, n_sparse:] += S.T @ D[rows]
    if D.shape[1]:
        H[n_sparse:, :n_sparse] = H[:n_sparse, n_sparse:].T
        H[n_sparse:, n_sparse:] = D.T @ D
        g[n_sparse:] = D.T @ b
    d = np.diag(H).copy()
    floor = 1e-9 * max(float(d.max(initial=0.0)), 1e-300)
    H[np.diag_indices(P)] += damping * d + floor
    try:
        return -sla.cho_solve(sla.cho_factor(H, lower=True, check_finite=False), g,
                              check_finite=False)
    except np.linalg.LinAlgError:
        return -np.linalg.lstsq(H, g, rcond=None)[0]


def gauss_newton_step(terms, damping: float = 0.0, n_params: int | None = None,
                      method: str = "cg", x0=None, block: int = 1,
                      max_cg: int = 400, cg_rtol: float = 1e-3):
    """One damped Gauss–Newton (Levenberg–Marquardt) step for weighted terms.

    Minimises ``Σ_t Σ_r w_r (r_r + J_r δ)²`` plus ``damping · δᵀ diag(H) δ``.

    Parameters
    ----------
    terms : iterable of (weight, r, J, row_weights)
        ``weight`` a float, ``r`` (k,), ``J`` (k, P) sparse, ``row_weights`` (k,)
        or None (IRLS weights).
    damping : float
        Levenberg–Marquardt factor on the diagonal of ``JᵀWJ``.
    Systems of at most :data:`DENSE_LIMIT` unknowns (graphs of a few hundred
    nodes, blendshapes, poses) are solved directly by Cholesky, whatever
    ``method`` says: dense for small ones, sparse + Schur complement
    (:data:`BORDERED_FROM`) for graphs of 100+ nodes.

    method : {"cg", "inexact", "direct"}
        "cg": conjugate gradients with a block-Jacobi preconditioner, falling
        back to a direct factorisation if they do not converge — a Gauss–Newton
        step does not need a solve to machine precision, and on deformation-graph
        systems CG is several times faster than a fresh sparse Cholesky (whose
        symbolic analysis cannot be reused through cholespy).  "inexact": CG capped at
        ``max_cg`` iterations, its result used as it is (the caller's
        Levenberg–Marquardt test rejects a bad step); for large, Laplacian-like
        systems where a factorisation is slow.  "direct": always factor.
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
    if not S_rows:
        return np.zeros(n_params or 0)
    n_sparse = S_rows[0].shape[1]
    D = np.vstack(D_rows)
    b = np.concatenate(b_rows)
    if n_sparse + D.shape[1] <= DENSE_LIMIT:
        if n_sparse >= BORDERED_FROM:
            return _bordered_step(S_rows, D, b, damping)
        return _dense_step(S_rows, D, b, damping)
    # one stacked least-squares system: a single sparse product for the sparse
    # block, BLAS for the dense (blend) block
    S = sp.vstack(S_rows, format="csr")
    St = S.T.tocsr()
    H = (St @ S).tocsr()
    g = St @ b
    if D.shape[1]:
        Hsd = sp.csr_matrix(St @ D)
        H = sp.bmat([[H, Hsd], [Hsd.T, sp.csr_matrix(D.T @ D)]], format="csr")
        g = np.concatenate([g, D.T @ b])
    d = H.diagonal()
    # damping keeps the system definite where a parameter sees no data (a node in
    # a hole): its diagonal floor is relative to the largest diagonal entry
    floor = 1e-9 * max(float(d.max(initial=0.0)), 1e-300)
    H = (H + sp.diags(damping * d + floor)).tocsr()
    g = np.asarray(g, dtype=np.float64)
    if method in ("cg", "inexact"):
        n_sparse = S.shape[1]
        M = block_jacobi(H, block, n_blocked=n_sparse - n_sparse % block)
        x, _, converged = conjugate_gradients(H, -g, x0, M, rtol=cg_rtol,
                                              max_iterations=max_cg)
        if np.all(np.isfinite(x)) and (converged or method == "inexact"):
            return x
    return -factorize(H, check=False, solves="few").solve(g)
