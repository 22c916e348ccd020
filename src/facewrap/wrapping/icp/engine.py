"""The one registration engine: correspondences → deformation solve → repeat.

Non-rigid ICP (SPEC §2.1) for any :class:`~facewrap.wrapping.models.base.DeformationModel`:

1. **Correspondences**: the closest scan point of every template vertex that is
   fitted (one AABB query for all), rejected when too far, when the normals
   disagree, when it lands on the scan's border (holes, crop), or when the
   vertex is excluded (eyes, mouth interior: they follow, unpulled).
2. **Robust weights** (IRLS): Welsch / Huber / Geman–McClure on the point
   distance, with the scale taken from the data (a multiple of the median
   distance) and so annealed as the fit tightens.
3. **One damped Gauss–Newton step** on
   ``E = data (point-to-plane + point_weight · point-to-point) +
   landmark_weight · landmarks + stiffness · smooth + blend_weight · blend``,
   Levenberg–Marquardt: a step that raises the energy is retried with more
   damping.
4. Repeat until the vertices stop moving, stage after stage of a schedule that
   goes from stiff to loose (:func:`default_schedule`).

The engine works in a normalised frame (template centred, unit bounding-box
diagonal), so weights and tolerances mean the same on a face in mm, cm or m;
the scan's :class:`~facewrap.geometry.ClosestPointTree` stays in the scan's
units.  Every term is a plain function in :mod:`facewrap.wrapping.icp.terms`; the linear
algebra is :func:`facewrap.solve.factor.gauss_newton_step`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import ClosestPointTree, vertex_normals
from facewrap.params import Interval, validate
from facewrap.solve import gauss_newton_step
from facewrap.wrapping.icp.terms import landmark_term, point_and_plane, robust_weights

__all__ = ["Stage", "default_schedule", "NonRigidICP", "Correspondences",
           "find_correspondences"]


@dataclass
class Stage:
    """One stage of the non-rigid ICP schedule (stiff to loose).

    Attributes
    ----------
    iterations : int
        Maximum ICP iterations (correspondences + one damped Gauss–Newton step).
    stiffness : float
        Weight of the model's smoothness regulariser (graph eq. 7, affine
        stiffness; per edge, relative to the mean data residual).
    landmark_weight : float
        Weight of the landmark term (mean over landmarks) relative to the data
        term (mean over correspondences).
    blend_weight : float
        Tikhonov weight on blend weights (eq. 5).
    data_weight : float
        Weight of the data term (0: landmarks and regularisers only, e.g. a
        first landmark-driven stage).
    robust_scale : float
        Floor of the robust norm's scale σ in this stage, as a fraction of the
        template's size.  Early stages keep it large so that parts of the
        template still far from the scan are pulled in, not written off as
        outliers; σ otherwise follows the data (a multiple of the median
        distance).
    sample : float
        Fraction of the fitted vertices that get a correspondence in this stage
        (a fixed, seeded subset).  A stiff stage moves a few hundred graph nodes
        and needs far fewer data points than the template has vertices (the
        subsets are nested: a larger fraction adds vertices).
    node_spacing_factor : float
        Graph models: this stage's node spacing as a multiple of the model's
        (coarse-to-fine in node count: 2 is about a quarter of the nodes).
        Consecutive stages with the same factor share one graph; the next graph
        continues the deformation (``model.on_graph``).  Other models ignore it.
    bound_weight : float
        Weight of the penalty on blend weights outside their range
        (``WrapSettings.weight_range``).  Measured on the sample and three ICT
        cases (hybrid): 1e-4 lowered the mean error on all four (eyes shut +
        smile 0.69 → 0.60 mm) and no weight left [0, 1] by more than 0.01;
        1e-3 cost the scream case's p95.
    """
    iterations: int = 10
    stiffness: float = 1.0
    landmark_weight: float = 1.0
    blend_weight: float = 1e-6
    data_weight: float = 1.0
    robust_scale: float = 0.0
    sample: float = 1.0
    node_spacing_factor: float = 1.0
    bound_weight: float = 1e-4

    #: allowed values of every field, checked at construction (:mod:`facewrap.params`)
    constraints = {
        "iterations": Interval(int, 1, None),
        "stiffness": Interval(float, 0, None),
        "landmark_weight": Interval(float, 0, None),
        "blend_weight": Interval(float, 0, None),
        "data_weight": Interval(float, 0, None),
        "robust_scale": Interval(float, 0, None),
        "sample": Interval(float, 0, 1, closed="right"),
        "node_spacing_factor": Interval(float, 0, None, closed="neither"),
        "bound_weight": Interval(float, 0, None),
    }

    def __post_init__(self):
        validate(self)


def default_schedule(model: str) -> list[Stage]:
    """The schedule each model uses unless told otherwise.

    Stiff to loose: a landmark-only stage pulls the template into the scan's
    expression, then the data term comes in and the regulariser relaxes while
    the landmarks' weight drops (they are less accurate than the scan surface).
    In the hybrid model the graph starts stiff so that the blendshapes, not the
    graph, take the expression; it relaxes once the weights have settled.
    Stiff stages fit a third of the vertices (``sample``); the last one of the
    graph models half (their few hundred nodes are still overdetermined many
    times, the final projection puts every vertex on the scan, and on the ICT
    cases of ``bench_nicp`` all of them changed no error by more than 0.01 mm
    mean).
    Graph models go coarse to fine in node count too: the stiffest stages run on
    a graph with twice the node spacing (a quarter of the nodes), whose motion
    the fine graph continues.  Measured on the ICT cases of ``bench_nicp``: the
    same error (hybrid scream 0.49 / 1.03 mm mean / p95 either way) for
    15–25 % less time; the hybrid's second stage on the coarse graph cost
    accuracy (p95 1.03 → 1.25 mm), so only its first stage is coarse.
    """
    if model == "rigid":
        return [Stage(iterations=10, stiffness=0.0, landmark_weight=0.1, sample=0.3),
                Stage(iterations=5, stiffness=0.0, landmark_weight=0.1)]
    if model == "blendshape":
        return [Stage(iterations=4, landmark_weight=1.0, blend_weight=1e-7,
                      data_weight=0.0),
                Stage(iterations=6, landmark_weight=0.3, blend_weight=1e-8, sample=0.3),
                Stage(iterations=6, landmark_weight=0.1, blend_weight=1e-8)]
    if model == "affine":
        return [Stage(iterations=3, stiffness=10.0, landmark_weight=1.0),
                Stage(iterations=3, stiffness=3.0, landmark_weight=0.5),
                Stage(iterations=3, stiffness=1.0, landmark_weight=0.2),
                Stage(iterations=3, stiffness=0.3, landmark_weight=0.1),
                Stage(iterations=3, stiffness=0.1, landmark_weight=0.1)]
    if model == "hybrid":
        # (no landmark-only stage: the blendshape pre-fit in wrap() did that job)
        # The robust floors are the graph model's: on a real scan of another
        # identity (menpo's james) floors of 0.02 / 0.01 / 0.005 wrote off the
        # nose wings and temples as outliers (fit before projection 1.60 mm mean,
        # 7.1 mm p95; with these 1.04 / 4.1 mm); the ICT ground-truth cases moved
        # by at most 0.002 mm mean.
        return [Stage(iterations=5, stiffness=10.0, landmark_weight=0.5, blend_weight=1e-8,
                      robust_scale=0.06, sample=0.3, node_spacing_factor=2.0),
                Stage(iterations=5, stiffness=1.0, landmark_weight=0.2, blend_weight=1e-8,
                      robust_scale=0.03, sample=0.3),
                Stage(iterations=5, stiffness=0.1, landmark_weight=0.1, blend_weight=1e-8,
                      robust_scale=0.015, sample=0.3),
                Stage(iterations=5, stiffness=0.03, landmark_weight=0.1, blend_weight=1e-8,
                      sample=0.5)]
    # graph: without blendshapes a wide-open jaw leaves the chin and neck far from
    # the scan after the landmark stage; larger robust floors keep pulling them in
    # (ICT jaw-open case: p95 12.7 -> 5.5 mm)
    return [Stage(iterations=4, stiffness=1.0, landmark_weight=1.0, data_weight=0.0,
                  node_spacing_factor=2.0),
            Stage(iterations=5, stiffness=1.0, landmark_weight=0.5, robust_scale=0.06,
                  sample=0.3, node_spacing_factor=2.0),
            Stage(iterations=5, stiffness=0.3, landmark_weight=0.2, robust_scale=0.03,
                  sample=0.3, node_spacing_factor=2.0),
            Stage(iterations=5, stiffness=0.1, landmark_weight=0.1, robust_scale=0.015,
                  sample=0.3),
            Stage(iterations=5, stiffness=0.03, landmark_weight=0.1, sample=0.5)]


@dataclass
class Correspondences:
    """Template vertices with an accepted scan point (normalised frame).

    Attributes
    ----------
    vertices : (k,) int64
    points, normals : (k, 3) float64
        Closest scan points and the scan's interpolated unit normals there.
    distances : (k,) float64
    rejected : dict
        How many candidates each test removed ("distance", "normal", "border").
    """
    vertices: np.ndarray
    points: np.ndarray
    normals: np.ndarray
    distances: np.ndarray
    rejected: dict = field(default_factory=dict)


def find_correspondences(V, T, tree: ClosestPointTree, candidates, *, center, size,
                         max_distance: float, max_normal_angle: float = 60.0,
                         reject_boundary: bool = True) -> Correspondences:
    """Closest scan points of template vertices, with rejection.

    Parameters
    ----------
    V : (n, 3) float64
        Template vertices in the normalised frame.
    T : (t, 3) int
        Template triangles (for the template's normals).
    tree : ClosestPointTree
        The scan, in its own units.
    candidates : (c,) int
        Vertices that may be fitted.
    center : (3,) float, size : float
        The normalised frame: ``x_scan = x * size + center``.
    max_distance : float
        Longest accepted distance (normalised).
    max_normal_angle : float
        Degrees.
    reject_boundary : bool
        Reject points on the scan's border triangles.
    """
    cp = tree.query(V[candidates] * size + center)
    points = (cp.points - center) / size
    d = cp.distances / size
    n_t = vertex_normals(V, T)[candidates]
    ok_d = d <= max_distance
    ok_n = np.einsum("ka,ka->k", n_t, cp.normals) >= np.cos(np.radians(max_normal_angle))
    ok_b = ~tree.boundary_triangles[cp.triangles] if reject_boundary else np.ones_like(ok_d)
    keep = ok_d & ok_n & ok_b
    rejected = {"distance": int((~ok_d).sum()), "normal": int((ok_d & ~ok_n).sum()),
                "border": int((ok_d & ok_n & ~ok_b).sum())}
    return Correspondences(np.asarray(candidates)[keep], points[keep], cp.normals[keep],
                           d[keep], rejected)


class NonRigidICP:
    """Non-rigid ICP with any deformation model (settings only; see :meth:`fit`).

    Parameters
    ----------
    stages : list of Stage
    point_weight : float
        Weight of point-to-point against point-to-plane (weight 1).
    robust : {"welsch", "huber", "geman_mcclure", "none"}
    robust_factor : float
        Robust scale σ = ``robust_factor`` × median correspondence distance
        (floored at ``min_scale``): outliers are judged against the current fit.
    min_scale : float
        Floor of σ (normalised units).
    max_distance : float
        Longest correspondence (normalised units, i.e. fraction of the template's
        size).
    max_normal_angle : float
        Degrees.
    reject_boundary : bool
    tolerance : float
        A stage ends when no vertex moved more than this (normalised units).
    damping : float
        Initial Levenberg–Marquardt damping.
    blas_threads : int or None
        BLAS threads during the fit (None: leave as is).

    Attributes (after :meth:`fit`)
    ------------------------------
    params_ : model parameters
    vertices_ : (n, 3) float64
        In the caller's units (the frame is undone).
    history_ : list of dict
        Per iteration: stage, iteration, energy, data_rms, landmark_rms (caller's
        units), correspondences, rejected counts, damping, seconds.
    """

    def __init__(self, stages=None, *, point_weight: float = 0.1,
                 robust: str = "welsch", robust_factor: float = 3.0,
                 min_scale: float = 5e-4, max_distance: float = 0.05,
                 max_normal_angle: float = 60.0, reject_boundary: bool = True,
                 tolerance: float = 5e-4, damping: float = 1e-4,
                 blas_threads: int | None = 1):
        self.stages = stages
        self.point_weight = point_weight
        self.robust = robust
        self.robust_factor = robust_factor
        self.min_scale = min_scale
        self.max_distance = max_distance
        self.max_normal_angle = max_normal_angle
        self.reject_boundary = reject_boundary
        self.tolerance = tolerance
        self.damping = damping
        self.blas_threads = blas_threads

    def fit(self, model, triangles, tree: ClosestPointTree, *, center, size,
            fit_mask=None, landmark_matrix=None, landmark_targets=None,
            params=None) -> "NonRigidICP":
        """Register ``model`` to the scan in ``tree``.

        Parameters
        ----------
        model : DeformationModel
            Built on template positions in the normalised frame
            ``(x - center) / size``.
        triangles : (t, 3) int
            Template triangles.
        tree : ClosestPointTree
            The scan (its own units).
        center : (3,) float, size : float
            The normalised frame.
        fit_mask : (n,) bool, optional
            Vertices pulled to the scan (default all).
        landmark_matrix : (l, n) sparse, optional
            Landmark rows (vertex / barycentric weights).
        landmark_targets : (l, 3) float, optional
            Landmark targets in the normalised frame.
        params : optional
            Warm start (default ``model.initial_params()``).
        """
        # Many small vector operations: BLAS threads only contend (10x slower on a
        # loaded 2-core machine), one thread is fastest.
        from threadpoolctl import threadpool_limits
        with threadpool_limits(limits=self.blas_threads, user_api="blas"):
            return self._fit(model, triangles, tree, center=center, size=size,
                             fit_mask=fit_mask, landmark_matrix=landmark_matrix,
                             landmark_targets=landmark_targets, params=params)

    def _fit(self, model, triangles, tree, *, center, size, fit_mask, landmark_matrix,
             landmark_targets, params):
        stages = self.stages or default_schedule("graph")
        T = np.asarray(triangles, dtype=np.int64)
        n = model.n_vertices
        candidates = np.flatnonzero(np.ones(n, bool) if fit_mask is None else fit_mask)
        # a fixed subset order for stages that sample the data (deterministic)
        sample_order = candidates[np.random.default_rng(0).permutation(len(candidates))]
        lm_vertices = (np.unique(sp.csr_matrix(landmark_matrix).indices)
                       if landmark_matrix is not None else np.zeros(0, np.int64))
        p = model.initial_params() if params is None else params
        V = model.vertices(p)
        history = []
        mu = self.damping
        has_lm = landmark_matrix is not None and landmark_matrix.shape[0] > 0
        for s_index, stage in enumerate(stages):
            for it in range(stage.iterations):
                t0 = time.perf_counter()
                corr = None
                if stage.data_weight > 0:
                    used = candidates if stage.sample >= 1 else np.sort(
                        sample_order[:max(1, int(np.ceil(stage.sample * len(candidates))))])
                    corr = find_correspondences(
                        V, T, tree, used, center=center, size=size,
                        max_distance=self.max_distance,
                        max_normal_angle=self.max_normal_angle,
                        reject_boundary=self.reject_boundary)
                    if len(corr.vertices) == 0:
                        raise ValueError("no template vertex found a valid scan point: "
                                         "is the scan aligned with the template?")
                    sigma = max(self.robust_factor * float(np.median(corr.distances)),
                                stage.robust_scale, self.min_scale)
                    rw = robust_weights(corr.distances, sigma, self.robust)
                energy_of = self._energy_function(model, stage, corr, rw if corr else None,
                                                  landmark_matrix, landmark_targets, has_lm)
                # the Jacobian of the vertices that enter a term, nothing more
                active = lm_vertices if corr is None else np.union1d(corr.vertices,
                                                                     lm_vertices)
                Jv = model.jacobian(p, active)
                terms = self._terms(model, p, V, Jv, active, stage, corr,
                                    rw if corr else None, landmark_matrix,
                                    landmark_targets, has_lm)
                e0 = energy_of(p, V)
                for _ in range(6):  # Levenberg–Marquardt: retry with more damping
                    delta = gauss_newton_step(terms, damping=mu, n_params=model.n_params,
                                              method=model.solver,
                                              block=model.param_block)
                    p_new = model.update(p, delta)
                    V_new = model.vertices(p_new)
                    e1 = energy_of(p_new, V_new)
                    if e1 <= e0 * (1 + 1e-12):
                        mu = max(mu / 3.0, 1e-7)
                        break
                    mu *= 10.0
                else:
                    p_new, V_new, e1 = p, V, e0
                moved = float(np.abs(V_new - V).max())
                p, V = p_new, V_new
                entry = {"stage": s_index, "iteration": it, "energy": float(e1),
                         "max_move": moved * size, "damping": mu,
                         "seconds": time.perf_counter() - t0}
                if corr is not None:
                    entry.update(correspondences=int(len(corr.vertices)),
                                 data_rms=float(np.sqrt(np.mean(corr.distances ** 2)))
                                 * size, robust_scale=sigma * size,
                                 rejected=corr.rejected)
                if has_lm:
                    e = (landmark_matrix @ V - landmark_targets)
                    entry["landmark_rms"] = float(np.sqrt((e ** 2).sum(1).mean())) * size
                history.append(entry)
                if moved < self.tolerance:
                    break
        self.params_ = p
        self.vertices_ = V * size + center
        self.history_ = history
        return self

    # -- energy assembly ---------------------------------------------------------
    def _terms(self, model, p, V, Jv, active, stage, corr, rw, L, targets, has_lm):
        terms = []
        if corr is not None:
            k = max(len(corr.vertices), 1)
            r, J = point_and_plane(V, Jv, corr.vertices, corr.points, corr.normals,
                                   self.point_weight,
                                   jacobian_rows=np.searchsorted(active, corr.vertices))
            terms.append((stage.data_weight / k, r, J, np.repeat(rw, 3)))
        if has_lm and stage.landmark_weight > 0:
            r, J = landmark_term(V, Jv, L, targets, jacobian_vertices=active)
            terms.append((stage.landmark_weight / L.shape[0], r, J, None))
        weights = {"smooth": stage.stiffness, "blend": stage.blend_weight,
                   "bounds": stage.bound_weight}
        for name, (r, J) in model.regularizers(p).items():
            terms.append((weights.get(name, 0.0), r, J, None))
        return terms

    def _energy_function(self, model, stage, corr, rw, L, targets, has_lm):
        """E(params, vertices) with the correspondences and IRLS weights fixed."""
        weights = {"smooth": stage.stiffness, "blend": stage.blend_weight,
                   "bounds": stage.bound_weight}

        def energy(p, V):
            e = 0.0
            if corr is not None:
                k = max(len(corr.vertices), 1)
                diff = V[corr.vertices] - corr.points
                plane = np.einsum("ka,ka->k", diff, corr.normals)
                e += stage.data_weight / k * float(rw @ plane ** 2)
                e += stage.data_weight * self.point_weight / k * float(
                    rw @ (diff ** 2).sum(1))
            if has_lm and stage.landmark_weight > 0:
                d = L @ V - targets
                e += stage.landmark_weight / L.shape[0] * float((d ** 2).sum())
            for name, r in model.regularizer_residuals(p).items():
                e += weights.get(name, 0.0) * float(r @ r)
            return e
        return energy
