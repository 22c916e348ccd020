"""The model-fitting stages of a wrap: coarse pre-fit and non-rigid ICP fit.

A wrap whose model is fitted by non-rigid ICP (its registry entry,
:class:`~facewrap.wrapping.models.ModelSpec`, has no closed form) runs two
stages here, both in the template's :class:`~facewrap.geometry.frames.NormalisedFrame`:

1. :func:`coarse_fit` — the registry's ``coarse`` model (pose and scale, with blend
   weights for the hybrid) first, because local deformation resists global
   scaling;
2. :func:`icp_fit` — the model itself, stage group after stage group of its
   schedule (graph models go coarse to fine in node count).

:func:`icp_start` prepares what both share: the frame, the blendshape deltas
posed like the template, the landmark rows and targets.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from facewrap.geometry.frames import NormalisedFrame
from facewrap.geometry.similarity import Similarity
from facewrap.progress import progress
from facewrap.wrapping.icp.engine import NonRigidICP
from facewrap.wrapping.icp.terms import landmark_rows
from facewrap.wrapping.models import MODEL_REGISTRY, ModelParts, ModelSpec
from facewrap.wrapping.models.blendshape import blendshape_basis
from facewrap.wrapping.models.graph import GraphCache

__all__ = ["IcpStart", "ModelFit", "icp_start", "coarse_fit", "icp_fit", "stage_groups"]

#: the coarse pre-fit samples at most this fraction of the vertices in every stage
#: (the main fit refines afterwards)
COARSE_SAMPLE = 0.3


@dataclass(frozen=True, eq=False)
class IcpStart:
    """Where the ICP model fit starts (normalised frame).

    Attributes
    ----------
    frame : NormalisedFrame
        Of the similarity-aligned template.
    base : (n, 3) float64
        Template positions the model deforms.
    deltas : (3n, K) float64
        Blendshape deltas, rotated and scaled like ``base`` (K = 0 without).
    shape_names : list of str
        Names of the K blendshapes (or PCA components).
    weights : (K,) float64 or None
        Blend weights to start from (after a blendshape pre-fit).
    landmark_matrix : (l, n) scipy.sparse.csr_matrix
    landmark_targets : (l, 3) float64
    body : (b,) int64 or None
        The vertices the frame is measured on and a pose turns about (the skin's;
        None: every vertex of a face).
    """
    frame: NormalisedFrame
    base: np.ndarray
    deltas: np.ndarray
    shape_names: list
    weights: np.ndarray | None
    landmark_matrix: object
    landmark_targets: np.ndarray
    body: np.ndarray | None = None


@dataclass
class ModelFit:
    """Outcome of the model-fitting stages of a wrap.

    Attributes
    ----------
    vertices : (n, 3) float64
        Fitted positions, in the scan's units.
    history : list of dict
        One entry per ICP iteration (empty for closed-form models).
    weights : (K,) float64 or None
        Fitted blend weights.
    shape_names : list of str
    setup_seconds : float
        Spent building models and graphs and in the coarse pre-fit.
    rest : (n, 3) float64 or None
        The expression the blend weights make (aligned template plus weighted
        shapes), which the fit's triangles should face like; None for models
        without blendshapes (the aligned template is that pose).
    """
    vertices: np.ndarray
    history: list = field(default_factory=list)
    weights: np.ndarray | None = None
    shape_names: list = field(default_factory=list)
    setup_seconds: float = 0.0
    rest: np.ndarray | None = None


def icp_start(template, vertices, similarity: Similarity, landmarks, targets,
              spec: ModelSpec, blendshapes=None, pca_components=None, *,
              frame_triangles=None) -> IcpStart:
    """The normalised frame, posed blendshape deltas and landmark rows of a fit.

    Parameters
    ----------
    template : Mesh
    vertices : (n, 3) float64
        The similarity-aligned template (scan units).
    similarity : Similarity
        Template → scan, as applied to ``vertices``.
    landmarks : Landmarks
        Template landmarks on the mesh, paired with ``targets``.
    targets : (l, 3) float64
        Their scan positions.
    spec : ModelSpec
    blendshapes : dict name -> (n, 3) float64, optional
        Needed when ``spec.needs_blendshapes``.
    pca_components : int, optional
    frame_triangles : (t', 3) int, optional
        The triangles whose vertices the fit's normalised frame is measured on
        and a pose turns about (default every face's:
        :meth:`facewrap.mesh.Mesh.surface_points`;
        :attr:`facewrap.wrapping.problem.WrapProblem.skin_triangles`: the skin's).

    Returns
    -------
    IcpStart
    """
    V = np.asarray(vertices, dtype=np.float64)
    # the frame of the surface: a stray point no face uses would move its centre
    # and size (and every tolerance in it)
    body = None if frame_triangles is None else np.unique(np.asarray(frame_triangles))
    frame = NormalisedFrame.of(template.with_vertices(V).surface_points() if body is None
                               else V[body])
    deltas, names = np.zeros((3 * len(V), 0)), []
    if spec.needs_blendshapes:
        D, names = blendshape_basis(template.vertices, blendshapes, pca_components)
        # deltas live in the template's frame: rotate and scale them like the template
        D = D.reshape(len(V), 3, -1)
        deltas = (similarity.scale * np.matmul(similarity.rotation, D)
                  / frame.size).reshape(3 * len(V), -1)
    L = landmark_rows(landmarks, len(V), template.triangles)
    return IcpStart(frame, frame.to_frame(V), deltas, names, None, L,
                    frame.to_frame(targets), body)


def _engine(settings, frame: NormalisedFrame, stages) -> NonRigidICP:
    """The ICP engine configured by a wrap's settings."""
    max_distance = settings.max_distance / frame.size if settings.max_distance else 0.05
    return NonRigidICP(stages, point_weight=settings.point_weight, robust=settings.robust,
                       max_distance=max_distance,
                       max_normal_angle=settings.max_normal_angle,
                       reject_boundary=settings.reject_boundary)


def _run(settings, start: IcpStart, model, stages, template, tree, excluded, params):
    return _engine(settings, start.frame, stages).fit(
        model, template.triangles, tree, frame=start.frame, fit_mask=~excluded,
        landmark_matrix=start.landmark_matrix, landmark_targets=start.landmark_targets,
        params=params)


def coarse_fit(start: IcpStart, spec: ModelSpec, settings, template, tree, excluded, *,
               warm_weights=None, warm: bool = False) -> tuple[IcpStart, list]:
    """The registry's coarse pre-fit of ``spec`` (none: ``start`` unchanged).

    Parameters
    ----------
    start : IcpStart
    spec : ModelSpec
        The model to be fitted; its ``coarse`` entry names the pre-fit model.
    settings : WrapSettings
    template : Mesh
    tree : ClosestPointTree
        The scan.
    excluded : (n,) bool
        Vertices not pulled to the scan.
    warm_weights : (K,) float64, optional
        Blend weights of a previous frame: they start a blendshape pre-fit.
    warm : bool
        Warm-started (tracking): skip the landmark-only stages, the start is
        already close.

    Returns
    -------
    start : IcpStart
        Posed by the pre-fit: the fitted positions (rigid pre-fit), or the posed
        neutral and deltas plus the fitted weights (blendshape pre-fit).
    history : list of dict
    """
    if spec.coarse is None:
        return start, []
    coarse = MODEL_REGISTRY[spec.coarse]
    pre = coarse.build(ModelParts(start.base, template.triangles, start.deltas,
                                  scale=settings.scale, bounds=settings.blend_bounds(),
                                  body=start.body,
                                  # with blendshapes only: without them the stretch
                                  # takes the expression (ICT's scream, graph model:
                                  # 1.41 -> 1.77 mm mean)
                                  stretch=settings.stretch and coarse.needs_blendshapes))
    p_init = None
    if coarse.needs_blendshapes and warm_weights is not None \
            and len(warm_weights) == start.deltas.shape[1]:
        p_init = pre.initial_params(warm_weights)
    stages = [replace(st, sample=min(st.sample, COARSE_SAMPLE),
                      landmark_weight=st.landmark_weight * settings.landmark_scale)
              for st in coarse.schedule() if not (warm and st.data_weight == 0)]
    with progress(None, f"coarse {coarse.name} pre-fit"):  # a spinner on a terminal
        icp = _run(settings, start, pre, stages, template, tree, excluded, p_init)
    history = [dict(h, model="pre-" + coarse.name) for h in icp.history_]
    p0 = icp.params_
    if not coarse.needs_blendshapes:
        return replace(start, base=start.frame.to_frame(icp.vertices_)), history
    # the pose moves into the neutral and the deltas; the weights start the main fit
    base = pre.vertices(replace(p0, w=np.zeros_like(p0.w)))
    return replace(start, base=base, deltas=pre.posed_deltas(p0), weights=p0.w), history


def stage_groups(stages, by_graph: bool) -> list[tuple[float, list]]:
    """Consecutive stages that share a node spacing (graph models), as
    ``(factor, stages)``; one group for other models.

    Examples
    --------
    >>> from facewrap.wrapping.icp.schedule import Stage
    >>> [(f, len(g)) for f, g in stage_groups([Stage(node_spacing_factor=2.0),
    ...     Stage(node_spacing_factor=2.0), Stage()], by_graph=True)]
    [(2.0, 2), (1.0, 1)]
    """
    if not by_graph:
        return [(1.0, list(stages))]
    groups: list[tuple[float, list]] = []
    for st in stages:
        if groups and groups[-1][0] == st.node_spacing_factor:
            groups[-1][1].append(st)
        else:
            groups.append((st.node_spacing_factor, [st]))
    return groups


def icp_fit(start: IcpStart, spec: ModelSpec, settings, template, tree, excluded,
            graph_cache: GraphCache, setup_started: float, *,
            graph_triangles=None) -> ModelFit:
    """Fit the model of ``spec`` by non-rigid ICP, group after group of its schedule.

    Parameters
    ----------
    start : IcpStart
        After :func:`coarse_fit`.
    spec : ModelSpec
    settings : WrapSettings
        ``stages`` (None: the model's default schedule), ``node_spacing``...
    template : Mesh
    tree : ClosestPointTree
    excluded : (n,) bool
    graph_cache : GraphCache
    setup_started : float
        ``time.perf_counter()`` when the model set-up began (for ``setup_seconds``).
    graph_triangles : (t', 3) int, optional
        The triangles the deformation graph is built on (default the template's;
        :attr:`facewrap.wrapping.problem.WrapProblem.skin_triangles`: the skin's).

    Returns
    -------
    ModelFit
    """
    stages = [replace(st, landmark_weight=st.landmark_weight * settings.landmark_scale)
              for st in (settings.stages or spec.schedule())]
    groups = stage_groups(stages, spec.uses_graph)

    graph_T = template.triangles if graph_triangles is None else graph_triangles

    def graph_of(factor):
        return graph_cache.graph(template.vertices, graph_T, settings.node_spacing * factor)

    model = spec.build(ModelParts(start.base, template.triangles, start.deltas,
                                  graph_of(groups[0][0]) if spec.uses_graph else None,
                                  settings.scale, settings.blend_bounds(),
                                  body=start.body))
    setup = time.perf_counter() - setup_started
    params = None if start.weights is None else model.initial_params(start.weights)
    history, first = [], 0          # first: index of the group's first stage
    # on a terminal: a bar of stage groups (one graph each) over the engine's bar
    with progress(len(groups), f"fitting {spec.name}") as bar:
        for factor, group in groups:
            if spec.uses_graph and first > 0:
                # coarse-to-fine: the next graph continues the deformation so far
                model, params = model.on_graph(graph_of(factor), params
                                               if params is not None
                                               else model.initial_params())
            icp = _run(settings, start, model, group, template, tree, excluded, params)
            params = icp.params_
            nodes = getattr(getattr(model, "graph", None), "n_nodes", None)
            history += [dict(h, model=spec.name, stage=h["stage"] + first, nodes=nodes)
                        for h in icp.history_]
            first += len(group)
            bar.advance()
    weights = getattr(icp.params_, "w", None)
    rest = None
    if weights is not None and start.deltas.shape[1]:
        rest = start.frame.from_frame(start.base + (start.deltas @ weights).reshape(-1, 3))
    return ModelFit(icp.vertices_, history, weights, start.shape_names, setup, rest)
