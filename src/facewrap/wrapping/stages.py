"""``wrap``: register a template onto a scan, keeping the template's topology.

The pipeline (SPEC §1; the non-rigid ICP models of §2 plug in as further steps):

    landmark pairs → similarity (Umeyama) → RBF warp of landmark displacements
    → projection onto the scan along normals, smooth where not projected
    → the template's mesh with new vertex positions (same count, order, faces, UVs)

:func:`wrap` returns a :class:`WrapResult` with the fitted mesh, what happened at
each stage, timings and fit metrics; nothing here reads or writes files.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field, replace

import numpy as np

from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.wrapping.align import rigid_icp
from facewrap.geometry import ClosestPointTree, connected_components
from facewrap.wrapping.icp.engine import NonRigidICP, Stage, default_schedule
from facewrap.landmarks import Landmarks, pair_landmarks, snap_to_surface
from facewrap.mesh import Mesh
from facewrap.wrapping.models.affine import AffineModel
from facewrap.wrapping.models.blendshape import (BlendshapeModel, BlendshapeParams, RigidModel,
                                blendshape_basis)
from facewrap.wrapping.models.graph import GraphModel, build_graph
from facewrap.wrapping.models.hybrid import HybridModel, HybridParams
from facewrap.params import (Empty, Flag, Instances, Interval, NoneAllowed, Options, Pair,
                             validate)
from facewrap.wrapping.warp import KERNELS, RBFWarp, pull_to_landmarks
from facewrap.wrapping.icp.terms import ROBUST_NORMS, landmark_rows
from facewrap.wrapping.projection import Projection, project_to_surface

__all__ = ["WrapSettings", "WrapResult", "wrap", "MODELS"]

MODELS = ("auto", "rigid", "rbf", "affine", "graph", "blendshape", "hybrid")
#: the models fitted by non-rigid ICP (the others are closed-form)
NONRIGID_MODELS = ("affine", "graph", "blendshape", "hybrid")


@dataclass
class WrapSettings:
    """Settings of a wrap (no work is done here; see :func:`wrap`).

    Every field is also a key of the ``[wrap]`` table of a job file and (for the
    common ones) a ``facewrap wrap`` option.

    Attributes
    ----------
    model : {"auto", "rigid", "rbf", "affine", "graph", "blendshape", "hybrid"}
        Deformation after the similarity.  "rigid": none; "rbf": landmark RBF warp
        only; the others run non-rigid ICP (SPEC §2) with that deformation model.
        "auto" is "hybrid" when blendshapes are given, else "graph".
    scale : bool
        Let the similarity scale the template.
    rigid_refine : bool
        Refine the similarity with trimmed point-to-plane ICP (good when landmarks
        are few or noisy; off by default because expressions bias it).
    kernel, smoothing : see :class:`~facewrap.wrapping.warp.RBFWarp`.
    project : bool
        Move vertices onto the scan at the end (SPEC §1.3).
    max_distance : float, optional
        Longest projection move / correspondence distance at the end; default 5 %
        of the template size.
    max_normal_angle : float
        Degrees; larger differences between template and scan normals are rejected.
    blend_order : {1, 2}
        Harmonic (default) or biharmonic blending of the displacement of
        vertices that are not projected.  Biharmonic is smoother where projected
        and blended vertices meet but overshoots over large unprojected regions
        (the parts of a template a scan does not cover): on menpo's james scan
        its blend folded 229 template triangle pairs, the harmonic one 72
        (with the projection's fold guard; the ICP result had 26).
    stages : list of Stage, optional
        The non-rigid ICP schedule (stiff to loose); None = the model's default
        (see :func:`facewrap.wrapping.icp.engine.default_schedule`).
    node_spacing : float, optional
        Deformation-graph node spacing as a fraction of the template's bounding
        box diagonal (default 0.05: ~200 nodes on a face).
    point_weight : float
        Weight of point-to-point against point-to-plane (weight 1) in the data term.
    robust : {"welsch", "huber", "geman_mcclure", "none"}
        IRLS norm of the data term; its scale comes from the residuals and is
        annealed.
    pca_components : int, optional
        Fit this many PCA components of the blendshapes instead of the raw shapes.
    weight_range : (lo, hi), optional
        Range of the blend weights (an expression rig's [0, 1]); a one-sided
        quadratic penalty (``Stage.bound_weight``) keeps them inside, so
        opposing shapes cannot cancel each other with negative weights.  Empty
        or None: unbounded.  Not applied to PCA components.
    reject_boundary : bool
        Ignore correspondences on the scan's border (holes, crop).
    landmark_scale : float
        Multiplies the landmark weight of every ICP stage, the coarse pre-fit's
        included: how much the landmarks are trusted.  :func:`facewrap.wrapping.track.track`
        uses 0.05 for frames whose landmarks are only carried over from the
        previous frame, so they guard against gross failure without holding the
        face where it was.
    landmark_pull : bool
        After a non-rigid fit (not "rigid" or "rbf"), pull landmarks left farther
        than ``landmark_tolerance`` from their targets to that distance, by a
        local smooth displacement (:func:`~facewrap.wrapping.warp.pull_to_landmarks`)
        before the projection.  The ICP's late stages weigh landmarks lightly,
        since they are less accurate than the scan surface; on a real scan of
        another identity (menpo's james, ICT template) that left them 1.43 mm
        off on average, 3.7 mm at worst.  With the pull: 0.79 / 1.59 mm, and the
        fit away from the borders 0.50 → 0.44 mm (``bench_realscan``); on the
        ground-truth cases of ``bench_nicp`` (landmarks with 0.5 mm noise) the
        hybrid's mean error moved by at most 0.01 mm.
    landmark_tolerance : float
        How far a landmark may stay from its target, as a fraction of the
        template's size (default 0.002, about 0.5 mm on a head); 0 keeps
        landmarks exactly, which cost the ground-truth cases up to 0.18 mm:
        pin only landmarks you trust.
    """
    model: str = "auto"
    scale: bool = True
    rigid_refine: bool = False
    kernel: str = "biharmonic"
    smoothing: float = 0.0
    project: bool = True
    max_distance: float | None = None
    max_normal_angle: float = 60.0
    blend_order: int = 1
    stages: list[Stage] | None = None
    node_spacing: float = 0.05
    point_weight: float = 0.1
    robust: str = "welsch"
    pca_components: int | None = None
    weight_range: tuple[float, ...] | None = (0.0, 1.0)
    reject_boundary: bool = True
    landmark_scale: float = 1.0
    landmark_pull: bool = True
    landmark_tolerance: float = 0.002

    #: allowed values of every field, checked at construction (:mod:`facewrap.params`);
    #: the CLI and job files take their choices from here
    constraints = {
        "model": Options(*MODELS),
        "scale": Flag(),
        "rigid_refine": Flag(),
        "kernel": Options(*KERNELS),
        "smoothing": Interval(float, 0, None),
        "project": Flag(),
        "max_distance": (NoneAllowed(), Interval(float, 0, None, closed="neither")),
        "max_normal_angle": Interval(float, 0, 180, closed="right"),
        "blend_order": Options(1, 2),
        "stages": (NoneAllowed(), Instances(Stage)),
        "node_spacing": Interval(float, 0, 1, closed="right"),
        "point_weight": Interval(float, 0, None),
        "robust": Options(*ROBUST_NORMS),
        "pca_components": (NoneAllowed(), Interval(int, 1, None)),
        "weight_range": (NoneAllowed(), Empty(), Pair(Interval(float, None, None))),
        "reject_boundary": Flag(),
        "landmark_scale": Interval(float, 0, None),
        "landmark_pull": Flag(),
        "landmark_tolerance": Interval(float, 0, None),
    }

    def __post_init__(self):
        validate(self)
        if self.weight_range is not None:
            r = tuple(float(x) for x in self.weight_range)
            self.weight_range = r or None

    def blend_bounds(self):
        """The weight range the blend models use (None: unbounded)."""
        return None if self.pca_components else self.weight_range


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
        Vertices to include in the fit statistics (e.g. not excluded ones).

    Fit distances are taken over the vertices whose closest scan point is not on
    the scan's border (``fit_coverage`` is their fraction): a template usually
    covers more than the scanner saw.
    """
    V = np.asarray(vertices)
    cp = tree.query(V)
    # Only vertices the scan covers count: where the closest point is on the scan's
    # border (holes, cropped regions) the template has nothing to fit to.
    covered = ~tree.boundary_triangles[cp.triangles]
    if mask is not None:
        covered &= mask
    d = cp.distances[covered] if covered.any() else cp.distances
    out = {"fit_mean": float(d.mean()), "fit_p95": float(np.percentile(d, 95)),
           "fit_max": float(d.max()), "fit_coverage": float(covered.mean())}
    if landmark_positions is not None:
        e = np.linalg.norm(np.asarray(landmark_positions) - np.asarray(scan_landmarks),
                           axis=1)
        out.update(landmark_mean=float(e.mean()), landmark_max=float(e.max()))
    return out


def wrap(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
         scan_landmarks: Landmarks, settings: WrapSettings | None = None, *,
         exclude=None, blendshapes=None,
         scan_tree: ClosestPointTree | None = None,
         initial: WrapResult | None = None) -> WrapResult:
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
        Template vertices that must not be pulled onto the scan (eyes, mouth
        interior...): they follow smoothly.
    blendshapes : dict name -> (n, 3) float, optional
        Shapes in the template's topology (positions, not deltas), for the
        "blendshape" and "hybrid" models.
    scan_tree : ClosestPointTree, optional
        Reuse a tree already built on the scan.
    initial : WrapResult, optional
        A previous result of the same template (the previous frame of a
        sequence): its similarity replaces the landmark alignment and its blend
        weights start the fit.

    Returns
    -------
    WrapResult
    """
    s = replace(settings or WrapSettings())
    if s.model not in MODELS:
        raise ValueError(f"model must be one of {MODELS}, got {s.model!r}")
    if s.model == "auto":
        s.model = "hybrid" if blendshapes else "graph"
    if s.model in ("blendshape", "hybrid") and not blendshapes:
        raise ValueError(f"model {s.model!r} needs blendshapes")
    timings = {}
    t0 = time.perf_counter()
    if not template_landmarks.on_mesh:
        template_landmarks = _snapped_template_landmarks(template, template_landmarks)
    ia, ib = pair_landmarks(template_landmarks, scan_landmarks)
    if len(ia) < 3:
        raise ValueError(f"need at least 3 landmark pairs, got {len(ia)}")
    src = template_landmarks.positions(template)[ia]
    dst = scan_landmarks.positions(scan)[ib]
    n = template.n_vertices
    excluded = np.zeros(n, dtype=bool)
    if exclude is not None:
        ex = np.asarray(exclude)
        if ex.dtype == bool:
            if ex.shape != (n,):
                raise ValueError(f"exclude mask must have shape ({n},)")
            excluded = ex.copy()
        else:
            if len(ex) and (ex.min() < 0 or ex.max() >= n):
                raise ValueError(f"exclude holds vertex ids outside [0, {n})")
            excluded[ex.astype(np.int64)] = True

    tree = scan_tree if scan_tree is not None else ClosestPointTree(scan.vertices,
                                                                    scan.triangles)
    timings["setup"] = time.perf_counter() - t0

    t = time.perf_counter()
    if initial is not None:
        T = initial.transform
    else:
        T = similarity_transform(src, dst,
                                 weights=_alignment_weights(template_landmarks, ia),
                                 scale=s.scale)
    if s.rigid_refine:
        T = rigid_icp(template.vertices[~excluded], tree, init=T,
                      max_distance=0.05 * scan.scale()).transform
    V = T.apply(template.vertices)
    timings["align"] = time.perf_counter() - t

    t = time.perf_counter()
    history, weights, names = [], None, []
    if s.model == "rbf":
        lm_now = template_landmarks.positions(V, template.triangles)[ia]
        warp = RBFWarp(kernel=s.kernel, smoothing=s.smoothing).fit(lm_now, dst - lm_now)
        V = warp.transform(V)
    elif s.model in NONRIGID_MODELS:
        w_init = None if initial is None else initial.weights
        fitted = _nonrigid_icp(template, V, T, tree, template_landmarks.subset(ia), dst,
                               s, excluded, blendshapes, w_init, warm=initial is not None)
        V, history, weights, names, timings["model_setup"] = fitted
    # "model_setup" (graph, coarse pre-fit) and "icp" are disjoint parts of the run
    timings["warp" if s.model == "rbf" else "icp"] = (time.perf_counter() - t
                                                      - timings.get("model_setup", 0.0))
    pull = None
    if s.model in NONRIGID_MODELS and s.landmark_pull:
        t = time.perf_counter()
        V, pull = _pull_landmarks(template, V, template_landmarks.subset(ia), dst,
                                  s.landmark_tolerance, excluded)
        timings["landmark_pull"] = time.perf_counter() - t

    projection = None
    out = V
    t = time.perf_counter()
    if s.project:
        projection = project_to_surface(
            template, tree, vertices=V, mask=~excluded, max_distance=s.max_distance,
            max_normal_angle=s.max_normal_angle, blend_order=s.blend_order)
        out = projection.vertices
    timings["project"] = time.perf_counter() - t
    timings["total"] = time.perf_counter() - t0

    metrics = fit_metrics(out, tree,
                          template_landmarks.positions(out, template.triangles)[ia], dst,
                          mask=~excluded)
    if projection is not None:
        metrics["projection"] = projection.summary()
    if pull is not None:
        metrics["landmark_pull"] = pull
    return WrapResult(template.with_vertices(out), T, V, projection, timings, metrics,
                      settings=s, history=history, weights=weights, shape_names=names)


def _pull_landmarks(template: Mesh, V, landmarks: Landmarks, targets, tolerance: float,
                    excluded) -> tuple[np.ndarray, dict]:
    """``WrapSettings.landmark_pull``: landmarks farther than ``tolerance`` (fraction
    of the size of ``V``) from their targets are pulled to it.  Excluded islands
    (eyeballs, teeth) move by their mean pull, so they keep their shape."""
    size = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    moved, pulls = pull_to_landmarks(V, landmarks.positions(V, template.triangles),
                                     targets, tolerance * size)
    if excluded.any() and pulls.any():
        T = template.triangles
        island = connected_components(T[excluded[T].all(axis=1)], len(V))[excluded]
        shift = moved[excluded] - V[excluded]
        count = np.bincount(island)
        mean = np.stack([np.bincount(island, shift[:, c]) for c in range(3)], 1)
        moved[excluded] = V[excluded] + mean[island] / count[island, None]
    return moved, {"tolerance": tolerance * size, "pulled": int(np.count_nonzero(pulls)),
                   "mean": float(pulls.mean()), "max": float(pulls.max())}


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


def _alignment_weights(landmarks: Landmarks, index) -> np.ndarray:
    """Weights of landmark pairs in the similarity: the jaw line and the mouth
    move with expressions (a scan with the jaw open would bias the scale and
    tilt), so when landmarks are named, those get a small weight."""
    if landmarks.names is None:
        return np.ones(len(index))
    names = [landmarks.names[i] for i in index]
    moving = np.array([n.startswith(("jaw", "mouth", "chin", "lip")) for n in names])
    if (~moving).sum() < 4:
        return np.ones(len(index))
    return np.where(moving, 0.05, 1.0)


#: deformation graphs by (template content, spacing), most recent last
_GRAPHS: "OrderedDict[tuple, object]" = OrderedDict()
_GRAPH_CACHE_SIZE = 8


def _template_graph(template: Mesh, spacing: float):
    """The deformation graph of a template, built once per template and spacing.

    Nodes and skinning depend only on the template's surface (geodesic
    distances in the normalised frame, which a similarity does not change), so
    every scan of a batch or frame of a sequence reuses it.  The key is the
    template's content, not the object: batch jobs read the template afresh
    and still share one graph.
    """
    V = np.ascontiguousarray(template.vertices)
    T = np.ascontiguousarray(template.triangles)
    key = (hashlib.sha1(V.tobytes() + T.tobytes()).hexdigest(), V.shape, T.shape,
           float(spacing))
    if key in _GRAPHS:
        _GRAPHS.move_to_end(key)
        return _GRAPHS[key]
    size = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    graph = build_graph((V - V.mean(axis=0)) / size, T, spacing=spacing)
    _GRAPHS[key] = graph
    while len(_GRAPHS) > _GRAPH_CACHE_SIZE:
        _GRAPHS.popitem(last=False)
    return graph


def _stage_groups(stages, by_graph: bool) -> list[tuple[float, list]]:
    """Consecutive stages that share a node spacing (graph models), as
    ``(factor, stages)``; one group for other models."""
    if not by_graph:
        return [(1.0, list(stages))]
    groups: list[tuple[float, list]] = []
    for st in stages:
        if groups and groups[-1][0] == st.node_spacing_factor:
            groups[-1][1].append(st)
        else:
            groups.append((st.node_spacing_factor, [st]))
    return groups


def _nonrigid_icp(template, V, T, tree, landmarks, targets, s, excluded, blendshapes,
                  w_init=None, warm: bool = False):
    """Non-rigid ICP from the similarity-aligned template ``V``.

    Returns (vertices, history, blend weights or None, shape names, setup seconds).
    """
    t0 = time.perf_counter()
    # the engine's normalised frame: centred, unit bounding-box diagonal
    center = V.mean(axis=0)
    size = float(np.linalg.norm(V.max(axis=0) - V.min(axis=0)))
    base = (V - center) / size
    deltas, names = np.zeros((3 * len(V), 0)), []
    if s.model in ("blendshape", "hybrid"):
        neutral = template.vertices
        D, names = blendshape_basis(neutral, blendshapes, s.pca_components)
        # deltas live in the template's frame: rotate and scale them like the template
        D = D.reshape(len(V), 3, -1)
        deltas = (T.scale * np.einsum("ab,nbk->nak", T.rotation, D) / size
                  ).reshape(3 * len(V), -1)
    L = landmark_rows(landmarks, len(V), template.triangles)
    lm_targets = (targets - center) / size
    max_distance = (s.max_distance / size if s.max_distance else 0.05)

    def fit(model, stages, params=None):
        engine = NonRigidICP(stages, point_weight=s.point_weight, robust=s.robust,
                             max_distance=max_distance,
                             max_normal_angle=s.max_normal_angle,
                             reject_boundary=s.reject_boundary)
        return engine.fit(model, template.triangles, tree, center=center, size=size,
                          fit_mask=~excluded, landmark_matrix=L,
                          landmark_targets=lm_targets, params=params)

    history = []
    w0 = None
    if s.model in ("affine", "graph", "hybrid"):
        # coarse first: the whole template's pose and scale (with blend weights for
        # the hybrid) before local deformation, which resists global scaling
        if s.model == "hybrid":
            pre = BlendshapeModel(base, deltas, scale=s.scale, bounds=s.blend_bounds())
        else:
            pre = RigidModel(base, scale=s.scale)
        p_init = None
        if s.model == "hybrid" and w_init is not None and len(w_init) == deltas.shape[1]:
            p_init = BlendshapeParams(np.eye(3), np.zeros(3), 1.0, np.asarray(w_init))
        # the coarse pre-fit keeps its own stages, on a third of the vertices
        # throughout (the main fit refines afterwards); warm-started (tracking),
        # it skips the landmark-only stage: the start is already close
        pre_stages = [replace(st, sample=min(st.sample, 0.3),
                              landmark_weight=st.landmark_weight * s.landmark_scale)
                      for st in default_schedule("blendshape" if s.model == "hybrid"
                                                 else "rigid")
                      if not (warm and st.data_weight == 0)]
        coarse = fit(pre, pre_stages, p_init)
        history += [dict(h, model="pre-" + ("blendshape" if s.model == "hybrid"
                                            else "rigid")) for h in coarse.history_]
        p0 = coarse.params_
        base = (coarse.vertices_ - center) / size if s.model != "hybrid" else \
            pre.vertices(BlendshapeParams(p0.R, p0.t, p0.s, np.zeros_like(p0.w)))
        if s.model == "hybrid":
            D = deltas.reshape(len(V), 3, -1)
            deltas = (p0.s * np.einsum("ab,nbk->nak", p0.R, D)).reshape(3 * len(V), -1)
            w0 = p0.w
    stages = [replace(st, landmark_weight=st.landmark_weight * s.landmark_scale)
              for st in (s.stages or default_schedule(s.model))]
    groups = _stage_groups(stages, s.model in ("graph", "hybrid"))
    if s.model in ("graph", "hybrid"):
        graph = _template_graph(template, s.node_spacing * groups[0][0])
    if s.model == "affine":
        model = AffineModel(base, template.triangles)
    elif s.model == "graph":
        model = GraphModel(base, graph)
    elif s.model == "blendshape":
        model = BlendshapeModel(base, deltas, scale=s.scale, bounds=s.blend_bounds())
    else:
        model = HybridModel(base, deltas, graph, bounds=s.blend_bounds())
    setup = time.perf_counter() - t0
    params = None
    if w0 is not None:
        params = HybridParams(model.initial_params().graph, w0)
    first = 0                       # index of the group's first stage
    for factor, group in groups:
        if s.model in ("graph", "hybrid") and first > 0:
            # coarse-to-fine: the next graph continues the deformation so far
            graph = _template_graph(template, s.node_spacing * factor)
            model, params = model.on_graph(graph, params if params is not None
                                           else model.initial_params())
        icp = fit(model, group, params)
        params = icp.params_
        nodes = getattr(getattr(model, "graph", None), "n_nodes", None)
        history += [dict(h, model=s.model, stage=h["stage"] + first, nodes=nodes)
                    for h in icp.history_]
        first += len(group)
    w = getattr(icp.params_, "w", None)
    return icp.vertices_, history, w, names, setup
