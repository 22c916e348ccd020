"""Sparse linear solves shared by every fitting and transfer step.

Most of facewrap's work ends in a sparse symmetric positive definite system
``A x = b`` (normal equations of a least-squares energy).  :func:`factorize`
factors ``A`` once and returns a :class:`Factor` whose :meth:`Factor.solve` is a
cheap back-substitution for any number of right-hand sides — the "set up once,
solve many times" pattern (one factor, three coordinates; one factor, many poses).

Two Cholesky back ends (both wheels), chosen by what the factor is for:

* ``solves="many"`` (default): cholespy.  Its back-substitution is fast (about 7×
  SuperLU's on a 9.4k-vertex bi-Laplacian; 3–4× CHOLMOD-through-cvxopt's on the
  transfer systems here), its factorisation slow (0.79 s at 28k unknowns).
  For factors used for many solves: transfer poses, avatar shapes.
* ``solves="few"``: CHOLMOD's supernodal factorisation from cvxopt, with
  OpenBLAS: 5–6× faster to factor (0.13 s at 28k unknowns) and slower to
  back-substitute.  For a factor per step: correspondence steps, ICP iterations,
  local repairs.

Where the matrix is not positive definite (an energy with a null space, e.g. no
translation fixed) both refuse it (cholespy's CHOLMOD prints a warning on stderr);
the factor is also checked on a random right-hand side; either way the solve falls
back to SuperLU on a slightly regularised matrix, which always gives a finite
answer.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

__all__ = ["Factor", "factorize", "refactorize", "solve_spd"]


class Factor:
    """A factored sparse SPD matrix; call :meth:`solve` as often as needed.

    Build with :func:`factorize`.  Attributes: ``n`` (size), ``method``
    ("cholesky": cholespy, "cholmod": cvxopt's CHOLMOD, or "lu": SuperLU).
    """

    def __init__(self, n: int, method: str, solver):
        self.n = n
        self.method = method
        self._solver = solver

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
            from cvxopt import cholmod, matrix
            x = matrix(np.asfortranarray(b.reshape(self.n, -1)))
            cholmod.solve(self._solver, x)
            return np.array(x).reshape(b.shape)
        return self._solver.solve(b)


def refactorize(factor: Factor, A, *, check: bool = True) -> Factor:
    """Factor ``A``, which has the sparsity pattern of the matrix ``factor`` was
    made from, reusing its ordering and symbolic analysis where the back end allows
    (CHOLMOD: a third of the factorisation time at 28k unknowns).

    ``factor`` is used up (its storage may hold the new factor); use the returned
    one.  Any other factor, or a pattern CHOLMOD does not accept, is factored
    afresh with ``solves="few"``.
    """
    if factor.method == "cholmod":
        A = sp.csr_matrix(A, dtype=np.float64)
        # refilled in place: ``factor`` now holds the factor of ``A``
        if (_cholmod(A, analysed=factor._solver) is not None
                and (not check or _accurate(A, factor))):
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
    try:
        from cholespy import CholeskySolverD, MatrixType
    except ImportError:  # pragma: no cover - cholespy is a dependency
        CholeskySolverD = None
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
    lu = spla.splu((A + ridge * sp.identity(n, format="csr")).tocsc())
    return Factor(n, "lu", lu)


def _cholmod(A, analysed=None) -> Factor | None:
    """CHOLMOD's supernodal Cholesky through cvxopt, or None (no cvxopt, ``A`` not
    positive definite, or not of the pattern ``analysed`` -- a factor's symbolic
    analysis, refilled in place -- was made for)."""
    try:
        from cvxopt import cholmod
    except ImportError:  # pragma: no cover - cvxopt is a dependency
        return None
    M = _lower_triangle(A)
    try:
        F = cholmod.symbolic(M) if analysed is None else analysed
        cholmod.numeric(M, F)
    except (ArithmeticError, ValueError):  # not positive definite / other pattern
        return None
    return Factor(A.shape[0], "cholmod", F)


def _lower_triangle(A):
    """The lower triangle of a symmetric csr matrix as a cvxopt ``spmatrix``: all
    CHOLMOD reads, and half the entries to convert (the conversion costs more
    than the factorisation on the ICP's graph blocks)."""
    from cvxopt import spmatrix
    coo = sp.tril(A, format="coo")
    return spmatrix(coo.data, coo.row.astype(np.int64), coo.col.astype(np.int64),
                    A.shape)


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


#: systems with at most this many unknowns are solved directly: assembled
#: densely up to :data:`BORDERED_FROM` sparse unknowns, above that by a sparse
#: Cholesky of the sparse block and a dense Schur complement of the rest
DENSE_LIMIT = 2500
#: (ICT face, 195 nodes + 53 shapes: 1223 unknowns, the bordered solve saved
#: 0.35 s of 2.2 s of ICP; at 64 nodes the dense one is as fast)
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


def _gram(S) -> np.ndarray:
    """Dense ``SᵀS`` of a sparse matrix.

    Jacobian rows come in triples (the three coordinates of a vertex, or of a
    graph edge) that share their columns; then ``SᵀS`` is a sum of small dense
    blocks, accumulated with one ``bincount`` — several times faster than a
    sparse-sparse product — or, for vertex rows spanning several graph nodes, a
    block-sparse product (~2x faster again).  Other matrices take the sparse
    product.
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


def _sparse_gram(S) -> sp.csr_matrix:
    """Sparse ``SᵀS``, by blocks where the rows allow it (see :func:`_gram`)."""
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
    nodes ``A`` is ~7 % full, so this beats assembling and factoring densely."""
    n_sparse, K = S_rows[0].shape[1], D.shape[1]
    A = sp.csr_matrix((n_sparse, n_sparse))
    g1 = np.zeros(n_sparse)
    Bm = np.zeros((n_sparse, K))
    start = 0
    for S in S_rows:
        rows = slice(start, start + S.shape[0])
        start += S.shape[0]
        if S.nnz:
            A = A + _sparse_gram(S)
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
    import scipy.linalg as sla
    n_sparse = S_rows[0].shape[1]
    P = n_sparse + D.shape[1]
    H = np.zeros((P, P))
    g = np.zeros(P)
    start = 0
    for S in S_rows:
        rows = slice(start, start + S.shape[0])
        start += S.shape[0]
        if S.nnz:
            H[:n_sparse, :n_sparse] += _gram(S)
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
        systems CG is ~5× faster than a fresh sparse Cholesky (whose symbolic
        analysis cannot be reused through cholespy).  "inexact": CG capped at
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
    from facewrap.solve.block_jacobian import BlockJacobian
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
        x, info = spla.cg(H, -g, x0=x0, rtol=cg_rtol, maxiter=max_cg, M=M)
        if np.all(np.isfinite(x)) and (info == 0 or method == "inexact"):
            return x
    return -factorize(H, check=False, solves="few").solve(g)
