"""Deformation models: how a template may move, and the registry of them.

Each model is one module and one entry of :data:`MODEL_REGISTRY`, a
:class:`ModelSpec` that says what the model needs (blendshapes, a deformation
graph), how to build it, whether non-rigid ICP fits it (and after which coarse
pre-fit) and its default schedule.  :func:`facewrap.wrapping.wrap` reads only the
registry, never a model's name.

* :mod:`.blendshape` — :class:`RigidModel` (pose and scale) and
  :class:`BlendshapeModel` (pose plus blend weights);
* :mod:`.affine` — one affine transform per vertex (Amberg et al.);
* :mod:`.graph` — the embedded deformation graph, and :class:`GraphCache`;
* :mod:`.hybrid` — a deformation graph on top of blendshapes;
* :mod:`.base` — the interface every ICP model implements, rotation helpers;
* "rbf" is the landmark RBF warp of :mod:`facewrap.wrapping.warp` (closed form).

The ICP models are built on template positions in the normalised frame
(:class:`~facewrap.geometry.frames.NormalisedFrame`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from facewrap.wrapping.icp.schedule import (Stage, affine_schedule, blendshape_schedule,
                                            graph_schedule, hybrid_schedule,
                                            rigid_schedule)
from facewrap.wrapping.models.affine import AffineModel
from facewrap.wrapping.models.base import DeformationModel
from facewrap.wrapping.models.blendshape import BlendshapeModel, RigidModel
from facewrap.wrapping.models.graph import DeformationGraph, GraphCache, GraphModel
from facewrap.wrapping.models.hybrid import HybridModel
from facewrap.wrapping.warp import RBFWarp, rbf_kernel

__all__ = ["ModelParts", "ModelSpec", "MODEL_REGISTRY", "AUTO_MODEL", "model_spec",
           "default_schedule", "GraphCache", "RBFWarp", "rbf_kernel"]


@dataclass(frozen=True, eq=False)
class ModelParts:
    """What an ICP model is built from (all in the normalised frame).

    Attributes
    ----------
    base : (n, 3) float64
        Template positions the model deforms.
    triangles : (t, 3) int64
        Template triangles.
    deltas : (3n, K) float64
        Blendshape deltas in ``base``'s frame (K = 0 without blendshapes).
    graph : DeformationGraph or None
        For models with ``uses_graph``.
    scale : bool
        Whether a pose may scale.
    bounds : (lo, hi) or None
        Range of the blend weights.
    stretch : bool
        Whether a pose may stretch along the face's principal axes (the coarse
        pre-fits; see :mod:`.blendshape`).
    body : (b,) int64 or None
        The vertices a pose turns about and stretches along (the skin's: the parts
        must not move the pivot; None: all).
    """
    base: np.ndarray
    triangles: np.ndarray
    deltas: np.ndarray
    graph: DeformationGraph | None = None
    scale: bool = True
    bounds: tuple | None = None
    stretch: bool = False
    body: np.ndarray | None = None


@dataclass(frozen=True)
class ModelSpec:
    """One registered deformation model.

    Attributes
    ----------
    name : str
        The ``WrapSettings.model`` value.
    build : callable (ModelParts) -> DeformationModel, optional
        Builds the model that non-rigid ICP fits; None for a closed-form model.
    schedule : callable () -> list of Stage, optional
        The default ICP schedule.
    closed_form : callable (vertices, landmarks, targets, settings) -> vertices, optional
        A model fitted without ICP: new (n, 3) positions from the aligned
        template, its (l, 3) landmark positions and their targets.
    needs_blendshapes : bool
        Refuse to run without blendshapes.
    uses_graph : bool
        Built on a deformation graph (stages are grouped by node spacing).
    coarse : str or None
        The registered model fitted first (pose and scale, with blend weights for
        the hybrid) before local deformation, which resists global scaling.
    """
    name: str
    build: Callable[[ModelParts], DeformationModel] | None = None
    schedule: Callable[[], list[Stage]] | None = None
    closed_form: Callable | None = None
    needs_blendshapes: bool = False
    uses_graph: bool = False
    coarse: str | None = None

    @property
    def fitted_by_icp(self) -> bool:
        """Whether a wrap fits this model by non-rigid ICP (else in closed form;
        a closed-form model may still be built as another's coarse pre-fit)."""
        return self.closed_form is None


def _unchanged(vertices, landmarks, targets, settings) -> np.ndarray:
    """The "rigid" wrap: the similarity alone."""
    return vertices


def _rbf_warp(vertices, landmarks, targets, settings) -> np.ndarray:
    """The "rbf" wrap: landmark displacements interpolated over the template."""
    warp = RBFWarp(kernel=settings.kernel, smoothing=settings.smoothing)
    try:
        warp.fit(landmarks, targets - landmarks)
    except ValueError as exc:   # say what it is about, so a job can name the file
        raise ValueError(f"template landmarks: {exc} (a vertex id listed twice?): the "
                         "rbf model needs a place of its own for each") from None
    return warp.transform(vertices)


#: every model a wrap can use, by ``WrapSettings.model`` value (in the order the
#: CLI lists them)
MODEL_REGISTRY: dict[str, ModelSpec] = {spec.name: spec for spec in [
    ModelSpec("rigid", build=lambda m: RigidModel(m.base, scale=m.scale, stretch=m.stretch,
                                               body=m.body),
              schedule=rigid_schedule, closed_form=_unchanged),
    ModelSpec("rbf", closed_form=_rbf_warp),
    ModelSpec("affine", build=lambda m: AffineModel(m.base, m.triangles),
              schedule=affine_schedule, coarse="rigid"),
    ModelSpec("graph", build=lambda m: GraphModel(m.base, m.graph),
              schedule=graph_schedule, uses_graph=True, coarse="rigid"),
    ModelSpec("blendshape",
              build=lambda m: BlendshapeModel(m.base, m.deltas, scale=m.scale,
                                              bounds=m.bounds, stretch=m.stretch,
                                              body=m.body),
              schedule=blendshape_schedule, needs_blendshapes=True),
    ModelSpec("hybrid",
              build=lambda m: HybridModel(m.base, m.deltas, m.graph, bounds=m.bounds),
              schedule=hybrid_schedule, needs_blendshapes=True, uses_graph=True,
              coarse="blendshape"),
]}


#: what ``WrapSettings.model = "auto"`` becomes, with and without blendshapes
AUTO_MODEL = {True: "hybrid", False: "graph"}


def model_spec(name: str, *, has_blendshapes: bool = False) -> ModelSpec:
    """The registry entry of ``name`` ("auto": :data:`AUTO_MODEL`).

    Raises
    ------
    ValueError
        Naming the choices, for an unknown model.

    Examples
    --------
    >>> model_spec("auto", has_blendshapes=True).name
    'hybrid'
    """
    if name == "auto":
        name = AUTO_MODEL[bool(has_blendshapes)]
    if name not in MODEL_REGISTRY:
        raise ValueError(f"model must be one of {tuple(MODEL_REGISTRY)}, got {name!r}")
    return MODEL_REGISTRY[name]


def default_schedule(model: str) -> list[Stage]:
    """The schedule a model uses unless told otherwise (a fresh list each call).

    Stiff to loose: a landmark-only stage pulls the template into the scan's
    expression, then the data term comes in and the regulariser relaxes while
    the landmarks' weight drops (they are less accurate than the scan surface).
    Stiff stages fit a third of the vertices (``sample``; the hybrid's first, on
    its coarse graph, 15 %), the last stage of the graph models half: their few
    hundred nodes are still overdetermined many times and the final projection
    puts every vertex on the scan.  Graph models
    also go coarse to fine in node count: the stiffest stages run on a graph with
    twice the node spacing (a quarter of the nodes), whose motion the fine graph
    continues, for the same error in less time (docs/benchmarks.md).

    Parameters
    ----------
    model : str
        A registered model fitted by ICP, or "rigid" (the coarse pre-fit).

    Returns
    -------
    list of Stage

    Examples
    --------
    >>> [st.smooth_weight for st in default_schedule("affine")]
    [10.0, 3.0, 1.0, 0.3, 0.1]
    """
    spec = MODEL_REGISTRY.get(model)
    if spec is None or spec.schedule is None:
        raise ValueError(f"no default schedule for model {model!r}; one of "
                         f"{[n for n, s in MODEL_REGISTRY.items() if s.schedule]}")
    return spec.schedule()
