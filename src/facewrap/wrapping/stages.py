"""``wrap``: register a template onto a scan, keeping the template's topology.

The pipeline (SPEC §1–§2), one named function per stage, each testable alone:

    :func:`prepare_wrap`  the inputs checked, landmarks paired, the scan's tree
    :func:`align`         landmark similarity (Umeyama), optionally refined by rigid ICP
    :func:`fit_model`     the model of the registry entry: closed form (rigid, rbf)
                          or coarse pre-fit + non-rigid ICP (:mod:`.model_fit`)
    :func:`pull_landmarks` landmarks left far from their targets pulled to them
    :func:`project`       onto the scan along normals, smooth where not projected
    :func:`finish_fit`    pinned vertices back, folds unfolded, parts follow the skin
    :func:`fit_metrics`   distances to the scan and landmark errors

:func:`wrap` runs them in this order and returns a :class:`WrapResult` with the
fitted mesh (same vertex count, order, faces and UVs as the template), what
happened at each stage, timings and metrics; nothing here reads or writes files.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from facewrap.evaluate import surface_distances
from facewrap.geometry import ClosestPointTree, connected_components
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.landmarks import Landmarks, pair_landmarks, snap_to_surface
from facewrap.mesh import Mesh
from facewrap.progress import progress
from facewrap.wrapping.align import rigid_icp
from facewrap.wrapping.follow import follow_skin
from facewrap.wrapping.model_fit import ModelFit, coarse_fit, icp_fit, icp_start
from facewrap.wrapping.plausibility import (LACY_LIMIT, border_fraction, check_landmarks,
                                           check_scale, check_unscaled_size, checked_scan)
from facewrap.wrapping.models import ModelSpec, model_spec
from facewrap.wrapping.models.graph import DEFAULT_GRAPH_CACHE, GraphCache
from facewrap.wrapping.blend import smooth_extension
from facewrap.wrapping.projection import Projection, project_to_surface, seen_fit_p95
from facewrap.wrapping.seams import seam_weld
from facewrap.wrapping.roles import (FITTED, PART, PINNED, cached_hidden_surface,
                                     vertex_roles)
from facewrap.wrapping.settings import WrapSettings
from facewrap.wrapping.unfold import (relax_flips, settle_turned_corners,
                                     step_back_new_folds, unfold_among)
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


@dataclass(frozen=True, eq=False)
class WrapProblem:
    """The checked inputs of a wrap (made by :func:`prepare_wrap`).

    Attributes
    ----------
    template : Mesh
    scan : Mesh
        The scan as fitted: without duplicated faces, faces turned the template's
        way (see ``warnings``).
    tree : ClosestPointTree
        Its tree.
    landmarks : Landmarks
        Template landmarks on the mesh that have a scan partner, in pair order.
    sources : (l, 3) float64
        Their positions on the template.
    targets : (l, 3) float64
        Their partners' positions on the scan.
    alignment_weights : (l,) float64
        Weights of the pairs in the similarity.
    roles : (n,) int8
        Role of each template vertex (:func:`facewrap.wrapping.roles.vertex_roles`).
    excluded : (n,) bool
        Template vertices not pulled onto the scan (``roles != FITTED``).
    blendshapes : dict or None
    settings : WrapSettings
        With ``model`` resolved from "auto".
    spec : ModelSpec
        The model's registry entry.
    graph_cache : GraphCache
    warnings : tuple of str
        The plausibility checks' warnings.
    """
    template: Mesh
    scan: Mesh
    tree: ClosestPointTree
    landmarks: Landmarks
    sources: np.ndarray
    targets: np.ndarray
    alignment_weights: np.ndarray
    roles: np.ndarray
    excluded: np.ndarray
    blendshapes: dict | None
    settings: WrapSettings
    spec: ModelSpec
    graph_cache: GraphCache
    warnings: tuple = ()


def prepare_wrap(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
                 scan_landmarks: Landmarks, settings: WrapSettings | None = None, *,
                 exclude=None, fit_mask=None, pinned=None, blendshapes=None,
                 scan_tree: ClosestPointTree | None = None,
                 graph_cache: GraphCache | None = None) -> WrapProblem:
    """Check a wrap's inputs, resolve its model and pair its landmarks.

    Parameters are those of :func:`wrap`.

    Returns
    -------
    WrapProblem

    Raises
    ------
    ValueError
        For a model that needs blendshapes without them, fewer than 3 landmark
        pairs, template landmarks far off the template, landmarks that only a
        mirror image matches (unless ``settings.allow_mirrored``), or a bad
        ``exclude``, ``fit_mask`` or ``pinned``.
    """
    s = replace(settings or WrapSettings())
    spec = model_spec(s.model, has_blendshapes=bool(blendshapes))
    s.model = spec.name
    if spec.needs_blendshapes and not blendshapes:
        raise ValueError(f"model {s.model!r} needs blendshapes")
    if not template_landmarks.on_mesh:
        template_landmarks = _snapped_template_landmarks(template, template_landmarks)
    try:
        ia, ib = pair_landmarks(template_landmarks, scan_landmarks, ("template", "scan"))
    except ValueError as exc:  # say what it is about, so a job can name the file
        raise ValueError(f"scan landmarks: {exc}") from None
    if len(ia) < 3:
        raise ValueError(f"need at least 3 landmark pairs, got {len(ia)}")
    hidden = (cached_hidden_surface(template.vertices, template.triangles)
              if not s.fit_hidden and fit_mask is None else None)
    roles = vertex_roles(template.n_vertices, hidden, exclude=exclude, fit_mask=fit_mask,
                         pinned=pinned)
    excluded = roles != FITTED
    template_points = template_landmarks.positions(template)
    scan_points = scan_landmarks.positions(scan)
    weights = alignment_weights(template_landmarks, ia)
    notes, similarity = check_landmarks(template_landmarks, template_points,
                                        scan_landmarks, scan_points, (ia, ib), weights,
                                        scale=s.scale, allow_mirrored=s.allow_mirrored)
    aligned = None
    if similarity is not None:
        notes += check_scale(similarity.scale)
        aligned = similarity.apply(template.vertices)
    if not s.scale:
        notes += check_unscaled_size(template_points[ia], scan_points[ib], weights)
    scan, tree, scan_notes = checked_scan(scan, scan_tree, aligned, template.triangles,
                                          mask=~excluded)
    bordered = border_fraction(tree)
    if s.reject_boundary and bordered > LACY_LIMIT:
        s.reject_boundary = False
        scan_notes.append(f"scan: {100 * bordered:.0f} % of its triangles "
                          "touch a border (full of holes, or a triangle soup?): the ICP "
                          "keeps scan points near borders (reject_boundary off), the "
                          "projection still leaves them")
    return WrapProblem(template, scan, tree, template_landmarks.subset(ia),
                       template_points[ia], scan_points[ib], weights, roles, excluded,
                       blendshapes, s, spec,
                       DEFAULT_GRAPH_CACHE if graph_cache is None else graph_cache,
                       tuple(notes + scan_notes))


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
    start = icp_start(template, vertices, similarity, problem.landmarks, problem.targets,
                      spec, problem.blendshapes, s.pca_components)
    start, history = coarse_fit(start, spec, s, template, problem.tree, problem.excluded,
                                warm_weights=None if initial is None else initial.weights,
                                warm=initial is not None)
    fitted = icp_fit(start, spec, s, template, problem.tree, problem.excluded,
                     problem.graph_cache, t0)
    fitted.history = history + fitted.history
    return fitted


def pull_landmarks(problem: WrapProblem, vertices) -> tuple[np.ndarray, dict]:
    """``WrapSettings.landmark_pull``: landmarks farther than ``landmark_tolerance``
    (fraction of the size of ``vertices``) from their targets are pulled to it.

    Excluded islands (eyeballs, teeth) move by their mean pull, so they keep their
    shape.

    Returns
    -------
    vertices : (n, 3) float64
    summary : dict
        Tolerance, how many landmarks were pulled, mean and largest pull.
    """
    V, T, excluded = vertices, problem.template.triangles, problem.excluded
    tolerance = problem.settings.landmark_tolerance
    size = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    moved, pulls = pull_to_landmarks(V, problem.landmarks.positions(V, T),
                                     problem.targets, tolerance * size)
    if excluded.any() and pulls.any():
        island = connected_components(T[excluded[T].all(axis=1)], len(V))[excluded]
        shift = moved[excluded] - V[excluded]
        count = np.bincount(island)
        mean = np.stack([np.bincount(island, shift[:, c]) for c in range(3)], 1)
        moved[excluded] = V[excluded] + mean[island] / count[island, None]
    return moved, {"tolerance": tolerance * size, "pulled": int(np.count_nonzero(pulls)),
                   "mean": float(pulls.mean()), "max": float(pulls.max())}


#: Smoothing order of unfolding and pinning (harmonic): a biharmonic relaxation
#: overshoots and unfolds less (ICT's face region onto james: 12 triangles left
#: flipped, against 0).
_UNFOLD_ORDER = 1


def project(problem: WrapProblem, vertices, upright=None, reference=None
            ) -> Projection | None:
    """Projection onto the scan (None when ``settings.project`` is off); ``upright``:
    positions whose triangle orientation it must keep; ``reference``: the
    orientation its biharmonic fill must keep (see
    :func:`~facewrap.wrapping.projection.project_to_surface`)."""
    s = problem.settings
    if not s.project:
        return None
    return project_to_surface(problem.template, problem.tree, vertices=vertices,
                              mask=~problem.excluded, max_distance=s.max_distance,
                              max_normal_angle=s.max_normal_angle,
                              blend_order=s.blend_order, upright=upright,
                              reference=reference)


def pin(problem: WrapProblem, vertices, similarity: Similarity,
        projection: Projection | None) -> np.ndarray:
    """Pinned vertices back where ``similarity`` puts them, the rest blended.

    Projected vertices stay on the scan; pinned ones move to their aligned
    template positions exactly; every other vertex takes the harmonic
    extension of those two displacements, so nothing tears where pinned and
    fitted regions meet (a biharmonic one overshoots across the large regions
    between them).

    Returns
    -------
    (n, 3) float64
        ``vertices`` unchanged when nothing is pinned.
    """
    pinned = problem.roles == PINNED
    if not pinned.any():
        return vertices
    template = problem.template
    known = pinned.copy()
    if projection is not None:
        known |= projection.projected
    displacement = np.zeros_like(vertices)
    displacement[pinned] = similarity.apply(template.vertices[pinned]) - vertices[pinned]
    return vertices + smooth_extension(template, displacement, known,
                                       order=_UNFOLD_ORDER)


def finish_fit(problem: WrapProblem, vertices, similarity: Similarity,
               projection: Projection | None, rest=None) -> tuple[np.ndarray, dict]:
    """The last stage: triangles the fit turned over unfolded (``settings.unfold``,
    :func:`~facewrap.wrapping.unfold.relax_flips`) and the result projected
    again from there, pinned vertices put back (:func:`pin`), the template's parts
    moved with the skin nearest to them and kept on their side of it
    (:mod:`facewrap.wrapping.follow`).

    Folds the first pass leaves (its regions share a budget) are unfolded again,
    each in a region as wide as it needs (:data:`_WIDE_UNFOLD`).  ``rest`` (n, 3)
    is the pose a triangle is turned over from: the expression the blend weights
    make (:attr:`ModelFit.rest`), so a lip rolled by a pucker shape is not
    "unfolded"; default the aligned template.

    Returns
    -------
    vertices : (n, 3) float64
    summary : dict
        ``pinned`` and ``unfolded`` (vertices).
    """
    template, roles = problem.template, problem.roles
    aligned = similarity.apply(template.vertices)
    summary = {"pinned": int(np.count_nonzero(roles == PINNED)), "unfolded": 0}
    out = vertices
    if problem.settings.unfold:
        upright = aligned if rest is None else rest
        relaxed, settled = np.zeros((2, len(out)), dtype=bool)
        for extra in ({}, _WIDE_UNFOLD):
            out, more = relax_flips(template, upright, out, fixed=roles == PINNED,
                                    order=_UNFOLD_ORDER, **extra)
            if more.any() and projection is not None:
                out, projection, again = _project_unfolded(
                    problem, upright, out, projection, more if extra else None)
                more |= again
            relaxed |= more
            # slivers, one corner each (the second pass would smooth wide in vain)
            out, corners = settle_turned_corners(
                template, upright, out, movable=(roles != PINNED) & (roles != PART))
            settled |= corners
        summary["unfolded"], summary["settled"] = int(relaxed.sum()), int(settled.sum())
    out = pin(problem, out, similarity, projection)
    out = follow_skin(template.triangles, aligned, out, roles)
    return out, summary


#: the second unfolding pass: each fold the first left in a region of its own, as
#: wide as it needs up to 12 rings (kept only if it unfolds), no budget shared
_WIDE_UNFOLD = {"rounds": 12, "most_relaxed": None, "each_region": True}


def _project_unfolded(problem: WrapProblem, upright, unfolded, projection: Projection,
                      region=None) -> tuple[np.ndarray, Projection, np.ndarray]:
    """``unfolded`` onto the scan again, keeping the orientation of ``upright``
    (what the new blend turns over unfolded among the vertices not projected,
    what still folds stepped back toward ``unfolded``).  With ``region`` (n,)
    bool, either every vertex or only the region's take the new landing points,
    whichever fits tighter (:func:`~facewrap.wrapping.projection.seen_fit_p95`):
    landing everything again can lose more elsewhere than the region gains.
    Returns the positions, projection and moved vertices."""
    T, roles = problem.template.triangles, problem.roles
    again = project(problem, unfolded, upright=upright)
    landed, moved = unfold_among(problem.template, upright, again.vertices,
                                 (roles != PINNED) & ~again.projected,
                                 counted=(roles[T] != PART).all(axis=1))
    picks = [(landed, again, moved)] + ([] if region is None else [
        (np.where(region[:, None], landed, unfolded), projection, moved & region)])
    stepped = [(step_back_new_folds(T, upright, unfolded, out, roles == PINNED), kept,
                moved) for out, kept, moved in picks]
    (out, back), kept, moved = min(stepped, key=lambda c: seen_fit_p95(
        problem.tree, c[0][0][roles == FITTED]))     # the first of equals: everything
    return out, kept, moved | back


def _timed(timings: dict, key: str, bar, stage, *args, **kw):
    """``stage(*args, **kw)``, its seconds in ``timings[key]``, one step of ``bar``."""
    t = time.perf_counter()
    out = stage(*args, **kw)
    timings[key] = time.perf_counter() - t
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
        The only vertices pulled onto the scan (replaces the automatic choice of
        ``fit_hidden``; ``exclude`` still applies).
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
    """
    weld = seam_weld(template, blendshapes)
    if weld is not None:   # one surface where an exporter split the template (.seams)
        return weld.unweld(wrap(
            weld.mesh, scan, weld.landmarks(template_landmarks), scan_landmarks, settings,
            exclude=weld.vertex_set(exclude), fit_mask=weld.vertex_set(fit_mask),
            pinned=weld.vertex_set(pinned), blendshapes=weld.shapes(blendshapes),
            scan_tree=scan_tree, initial=initial, graph_cache=graph_cache), template)
    timings = {}
    t0 = time.perf_counter()
    # on a terminal, one line that says which stage runs (the ICP draws its own bars)
    with progress(6, "wrap: checking the inputs") as bar:
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

        pull = None
        if problem.spec.fitted_by_icp and problem.settings.landmark_pull:
            bar.update(description="wrap: pulling landmarks")
            V, pull = _timed(timings, "landmark_pull", bar, pull_landmarks, problem, V)
        else:
            bar.advance()
        bar.update(description="wrap: projecting onto the scan")
        rest = (similarity.apply(template.vertices) if fitted.rest is None
                else fitted.rest)
        projection = _timed(timings, "project", bar, project, problem, V, reference=rest)
        bar.update(description="wrap: unfolding, parts following")
        out, finish = _timed(timings, "finish", bar, finish_fit, problem,
                             V if projection is None else projection.vertices,
                             similarity, projection, rest=fitted.rest)
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
                      warnings=list(problem.warnings), roles=problem.roles)


