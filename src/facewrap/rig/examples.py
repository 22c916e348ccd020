"""Example-based facial rigging: a person's shapes corrected by scans of their face.

Shapes carried over from a template (:mod:`.personalise`) make a person's face
move as the template's does; their own smile may be stronger on one side, their
jaw may open with a twist.  Given scans of some of their expressions (wrapped in
the template's topology and stabilised, :mod:`.stabilise`), :func:`fit_examples`
follows Li, Weise and Pauly, "Example-based facial rigging" (SIGGRAPH 2010), and
alternates two steps:

(a) **weights**: each example's blend weights in [0, 1] by bounded least squares
    on the vertex positions, optionally held near weights the capture meant
    (the expression the person was asked to make; the paper's γ term);
(b) **shapes**: each shape's deformation gradients ``M_i`` (per triangle, relative
    to the person's neutral) chosen so that the rig reproduces the examples'
    gradients while staying close to the prior's ``M*_i``::

        Σ_j ‖I + Σ_i α_ji (M_i − I) − M(S_j)‖²  +  β Σ_i w_i,t ‖M_i − M*_i‖²

    with ``w_i,t = ((1 + ‖M*_i − I‖) / (κ + ‖M*_i − I‖))^θ`` per triangle: where the
    prior shape does not move the skin, it is held harder (the paper's weighting;
    an example's wrap noise on the forehead does not leak into a smile).

Why gradient space (the paper's choice) rather than positions with a Laplacian
term: the data term of an example then does not see where its skin *is*, only how
each patch is stretched and turned, so a small error of the head pose or a
translation left by the stabilisation does not bend every shape; and the system
splits into one small ``s × s`` solve per triangle (``s`` shapes with weight) and
one Poisson reconstruction of positions from gradients, whose matrix depends on
the neutral only: it is factored once for every shape and every iteration.  A
position-space energy with a Laplacian would couple all shapes through ``αᵀα`` in
one system of ``s·n`` unknowns, refactored whenever the weights change.

The corrections are solved for, not the shapes: a shape no example uses (weight
0 everywhere) keeps the prior exactly, and parts of the mesh no gradient reaches
(a separate eyeball) keep theirs too.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.linalg import cho_factor, solve_triangular

from facewrap.geometry.checks import as_points, as_shape_dict, as_vertex_ids
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import Interval, validate
from facewrap.solve.fixed import FixedSystem
from facewrap.transfer.constraints import tether_weights, untethered_vertices
from facewrap.transfer.deformation import source_gradient_blocks
from facewrap.transfer.gradients import FourthVertexElimination, gradient_operator

__all__ = ["ExampleSettings", "ExampleFit", "fit_examples", "fit_weights"]

#: identity deformation gradient, flattened like ``G @ X`` (row-major 3 x 3)
_IDENTITY = np.eye(3).reshape(9)
#: triangles per batch of the per-triangle solves (memory: batch × s² doubles)
_BATCH_ENTRIES = 4_000_000
#: blend weights below this count as unused (the shape is not corrected)
_ACTIVE = 1e-4


@dataclass(frozen=True)
class ExampleSettings:
    """Settings of :func:`fit_examples` (Li et al. 2010's parameters).

    Attributes
    ----------
    iterations : int
        Rounds of (weights, shapes).
    shape_prior : float
        β: how hard each shape is held at the prior (gradient space; the data term
        of one example at weight 1 counts 1).
    kappa, theta : float
        The per-triangle prior weight ``((1 + d) / (κ + d))^θ`` for a prior shape
        moving the triangle by ``d`` (Frobenius norm of ``M* − I``): 1/κ^θ times
        harder where the prior shape is still.
    weight_prior : float
        γ: how hard the weights are held at the ones the capture meant (when
        given), relative to the mean squared length of the shapes' motion.
    """

    iterations: int = 4
    shape_prior: float = 0.01
    kappa: float = 0.1
    theta: float = 2.0
    weight_prior: float = 0.5
    constraints = {"iterations": Interval(int, 1, 100),
                   "shape_prior": Interval(float, 0, None, closed="neither"),
                   "kappa": Interval(float, 0, None, closed="neither"),
                   "theta": Interval(float, 0, 10),
                   "weight_prior": Interval(float, 0, None)}

    def __post_init__(self):
        validate(self)


@dataclass(frozen=True)
class ExampleFit:
    """Outcome of :func:`fit_examples`.

    Attributes
    ----------
    shapes : dict of str to (n, 3) float64
        The corrected shapes (absolute positions, the neutral's frame).
    weights : list of dict of str to float
        Per example, every shape's weight in [0, 1].
    errors : list of dict
        Per example, ``mean`` and ``p95``: distance (mesh units) of the rig at the
        example's weights to the example, over the example's trusted vertices.
    prior_errors : list of dict
        The same for the prior shapes (their own best weights).
    poses : list of Similarity or None
        Per example, the rigid pose that stabilised it (set by
        :func:`~facewrap.rig.build_rig`; None when the examples came stabilised).
    timings : dict
        Seconds: ``setup`` (gradients, the factorisation), ``weights``, ``shapes``
        and ``total``.
    """

    shapes: dict
    weights: list
    errors: list
    prior_errors: list
    poses: list = field(default_factory=list)
    timings: dict = field(default_factory=dict)


def _least_squares_pieces(C: np.ndarray, B: np.ndarray, prior, gamma: float):
    """The weight fit's normal matrix ``C`` (s, s) and right-hand sides ``B`` (s, k),
    the prior folded in."""
    scale = float(np.mean(np.diag(C))) or 1.0
    reg = np.zeros(len(C))
    if prior is not None:
        reg[:] = gamma * scale
        B = B + reg[:, None] * prior.T
    # a tiny ridge: two shapes that move the same vertices alike stay solvable
    C = C + np.diag(reg + 1e-9 * scale)
    return C, B


def _kept_gram(D: np.ndarray, rows, gram) -> np.ndarray:
    """``Dᵀ D`` over the ``rows`` (bool) of ``D``; from ``gram`` (over all rows, when
    given) less the rows dropped when they are the fewer (what a scan did not
    see: a 53-shape Gram matrix of 28k rows is then one small product, not one
    copy and one large product per target)."""
    if rows is None:
        return D.T @ D if gram is None else gram
    dropped = ~rows
    if gram is not None and 2 * np.count_nonzero(dropped) < len(rows):
        out = D[dropped]
        return gram - out.T @ out
    kept = D[rows]
    return kept.T @ kept


def fit_weights(displacements, targets, *, prior=None, gamma: float = 0.0, rows=None,
                gram=None) -> np.ndarray:
    """Blend weights in [0, 1] that best reproduce each target (bounded least squares).

    Parameters
    ----------
    displacements : (m, s) float
        Each shape's displacement from the neutral, flattened (one column a shape).
    targets : (m, k) float
        Each target's displacement from the neutral, flattened.
    prior : (k, s) float, optional
        Weights the targets are meant to have, held with ``gamma``.
    gamma : float
        Weight of the prior, relative to the shapes' mean squared motion.
    rows : (m,) bool, optional
        The rows that count (a scan's seen vertices); default all.
    gram : (s, s) float, optional
        ``displacementsᵀ displacements`` over all rows, when already at hand (fits
        of many targets, each on its own rows, against the same shapes).

    Returns
    -------
    (k, s) float64

    Examples
    --------
    >>> D = np.eye(4)[:, :2]                       # two shapes of one unit each
    >>> fit_weights(D, np.array([[0.5, 2.0, 0, 0]]).T).round(6).tolist()
    [[0.5, 1.0]]
    >>> fit_weights(D, np.array([[0.5, 2.0, 0, 0]]).T, gram=D.T @ D,
    ...             rows=np.array([True, False, True, True])).round(6).tolist()
    [[0.5, 0.0]]
    """
    D = np.asarray(displacements, dtype=np.float64)
    E = np.asarray(targets, dtype=np.float64)
    P = None if prior is None else np.asarray(prior, dtype=np.float64)
    if rows is not None:
        rows = np.asarray(rows, dtype=bool)
        E = np.where(rows[:, None], E, 0.0)       # the rows dropped add nothing to Dᵀ E
    C, B = _least_squares_pieces(_kept_gram(D, rows, gram), D.T @ E, P, gamma)
    # ‖D α − e‖² + γ‖α − α*‖² = ‖Lᵀ α − L⁻¹ b‖² + const with C = L Lᵀ: an s × s
    # problem per target instead of one of the mesh's size
    L, _ = cho_factor(C, lower=True)
    L = np.tril(L)
    rhs = solve_triangular(L, B, lower=True)                   # (s, k)
    # loaded here: scipy.optimize is 0.16 s of the `facewrap rig` command's start-up,
    # and only a rig with expression scans fits weights
    from scipy.optimize import lsq_linear
    out = np.empty((E.shape[1], D.shape[1]))
    for j in range(E.shape[1]):       # a few examples: one small bounded solve each
        out[j] = lsq_linear(L.T, rhs[:, j], bounds=(0.0, 1.0), method="bvls").x
    return np.clip(out, 0.0, 1.0)


def _prior_weights(prior: np.ndarray, settings: ExampleSettings) -> np.ndarray:
    """β w_i,t for every shape and triangle, from the prior's gradient change."""
    d = np.linalg.norm(prior - _IDENTITY, axis=2)               # (s, t)
    return settings.shape_prior * ((1.0 + d) / (settings.kappa + d)) ** settings.theta


def _gradient_corrections(A, R, trusted, reg) -> np.ndarray:
    """Per triangle ``min Σ_j c_jt ‖Σ_i A_ji Δ_it − R_jt‖² + Σ_i reg_it ‖Δ_it‖²``.

    ``A`` (k, s) weights of the shapes solved for, ``R`` (k, t, 9) the examples'
    residuals under the prior, ``trusted`` (k, t) the data weights, ``reg`` (s, t),
    positive.  Returns Δ (s, t, 9); every triangle's system in one batched solve.

    With fewer examples than shapes (the usual capture: a handful of scans, dozens
    of shapes) each triangle's s × s system ``(D + Ãᵀ Ã) Δ = Ãᵀ R̃`` (``D`` =
    diag(reg), ``Ã`` = C^½ A, ``R̃`` = C^½ R) is solved through its k × k dual,
    ``Δ = D⁻¹ Ãᵀ (I + Ã D⁻¹ Ãᵀ)⁻¹ R̃`` (the push-through identity): the same
    answer, from systems the size of the example count.
    """
    k, s = A.shape
    t = R.shape[1]
    out = np.empty((s, t, 9))
    dual = k < s
    batch = max(1, _BATCH_ENTRIES // max(k * s if dual else s * s, 1))
    eye = np.eye(k)
    for lo in range(0, t, batch):     # batches bound the memory, not a Python loop per triangle
        hi = min(t, lo + batch)
        c = trusted[:, lo:hi].T                                   # (b, k)
        if dual:
            root = np.sqrt(c)[:, :, None]
            At = root * A[None]                                   # (b, k, s)
            AD = At / reg[:, lo:hi].T[:, None, :]                 # Ã D⁻¹
            K = AD @ At.transpose(0, 2, 1) + eye                  # (b, k, k)
            Y = np.linalg.solve(K, root * R[:, lo:hi].transpose(1, 0, 2))
            out[:, lo:hi] = (AD.transpose(0, 2, 1) @ Y).transpose(1, 0, 2)
            continue
        # X[b, i, j] = c_jb A_ji: both sums over the examples are batched matrix
        # products (BLAS), not an einsum over three indices
        X = c[:, None, :] * A.T[None]                            # (b, s, k)
        M = X @ A
        M[:, np.arange(s), np.arange(s)] += reg[:, lo:hi].T
        rhs = X @ R[:, lo:hi].transpose(1, 0, 2)                 # (b, s, 9)
        out[:, lo:hi] = np.linalg.solve(M, rhs).transpose(1, 0, 2)
    return out


class _ShapeGradients:
    """The prior shapes' gradient changes ``M*_i − I`` and prior weights β w_i,t,
    computed for a shape when it is first active: a capture's examples use a
    handful of a rig's 53 shapes (all of them took a third of the fit)."""

    def __init__(self, op, shapes: np.ndarray, settings: ExampleSettings):
        self._op, self._shapes, self._settings = op, shapes, settings
        self._grad: dict[int, np.ndarray] = {}
        self._reg: dict[int, np.ndarray] = {}

    def of(self, active: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(a, t, 9) gradient changes and (a, t) prior weights of shapes ``active``."""
        new = [int(i) for i in active if int(i) not in self._grad]
        if new:
            grad = source_gradient_blocks(self._op, self._shapes[new])   # (m, t, 9)
            reg = _prior_weights(grad, self._settings)
            for j, i in enumerate(new):
                self._grad[i], self._reg[i] = grad[j] - _IDENTITY, reg[j]
        return (np.stack([self._grad[int(i)] for i in active]),
                np.stack([self._reg[int(i)] for i in active]))


class _Poisson:
    """Vertex displacements from per-triangle gradient changes, on one neutral.

    ``min ‖G δ − Δ‖²`` over the displacements and fourth vertices, one vertex
    (an anchor) held at zero, the fourth vertices eliminated exactly
    (:class:`~facewrap.transfer.gradients.FourthVertexElimination`); factored
    once.  Pieces the anchor does not reach are tethered to zero, as deformation
    transfer tethers them to rest (:data:`~facewrap.transfer.constraints.TETHER_WEIGHT`).
    """

    def __init__(self, neutral: Mesh, anchor: int):
        self.op = gradient_operator(neutral.vertices, neutral.triangles)
        G = self.op.matrix
        n = self.op.n_vertices
        self.fourth = FourthVertexElimination(G.T @ G, n)
        H = self.fourth.matrix
        loose = untethered_vertices(self.op.triangles, n, [anchor])
        tether = tether_weights(H, loose)
        self.system = FixedSystem((H + sp.diags(tether)).tocsr(), [anchor])

    def displacements(self, delta: np.ndarray) -> np.ndarray:
        """(s, t, 9) gradient changes → (s, n, 3) vertex displacements."""
        s, t = delta.shape[:2]
        blocks = delta.reshape(s, t, 3, 3).transpose(1, 2, 0, 3).reshape(3 * t, 3 * s)
        x = self.system.solve(self.fourth.reduce(np.asarray(self.op.matrix.T @ blocks)))
        n = self.op.n_vertices
        return x.reshape(n, s, 3).transpose(1, 0, 2)


def _checked(neutral: Mesh, shapes: dict, examples, masks, weights):
    check_mesh(neutral, "neutral")
    n = neutral.n_vertices
    shapes = as_shape_dict(shapes, n, "shapes")
    names = list(shapes)
    examples = list(examples)
    if not names or not examples:
        raise ValueError(f"need shapes and examples, got {len(names)} shape(s) and "
                         f"{len(examples)} example(s)")
    S = np.stack([shapes[k] for k in names])
    E = np.stack([as_points(e, f"examples[{j}]") for j, e in enumerate(examples)])
    if E.shape[1:] != (n, 3):
        raise ValueError(f"shapes and examples must be ({n}, 3) each")
    k = len(E)
    trust = np.ones((k, n), dtype=bool)
    for j, m in enumerate(list(masks) or [None] * k):
        if m is not None:
            trust[j] = np.asarray(m, dtype=bool)
    prior = None
    weights = list(weights)
    if any(w is not None for w in weights):
        if len(weights) != k:
            raise ValueError(f"{k} examples but {len(weights)} weight entries")
        unknown = {x for w in weights if w for x in w} - set(names)
        if unknown:
            raise ValueError(f"example weights name unknown shapes: {sorted(unknown)}")
        prior = np.array([[float((w or {}).get(x, 0.0)) for x in names] for w in weights])
    return names, S, E, trust, prior


def _errors(neutral_v, shapes, alpha, E, trust) -> list[dict]:
    D = shapes - neutral_v[None]
    rig = neutral_v[None] + np.einsum("ji,ind->jnd", alpha, D)
    d = np.linalg.norm(rig - E, axis=2)
    return [{"mean": float(d[j][trust[j]].mean()),
             "p95": float(np.percentile(d[j][trust[j]], 95))} for j in range(len(E))]


def _weights_of(neutral_v, shapes, E, trust, prior, gamma) -> np.ndarray:
    """Every example's weights, each on its own trusted vertices (one Gram matrix of
    the shapes for them all)."""
    D = (shapes - neutral_v[None]).reshape(len(shapes), -1).T   # (3n, s)
    gram = D.T @ D
    out = []
    for j in range(len(E)):
        out.append(fit_weights(D, (E[j] - neutral_v).reshape(-1, 1),
                               prior=None if prior is None else prior[j:j + 1],
                               gamma=gamma, rows=np.repeat(trust[j], 3), gram=gram)[0])
    return np.array(out)


def fit_examples(neutral: Mesh, shapes: dict, examples, *, masks=(), weights=(),
                 rigid=None, settings: ExampleSettings | None = None) -> ExampleFit:
    """Correct a person's shapes so that their rig reproduces scans of their face.

    Parameters
    ----------
    neutral : Mesh
        The person's neutral in the template's topology.
    shapes : dict of str to (n, 3) float
        The prior: the template's shapes carried onto them (absolute positions).
    examples : sequence of (n, 3) float
        Their expressions wrapped in the same topology, head motion removed
        (:func:`~facewrap.rig.stabilise`).
    masks : sequence of (n,) bool or None, optional
        Per example, the vertices that lie on its scan (a wrap fills holes
        smoothly; only these count).  Default: every vertex.
    weights : sequence of (dict or None), optional
        Per example, the weights the capture meant (``{"jawOpen": 1.0}``), held
        with ``settings.weight_prior``; None or omitted: free.
    rigid : (r,) int, optional
        Skull-rigid vertices: the corrections leave their mean where it is.
        Default: the first vertex.
    settings : ExampleSettings, optional

    Returns
    -------
    ExampleFit

    Examples
    --------
    A shape twice as strong in the person as in the prior, seen at weight 1:

    >>> from facewrap.sample import make_template
    >>> tpl = make_template(20)
    >>> face, keep = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    >>> V = face.vertices
    >>> smile = tpl.blendshapes["smile"][keep]
    >>> fit = fit_examples(face, {"smile": smile}, [V + 2 * (smile - V)])
    >>> fit.weights[0]["smile"], fit.errors[0]["mean"] < 0.3 * fit.prior_errors[0]["mean"]
    (1.0, True)
    """
    settings = settings or ExampleSettings()
    t0 = time.perf_counter()
    names, S, E, trust, prior = _checked(neutral, shapes, examples, masks, weights)
    V0 = neutral.vertices
    rigid = np.array([0]) if rigid is None else as_vertex_ids(rigid, len(V0), "rigid")
    poisson = _Poisson(neutral, int(rigid[0]))
    T = poisson.op.triangles
    prior_shapes = _ShapeGradients(poisson.op, S, settings)
    grad_E = source_gradient_blocks(poisson.op, E) - _IDENTITY   # M(S_j) − I
    trusted = trust[:, T].all(axis=2).astype(np.float64)        # (k, t)
    t1 = time.perf_counter()
    timings = {"setup": t1 - t0, "weights": 0.0, "shapes": 0.0}
    alpha = _weights_of(V0, S, E, trust, prior, settings.weight_prior)
    prior_errors = _errors(V0, S, alpha, E, trust)
    current = S
    for _ in range(settings.iterations):
        t = time.perf_counter()
        active = np.flatnonzero(alpha.max(axis=0) > _ACTIVE)
        current = S.copy()
        if len(active):
            # residual of each example under the prior at the current weights
            grad_S, reg = prior_shapes.of(active)
            R = grad_E - np.tensordot(alpha[:, active], grad_S, axes=1)
            delta = _gradient_corrections(alpha[:, active], R, trusted, reg)
            move = poisson.displacements(delta)
            move -= move[:, rigid].mean(axis=1, keepdims=True)  # the skull stays put
            current[active] += move
        t2 = time.perf_counter()
        alpha = _weights_of(V0, current, E, trust, prior, settings.weight_prior)
        timings["shapes"] += t2 - t
        timings["weights"] += time.perf_counter() - t2
    timings["total"] = time.perf_counter() - t0
    return ExampleFit(dict(zip(names, current)),
                      [dict(zip(names, map(float, a))) for a in alpha],
                      _errors(V0, current, alpha, E, trust), prior_errors,
                      timings=timings)
