"""The one registration engine: closest scan points → deformation solve → repeat.

Non-rigid ICP (SPEC §2.1) for any :class:`~facewrap.wrapping.models.base.DeformationModel`:

1. **Closest scan points**: of every template vertex that is fitted (one AABB
   query for all), rejected when too far, when the normals disagree, when it
   lands on the scan's border (holes, crop), or when the vertex is excluded (eyes,
   mouth interior: they follow, unpulled) — :mod:`facewrap.geometry.matching`.
2. **Robust weights** (IRLS): Welsch / Huber / Geman–McClure on the point
   distance, with the scale taken from the data (a multiple of the median
   distance) and so annealed as the fit tightens.
3. **One damped Gauss–Newton step** on
   ``E = data (point-to-plane + point_weight · point-to-point) +
   landmark_weight · landmarks + smooth_weight · smooth + blend_weight · blend``,
   Levenberg–Marquardt: a step that raises the energy is retried with more
   damping.  The energy is evaluated from the same residual functions as the
   step (:mod:`facewrap.wrapping.icp.terms`), so the two cannot disagree.
4. Repeat until the vertices stop moving, stage after stage of a schedule that
   goes from stiff to loose (:mod:`facewrap.wrapping.icp.schedule`).

The engine works in a :class:`~facewrap.geometry.frames.NormalisedFrame` (template
centred, unit bounding-box diagonal), so weights and tolerances mean the same on a
face in mm, cm or m; the scan's :class:`~facewrap.geometry.ClosestPointTree` stays in
the scan's units.  The linear algebra is :func:`facewrap.solve.normal_equations`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from threadpoolctl import threadpool_limits

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.checks import as_triangles
from facewrap.geometry.frames import NormalisedFrame
from facewrap.geometry.normals import trusted_vertex_normals
from facewrap.geometry.matching import Matches, closest_compatible_points
from facewrap.progress import progress
from facewrap.solve import normal_equations
from facewrap.wrapping.icp.schedule import Stage, graph_schedule
from facewrap.wrapping.icp.terms import (landmark_residual, landmark_term,
                                         point_and_plane, point_and_plane_residual,
                                         robust_weights)

__all__ = ["NonRigidICP", "ScanPairs", "ICPProblem"]

#: Levenberg–Marquardt: how many times a step that raised the energy is retried
#: with tenfold damping before the iteration keeps the current parameters
_RETRIES = 6


@dataclass(frozen=True, eq=False)
class ScanPairs:
    """The data term of one iteration: template vertices paired with scan points.

    Attributes
    ----------
    vertices : (k,) int64
        Template vertices with an accepted closest scan point.
    matches : Matches
        Their scan points, normals and distances (normalised frame).
    weights : (k,) float64
        IRLS weights of the robust norm.
    robust_scale : float
        The norm's scale σ (normalised units).
    """
    vertices: np.ndarray
    matches: Matches
    weights: np.ndarray
    robust_scale: float


@dataclass(frozen=True, eq=False)
class ICPProblem:
    """What stays fixed during a fit: the model, the scan and the landmarks.

    Attributes
    ----------
    model : DeformationModel
    triangles : (t, 3) int64
        Template triangles (for the template's normals).
    tree : ClosestPointTree
        The scan, in its own units.
    frame : NormalisedFrame
        The model's frame: ``x_scan = x * frame.size + frame.center``.
    candidates : (c,) int64
        Vertices that may be fitted.
    sample_order : (c,) int64
        ``candidates`` in a fixed, seeded order: a stage that samples the data takes
        its first fraction (the subsets are nested).
    landmark_matrix : (l, n) sparse or None
    landmark_targets : (l, 3) float64 or None
        In the normalised frame.
    landmark_vertices : (v,) int64
        Vertices that enter a landmark row.
    """
    model: object
    triangles: np.ndarray
    tree: ClosestPointTree
    frame: NormalisedFrame
    candidates: np.ndarray
    sample_order: np.ndarray
    landmark_matrix: object
    landmark_targets: np.ndarray | None
    landmark_vertices: np.ndarray
    _around: dict = field(default_factory=dict, repr=False)   # triangles_around's
    # the last iteration's sparse factor: the next one mostly has its pattern, and
    # reuses its symbolic analysis (NormalEquations.factor)
    _factor: list = field(default_factory=lambda: [None], repr=False)

    @property
    def has_landmarks(self) -> bool:
        return self.landmark_matrix is not None and self.landmark_matrix.shape[0] > 0

    def sampled(self, fraction: float) -> np.ndarray:
        """The candidates a stage with ``sample=fraction`` fits, sorted."""
        if fraction >= 1:
            return self.candidates
        count = max(1, int(np.ceil(fraction * len(self.candidates))))
        return np.sort(self.sample_order[:count])

    def triangles_around(self, fraction: float) -> np.ndarray:
        """(t', 3) int64: the triangles with a corner among :meth:`sampled`
        (``fraction``), in their order; found once per fraction.

        The normals of the sampled vertices need no other triangle, and summed over
        these in the same order they are the very normals of the whole mesh.
        """
        if fraction not in self._around:
            corner = np.zeros(self.model.n_vertices, dtype=bool)
            corner[self.sampled(fraction)] = True
            self._around[fraction] = self.triangles[corner[self.triangles].any(axis=1)]
        return self._around[fraction]


class NonRigidICP:
    """Non-rigid ICP with any deformation model (settings only; see :meth:`fit`).

    Parameters
    ----------
    stages : list of Stage
        The schedule (default :func:`~facewrap.wrapping.icp.schedule.graph_schedule`).
    point_weight : float
        Weight of point-to-point against point-to-plane (weight 1).
    robust : {"welsch", "huber", "geman_mcclure", "none"}
    robust_factor : float
        Robust scale σ = ``robust_factor`` × median scan-point distance
        (floored at ``min_scale``): outliers are judged against the current fit.
    min_scale : float
        Floor of σ (normalised units).
    max_distance : float
        Longest accepted scan-point distance (normalised units, i.e. fraction of
        the template's size).
    max_normal_angle : float
        Degrees.
    reject_boundary : bool
        Reject scan points on the scan's border.
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
        units), correspondences (how many scan points), rejected counts, damping,
        seconds.
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

    def fit(self, model, triangles, tree: ClosestPointTree, *, frame: NormalisedFrame,
            fit_mask=None, landmark_matrix=None, landmark_targets=None,
            params=None) -> "NonRigidICP":
        """Register ``model`` to the scan in ``tree``.

        Parameters
        ----------
        model : DeformationModel
            Built on template positions in ``frame`` (``frame.to_frame(x)``).
        triangles : (t, 3) int
            Template triangles.
        tree : ClosestPointTree
            The scan (its own units).
        frame : NormalisedFrame
            The model's normalised frame.
        fit_mask : (n,) bool, optional
            Vertices pulled to the scan (default all).
        landmark_matrix : (l, n) sparse, optional
            Landmark rows (vertex / barycentric weights).
        landmark_targets : (l, 3) float, optional
            Landmark targets in the normalised frame.
        params : optional
            Warm start (default ``model.initial_params()``).

        Returns
        -------
        self
        """
        n = model.n_vertices
        candidates = np.flatnonzero(np.ones(n, bool) if fit_mask is None else fit_mask)
        # a fixed subset order for stages that sample the data (deterministic)
        sample_order = candidates[np.random.default_rng(0).permutation(len(candidates))]
        lm_vertices = (np.unique(sp.csr_matrix(landmark_matrix).indices)
                       if landmark_matrix is not None else np.zeros(0, np.int64))
        problem = ICPProblem(model, as_triangles(triangles, n), tree, frame,
                             candidates, sample_order, landmark_matrix, landmark_targets,
                             lm_vertices)
        # Many small vector operations: BLAS threads only contend on a loaded
        # machine, one thread is fastest.
        with threadpool_limits(limits=self.blas_threads, user_api="blas"):
            p, V, history = self._run_schedule(problem, params)
        self.params_ = p
        self.vertices_ = frame.from_frame(V)
        self.history_ = history
        return self

    def _run_schedule(self, problem: ICPProblem, params):
        """Every stage's iterations from ``params``: (params, vertices, history)."""
        model = problem.model
        p = model.initial_params() if params is None else params
        V = model.vertices(p)
        history = []
        mu = self.damping
        stages = self.stages or graph_schedule()
        # on a terminal: one bar of iterations (a stage that converges early counts
        # its remaining ones as done); silent elsewhere (facewrap.progress)
        with progress(sum(st.iterations for st in stages), "ICP") as bar:
            for s_index, stage in enumerate(stages):
                bar.update(description=f"ICP stage {s_index + 1}/{len(stages)}")
                for it in range(stage.iterations):
                    t0 = time.perf_counter()
                    pairs = (self.scan_pairs(problem, stage, V) if stage.data_weight > 0
                             else None)
                    p_new, V_new, energy, mu = self._damped_step(problem, stage, pairs, p,
                                                                 V, mu)
                    moved = float(np.abs(V_new - V).max())
                    p, V = p_new, V_new
                    history.append(self._history_entry(problem, pairs, V, s_index, it,
                                                       energy, moved, mu,
                                                       time.perf_counter() - t0))
                    bar.advance()
                    if moved < self.tolerance:
                        bar.advance(stage.iterations - it - 1)
                        break
        return p, V, history

    def scan_pairs(self, problem: ICPProblem, stage: Stage, V) -> ScanPairs:
        """Closest compatible scan points of the stage's vertices, with IRLS weights.

        Parameters
        ----------
        problem : ICPProblem
        stage : Stage
        V : (n, 3) float64
            Current vertices (normalised frame).

        Returns
        -------
        ScanPairs

        Raises
        ------
        ValueError
            When no vertex found an acceptable scan point (template and scan not
            aligned).
        """
        used = problem.sampled(stage.sample)
        # (the triangles were checked once in fit; query checks that V is finite)
        normals = trusted_vertex_normals(V, problem.triangles_around(stage.sample))[used]
        matches = closest_compatible_points(
            problem.tree, V[used], normals,
            frame=problem.frame, max_distance=self.max_distance,
            max_normal_angle=self.max_normal_angle, reject_border=self.reject_boundary)
        if len(matches) == 0:
            raise ValueError("no template vertex found a valid scan point within "
                             "max_distance (--max-distance) and max_normal_angle "
                             "(--max-normal-angle): is the scan aligned with the "
                             "template, and are those limits wide enough?")
        sigma = max(self.robust_factor * float(np.median(matches.distances)),
                    stage.robust_scale, self.min_scale)
        return ScanPairs(used[matches.index], matches,
                         robust_weights(matches.distances, sigma, self.robust), sigma)

    def _damped_step(self, problem: ICPProblem, stage: Stage, pairs, p, V, mu):
        """One Levenberg–Marquardt step: (params, vertices, energy, damping)."""
        model = problem.model
        # the Jacobian of the vertices that enter a term, nothing more
        active = (problem.landmark_vertices if pairs is None
                  else np.union1d(pairs.vertices, problem.landmark_vertices))
        Jv = model.jacobian(p, active)
        terms = self.step_terms(problem, stage, pairs, p, V, Jv, active)
        # assembled once: a retry with more damping only solves it again, and its
        # energy (the same residuals) is the one the step must lower
        system = normal_equations(terms, n_params=model.n_params, method=model.solver,
                                  block=model.param_block, analysis=problem._factor[0])
        e0 = system.energy
        for _ in range(_RETRIES):
            delta = system.step(mu)
            problem._factor[0] = system.factor
            p_new = model.update(p, delta)
            V_new = model.vertices(p_new)
            e1 = self.energy(problem, stage, pairs, p_new, V_new)
            if e1 <= e0 * (1 + 1e-12):
                return p_new, V_new, e1, max(mu / 3.0, 1e-7)
            mu *= 10.0
        return p, V, e0, mu

    def _term_weights(self, problem: ICPProblem, stage: Stage, pairs) -> dict:
        """Weight of each term: data and landmarks as means over their rows."""
        weights = {"smooth": stage.smooth_weight, "blend": stage.blend_weight,
                   "bounds": stage.bound_weight, "stretch": stage.stretch_weight}
        if pairs is not None:
            weights["data"] = stage.data_weight / max(len(pairs.vertices), 1)
        if problem.has_landmarks and stage.landmark_weight > 0:
            weights["landmarks"] = stage.landmark_weight / problem.landmark_matrix.shape[0]
        return weights

    def step_terms(self, problem: ICPProblem, stage: Stage, pairs, p, V, Jv,
                   active) -> list:
        """The weighted terms of a Gauss–Newton step, ``(weight, r, J, row weights)``."""
        weights = self._term_weights(problem, stage, pairs)
        terms = []
        if "data" in weights:
            m = pairs.matches
            r, J = point_and_plane(V, Jv, pairs.vertices, m.points, m.normals,
                                   self.point_weight,
                                   jacobian_rows=np.searchsorted(active, pairs.vertices))
            terms.append((weights["data"], r, J, np.repeat(pairs.weights, 3)))
        if "landmarks" in weights:
            r, J = landmark_term(V, Jv, problem.landmark_matrix, problem.landmark_targets,
                                 jacobian_vertices=active)
            terms.append((weights["landmarks"], r, J, None))
        for name, (r, J) in problem.model.regularizers(p).items():
            terms.append((weights.get(name, 0.0), r, J, None))
        return terms

    def energy(self, problem: ICPProblem, stage: Stage, pairs, p, V) -> float:
        """E(params, vertices) with the scan pairs and IRLS weights fixed: the
        weighted squared residuals of exactly the terms of :meth:`step_terms`."""
        weights = self._term_weights(problem, stage, pairs)
        e = 0.0
        if "data" in weights:
            m = pairs.matches
            r = point_and_plane_residual(V, pairs.vertices, m.points, m.normals,
                                         self.point_weight)
            e += weights["data"] * float(np.repeat(pairs.weights, 3) @ r ** 2)
        if "landmarks" in weights:
            r = landmark_residual(V, problem.landmark_matrix, problem.landmark_targets)
            e += weights["landmarks"] * float(r @ r)
        for name, r in problem.model.regularizer_residuals(p).items():
            e += weights.get(name, 0.0) * float(r @ r)
        return e

    def _history_entry(self, problem: ICPProblem, pairs, V, stage: int, iteration: int,
                       energy: float, moved: float, mu: float, seconds: float) -> dict:
        """One iteration's log (distances in the caller's units)."""
        size = problem.frame.size
        entry = {"stage": stage, "iteration": iteration, "energy": float(energy),
                 "max_move": moved * size, "damping": mu, "seconds": seconds}
        if pairs is not None:
            d = pairs.matches.distances
            entry.update(correspondences=int(len(pairs.vertices)),
                         data_rms=float(np.sqrt(np.mean(d ** 2))) * size,
                         robust_scale=pairs.robust_scale * size,
                         rejected=pairs.matches.rejected)
        if problem.has_landmarks:
            e = problem.landmark_matrix @ V - problem.landmark_targets
            entry["landmark_rms"] = float(np.sqrt((e ** 2).sum(1).mean())) * size
        return entry