#: template landmarks given as points may lie this far off the template's surface
#: (fraction of its bounding-box diagonal) and still be snapped onto it
SNAP_TOLERANCE = 0.02


def _snapped_template_landmarks(template: Mesh, landmarks: Landmarks) -> Landmarks:
    """Template landmarks given as x, y, z points, moved onto the template's
    surface so they follow it; an error names one that is far off (a point set
    meant for another mesh or in other units)."""
    snapped, moved = snap_to_surface(landmarks, template.vertices, template.triangles)
    limit = SNAP_TOLERANCE * template.scale()
    if (moved > limit).any():
        i = int(np.argmax(moved))
        raise ValueError(f"template landmark {landmarks.label(i)} lies {moved[i]:.4g} "
                         f"from the template's surface (more than {limit:.4g}, "
                         f"{100 * SNAP_TOLERANCE:g} % of its size): landmarks for another "
                         "mesh or in other units?")
    return snapped


def alignment_weights(landmarks: Landmarks, index) -> np.ndarray:
    """Weights of landmark pairs in the similarity: the jaw line and the mouth
    move with expressions (a scan with the jaw open would bias the scale and
    tilt), so when landmarks are named, those get a small weight.

    Parameters
    ----------
    landmarks : Landmarks
        The template landmarks (names, if any, decide the weights).
    index : (l,) int
        The landmarks that have a partner, in pair order.

    Returns
    -------
    (l,) float64
        1 for stable landmarks, 0.05 for moving ones (all 1 when unnamed or when
        fewer than 4 stable ones remain).
    """
    if landmarks.names is None:
        return np.ones(len(index))
    names = [landmarks.names[i] for i in index]
    moving = np.array([n.startswith(("jaw", "mouth", "chin", "lip")) for n in names])
    if (~moving).sum() < 4:
        return np.ones(len(index))
    return np.where(moving, 0.05, 1.0)
