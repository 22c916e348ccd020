"""``wrap``: register a template onto a scan, keeping the template's topology.

The pipeline (SPEC §1–§2), one named function per stage, each testable alone:

    :func:`prepare_wrap`  the inputs checked, landmarks paired, the scan's tree
                          (:mod:`.problem`)
    :func:`align`         landmark similarity (Umeyama), optionally refined by rigid ICP
    :func:`fit_model`     the model of the registry entry: closed form (rigid, rbf)
                          or coarse pre-fit + non-rigid ICP (:mod:`.model_fit`)
    :func:`pull_landmarks` landmarks left far from their targets pulled to them
    :func:`project`       onto the scan along normals, smooth where not projected
    :func:`finish_fit`    pinned vertices back, folds unfolded, parts follow the skin
                          (:mod:`.finish`, with :func:`project`)
    :func:`fit_metrics`   distances to the scan and landmark errors

:func:`wrap` runs them in this order and returns a :class:`WrapResult` with the
fitted mesh (same vertex count, order, faces and UVs as the template), what
happened at each stage, timings and metrics; nothing here reads or writes files.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from facewrap.evaluate import surface_distances
from facewrap.geometry import ClosestPointTree, connected_components, turned_triangles
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.params import expect_instance
from facewrap.progress import progress
from facewrap.wrapping.align import rigid_icp
from facewrap.wrapping.coverage import landmarks_off_scan
from facewrap.wrapping.finish import finish_fit, pin, project
from facewrap.wrapping.model_fit import ModelFit, coarse_fit, icp_fit, icp_start
from facewrap.wrapping.models.graph import GraphCache
from facewrap.wrapping.problem import (WrapProblem, alignment_weights, check_wrap_arguments,
                                      prepare_wrap)
from facewrap.wrapping.projection import Projection
from facewrap.wrapping.roles import FITTED
from facewrap.wrapping.seams import seam_weld
from facewrap.wrapping.settings import WrapSettings
from facewrap.wrapping.warp import pull_to_landmarks

__all__ = ["WrapResult", "WrapProblem", "wrap", "fit_metrics", "prepare_wrap", "align",
           "fit_model", "pull_landmarks", "project", "pin", "finish_fit",
           "alignment_weights"]


@dataclass
class WrapResult:
    """Outcome of :func:`wrap`.

    Attributes
    ----------
    mesh : Mesh
        The template's mesh with fitted vertex positions.
    transform : Similarity
        Template → scan similarity.
    warped : (n, 3) float64
        Positions after alignment and warp, before projection.
    projection : Projection or None
    timings : dict
        Seconds per stage.
    metrics : dict
        Landmark errors and fit distances (see :func:`fit_metrics`).
    settings : WrapSettings
        The settings used (``model`` resolved from "auto").
    history : list of dict
        One entry per ICP iteration (stage, energy, fit, landmark error, seconds).
    weights : (k,) float or None
        Fitted blend weights (blendshape and hybrid models).
    shape_names : list of str
        Names of the blendshapes, in the order of ``weights``.
    warnings : list of str
        One line per implausible input met (:mod:`facewrap.wrapping.plausibility`):
        mis-paired landmarks, duplicates, flipped or duplicated scan faces, a
        scale that suggests other units.  Empty for a clean run.
    roles : (n,) int8 or None
        What each template vertex was (:data:`facewrap.wrapping.roles.VERTEX_ROLES`):
        fitted, a part or cavity that followed, excluded, pinned.
    """
    mesh: Mesh
    transform: Similarity
    warped: np.ndarray
    projection: Projection | None
    timings: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    settings: WrapSettings | None = None
    history: list = field(default_factory=list)
    weights: np.ndarray | None = None
    shape_names: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    roles: np.ndarray | None = None

    @property
    def vertices(self) -> np.ndarray:
        return self.mesh.vertices


def fit_metrics(vertices, tree: ClosestPointTree, landmark_positions=None,
                scan_landmarks=None, mask=None) -> dict:
    """Distances from fitted vertices to the scan and landmark errors.

    Parameters
    ----------
    vertices : (n, 3) float
    tree : ClosestPointTree
        The scan.
    landmark_positions, scan_landmarks : (k, 3) float, optional
        Fitted and target landmark positions.
    mask : (n,) bool, optional
        Vertices to include in the fit statistics (the fitted ones).

    Fit distances are taken over the vertices whose closest scan point is not on
    the scan's border (``fit_coverage`` is their fraction of the vertices in
    ``mask``): a template usually covers more than the scanner saw.
    """
    # the one measure of distances to a surface (facewrap.evaluate): only vertices
    # the scan covers count, where the closest point is on the scan's border (holes,
    # cropped regions) the template has nothing to fit to
    d = surface_distances(vertices, tree, exclude_border=True, mask=mask).summary("fit_")
    out = {k: d[k] for k in ("fit_mean", "fit_p95", "fit_max", "fit_coverage")}
    if landmark_positions is not None:
        e = np.linalg.norm(np.asarray(landmark_positions) - np.asarray(scan_landmarks),
                           axis=1)
        out.update(landmark_mean=float(e.mean()), landmark_max=float(e.max()))
    return out

def align(problem: WrapProblem, initial: WrapResult | None = None) -> Similarity:
    """Template → scan similarity: from the landmark pairs (Umeyama) or a previous
    result, refined by trimmed rigid ICP when ``settings.rigid_refine``."""
    s = problem.settings
    if initial is not None:
        similarity = initial.transform
    else:
        similarity = similarity_transform(problem.sources, problem.targets,
                                          weights=problem.alignment_weights,
                                          scale=s.scale)
    if s.rigid_refine:
        similarity = rigid_icp(problem.template.vertices[~problem.excluded], problem.tree,
                               init=similarity,
                               max_distance=0.05 * problem.scan.scale()).transform
    return similarity


def fit_model(problem: WrapProblem, vertices, similarity: Similarity,
              initial: WrapResult | None = None) -> ModelFit:
    """Deform the aligned template ``vertices`` (n, 3) with the problem's model.

    Closed-form models (rigid, rbf) in one call; the others by a coarse pre-fit and
    non-rigid ICP (:mod:`facewrap.wrapping.model_fit`), warm-started from
    ``initial`` when given.
    """
    spec, s, template = problem.spec, problem.settings, problem.template
    if not spec.fitted_by_icp:
        current = problem.landmarks.positions(vertices, template.triangles)
        return ModelFit(spec.closed_form(vertices, current, problem.targets, s))
    t0 = time.perf_counter()
    skin = problem.skin_triangles
    start = icp_start(template, vertices, similarity, problem.landmarks, problem.targets,
                      spec, problem.blendshapes, s.pca_components, frame_triangles=skin)
    start, history = coarse_fit(start, spec, s, template, problem.tree, problem.excluded,
                                warm_weights=None if initial is None else initial.weights,
                                warm=initial is not None)
    fitted = icp_fit(start, spec, s, template, problem.tree, problem.excluded,
                     problem.graph_cache, t0, graph_triangles=skin)
    fitted.history = history + fitted.history
    return fitted


def pull_landmarks(problem: WrapProblem, vertices, guard: bool = False
                   ) -> tuple[np.ndarray, dict]:
    """``WrapSettings.landmark_pull``: landmarks farther than ``landmark_tolerance``
    (fraction of the size of ``vertices``) from their targets are pulled to it;
    with ``guard``, only as far as that turns no fitted triangle over (landmarks
    that disagree with each other or with the surface are held back; see
    :func:`~facewrap.wrapping.warp.pull_to_landmarks`).

    Excluded islands (eyeballs, teeth) move by their mean pull, so they keep their
    shape.

    Returns
    -------
    vertices : (n, 3) float64
    summary : dict
        Tolerance, how many landmarks were pulled, mean and largest pull, how
        many were held back (``held_back``) with the largest distance they were
        left short of the tolerance (``held_short``), both in scan units, and how
        many fitted triangles the pull turned over (``turned``).
    """
    V, T, excluded = vertices, problem.template.triangles, problem.excluded
    tolerance = problem.settings.landmark_tolerance
    size = problem.template.with_vertices(V).scale()     # of the surface
    fitted = problem.landmarks.positions(V, T)
    skin = T[~excluded[T].any(axis=1)]
    moved, pulls = pull_to_landmarks(V, fitted, problem.targets, tolerance * size,
                                     triangles=skin if guard else None)
    short = np.maximum(np.linalg.norm(problem.targets - fitted, axis=1)
                       - tolerance * size - pulls, 0.0)
    held = short > 1e-6 * size
    if excluded.any() and pulls.any():
        island = connected_components(T[excluded[T].all(axis=1)], len(V))[excluded]
        shift = moved[excluded] - V[excluded]
        count = np.bincount(island)
        mean = np.stack([np.bincount(island, shift[:, c]) for c in range(3)], 1)
        moved[excluded] = V[excluded] + mean[island] / count[island, None]
    return moved, {"tolerance": tolerance * size, "pulled": int(np.count_nonzero(pulls)),
                   "mean": float(pulls.mean()), "max": float(pulls.max()),
                   "held_back": int(held.sum()),
                   "held_short": float(short.max()) if held.any() else 0.0,
                   "turned": int(turned_triangles(moved, V, skin).sum())}

def _timed(timings: dict, key: str, bar, stage, *args, **kw):
    """``stage(*args, **kw)``, its seconds in ``timings[key]``, one step of ``bar``."""
    t = time.perf_counter()
    out = stage(*args, **kw)
    timings[key] = time.perf_counter() - t
    if bar is not None:
        bar.advance()
    return out


def wrap(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
         scan_landmarks: Landmarks, settings: WrapSettings | None = None, *,
         exclude=None, fit_mask=None, pinned=None, blendshapes=None,
         scan_tree: ClosestPointTree | None = None,
         initial: WrapResult | None = None,
         graph_cache: GraphCache | None = None) -> WrapResult:
    """Fit ``template`` to ``scan``.

    Parameters
    ----------
    template : Mesh
    scan : Mesh
    template_landmarks : Landmarks
        On the template (vertex or surface landmarks).
    scan_landmarks : Landmarks
        On the scan (free points, or vertex/surface landmarks of the scan).
    settings : WrapSettings, optional
    exclude : (n,) bool or int array, optional
        Template vertices that must not be pulled onto the scan: they follow
        smoothly.  The template's parts and cavities follow anyway
        (unless ``settings.fit_hidden``).
    fit_mask : (n,) bool or int array, optional
        The only vertices pulled onto the scan, even those the automatic choice
        calls cavities; outside it, the template's parts and cavities follow as such
        (unless ``settings.fit_hidden``); ``exclude`` still applies.
    pinned : (n,) bool or int array, optional
        Vertices kept exactly where the landmark similarity puts the template
        (a neck seam that must meet a body, say); the fit blends into them.
    blendshapes : dict name -> (n, 3) float, optional
        Shapes in the template's topology (positions, not deltas), for the
        "blendshape" and "hybrid" models.
    scan_tree : ClosestPointTree, optional
        Reuse a tree already built on the scan.
    initial : WrapResult, optional
        A previous result of the same template (the previous frame of a
        sequence): its similarity replaces the landmark alignment and its blend
        weights start the fit.
    graph_cache : GraphCache, optional
        Where deformation graphs are kept between wraps (default: one shared
        cache, :data:`facewrap.wrapping.models.graph.DEFAULT_GRAPH_CACHE`).

    Returns
    -------
    WrapResult

    Raises
    ------
    TypeError
        An argument of the wrong kind.
    ValueError
        Inputs that cannot be fitted; the message starts with what it is about
        (``"scan: ..."``, ``"template landmarks: ..."``).
    """
    blendshapes = check_wrap_arguments(template, scan, template_landmarks, scan_landmarks,
                                       settings, blendshapes=blendshapes,
                                       scan_tree=scan_tree, graph_cache=graph_cache)
    if expect_instance(initial, WrapResult, "initial", optional=True) is not None \
            and initial.mesh.n_vertices != template.n_vertices:
        raise ValueError(f"initial is a result of another template ({initial.mesh.n_vertices} "
                         f"vertices, the template has {template.n_vertices})")
    weld = seam_weld(template, blendshapes)
    if weld is not None:   # one surface where an exporter split the template (.seams)
        return weld.unweld(wrap(
            weld.mesh, scan, weld.landmarks(template_landmarks), scan_landmarks, settings,
            exclude=weld.vertex_set(exclude), fit_mask=weld.vertex_set(fit_mask),
            pinned=weld.vertex_set(pinned), blendshapes=weld.shapes(blendshapes),
            scan_tree=scan_tree, initial=initial, graph_cache=graph_cache), template)
    timings = {}
    t0 = time.perf_counter()
    # on a terminal, one line that says which stage runs (the ICP draws its own bars).
    # One BLAS thread: a wrap's dense work is small systems and vector operations,
    # where a second thread only waits for its core (ICT's head onto james on a
    # loaded machine: the parts' 55 small RBF solves took 2.5 s with two threads,
    # 0.03 s with one)
    with progress(6, "wrap: checking the inputs") as bar, \
            threadpool_limits(limits=1, user_api="blas"):
        problem = _timed(timings, "setup", bar, prepare_wrap, template, scan,
                         template_landmarks, scan_landmarks, settings, exclude=exclude,
                         fit_mask=fit_mask, pinned=pinned, blendshapes=blendshapes,
                         scan_tree=scan_tree, graph_cache=graph_cache)
        similarity = _timed(timings, "align", bar, align, problem, initial)
        V = similarity.apply(template.vertices)

        bar.update(description=f"wrap: fitting the {problem.spec.name} model")
        t = time.perf_counter()
        fitted = fit_model(problem, V, similarity, initial)
        V = fitted.vertices
        if fitted.setup_seconds:
            timings["model_setup"] = fitted.setup_seconds
        # "model_setup" (graph, coarse pre-fit) and "icp" are disjoint parts of the run
        timings["icp" if problem.spec.fitted_by_icp else "warp"] = (
            time.perf_counter() - t - fitted.setup_seconds)
        bar.advance()

        pulled = problem.spec.fitted_by_icp and problem.settings.landmark_pull
        rest = (similarity.apply(template.vertices) if fitted.rest is None
                else fitted.rest)
        V, pull, projection, out, finish = _land(problem, V, similarity, fitted, rest,
                                                 pulled, timings=timings, bar=bar)
        folds = _folds(problem, out, rest) if pull and pull["turned"] else 0
        if folds:
            # the pull turned triangles over and the unfolding left folds: landmarks
            # that disagree with each other (noisy, mis-clicked).  Landed again with
            # the pull held back where it folds; the one with fewer folds is kept
            t = time.perf_counter()
            again = _land(problem, fitted.vertices, similarity, fitted, rest, pulled,
                          guard=True)
            if _folds(problem, again[3], rest) < folds:
                V, pull, projection, out, finish = again
            timings["landmark_guard"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0

    metrics = fit_metrics(out, problem.tree,
                          problem.landmarks.positions(out, template.triangles),
                          problem.targets, mask=~problem.excluded)
    if projection is not None:
        metrics["projection"] = projection.summary()
    if pull is not None:
        metrics["landmark_pull"] = pull
    metrics["finish"] = finish
    return WrapResult(template.with_vertices(out), similarity, V, projection, timings,
                      metrics, settings=problem.settings, history=fitted.history,
                      weights=fitted.weights, shape_names=fitted.shape_names,
                      warnings=list(problem.warnings) + _pull_warnings(pull, problem)
                      + _slide_warnings(finish, problem, out)
                      + _off_scan(template_landmarks, problem, out),
                      roles=problem.roles)


#: the landmark pull's guard is reported when it left a landmark farther than this
#: many tolerances from its target: hand-clicked landmarks (james's) hold none
#: back, 0.7-1.4 mm of noise on the sample leaves them at most 3.4 tolerances
#: short, 5 mm on james 4.5-10
_HELD_SHORT_TOLERANCES = 4.0


def _land(problem: WrapProblem, V, similarity, fitted, rest, pulled: bool, *,
          guard: bool = False, timings=None, bar=None):
    """The fit's vertices ``V`` pulled to the landmarks (when ``pulled``),
    projected and finished: (pulled vertices, pull summary or None, projection,
    result, finish summary)."""
    timings = {} if timings is None else timings
    step = (lambda text: bar.update(description=text)) if bar else (lambda text: None)
    pull = None
    if pulled:
        step("wrap: pulling landmarks")
        V, pull = _timed(timings, "landmark_pull", bar, pull_landmarks, problem, V, guard)
    elif bar:
        bar.advance()
    step("wrap: projecting onto the scan")
    projection = _timed(timings, "project", bar, project, problem, V, reference=rest)
    step("wrap: unfolding, parts following")
    out, finish = _timed(timings, "finish", bar, finish_fit, problem,
                         V if projection is None else projection.vertices,
                         similarity, projection, rest=fitted.rest)
    return V, pull, projection, out, finish


def _folds(problem: WrapProblem, vertices, rest) -> int:
    """Fitted triangles of ``vertices`` turned past 90 degrees from ``rest``."""
    T = problem.template.triangles
    return int(turned_triangles(vertices, rest, T)[(problem.roles[T] == FITTED)
                                                  .all(axis=1)].sum())


def _off_scan(template_landmarks: Landmarks, problem: WrapProblem, vertices) -> list:
    """:func:`~facewrap.wrapping.coverage.landmarks_off_scan` of all the template's
    landmarks, their scan partners where they have them (points off the template:
    the paired ones only, snapped onto it)."""
    if template_landmarks.on_mesh:
        paired = problem.landmark_ids
    else:
        template_landmarks, paired = problem.landmarks, np.arange(len(problem.targets))
    return landmarks_off_scan(template_landmarks, vertices, problem.template.triangles,
                              problem.tree, paired, problem.targets)


#: the unfolding's slide of a landmark is reported past this many tolerances (0.2 %
#: of the head's size each): ICT's face onto its own held-out expressions slides them
#: at most 4.3 (a closed mouth over an open jaw, 3.2 mm), a head of other proportions
#: onto james 13-42 (10-33 mm)
_SLID_TOLERANCES = 10.0


def _slide_warnings(finish: dict, problem: WrapProblem, vertices) -> list:
    """One line when unfolding the fit moved landmark vertices far along the scan
    (:func:`~facewrap.wrapping.finish.finish_fit` holds them unless that leaves
    folds): the template's landmarks and the scan's disagree with the surface."""
    slid = finish.get("landmarks_slid", 0.0)
    size = problem.template.with_vertices(vertices).scale()
    if slid <= _SLID_TOLERANCES * problem.settings.landmark_tolerance * size:
        return []
    return [f"template landmarks: unfolding the fit moved landmark vertices up to "
            f"{slid:.3g} scan units from where the fit put them (held there, they "
            f"would leave the surface folded): the template's landmarks and the "
            f"scan's seem placed differently (a jaw point on the outline in one, on "
            f"the bone in the other?)"]


def _pull_warnings(pull: dict | None, problem: WrapProblem) -> list:
    """One line when the landmark pull was held back far from the targets: the
    landmarks disagree with each other or with the scan's surface (noisy or
    mis-clicked points)."""
    if not pull or pull["held_short"] <= _HELD_SHORT_TOLERANCES * pull["tolerance"]:
        return []
    return [f"scan landmarks: {pull['held_back']} of {len(problem.targets)} landmarks "
            f"were not pulled onto their targets, as that would fold the surface "
            f"between them (left up to {pull['held_short']:.3g} scan units short): "
            f"they disagree with each other or with the scan's surface; check the "
            f"landmark file (noisy or mis-clicked points?)"]
