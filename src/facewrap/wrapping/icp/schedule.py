"""The non-rigid ICP schedule: named, typed stages that go from stiff to loose.

A :class:`Stage` holds the weights and iteration budget of one stage of
:class:`~facewrap.wrapping.icp.engine.NonRigidICP`; one function per deformation
model gives its schedule (the model registry,
:data:`facewrap.wrapping.models.MODEL_REGISTRY`, names it, and
:func:`facewrap.wrapping.models.default_schedule` looks it up).  Every field is also a key of a job file's
``[[wrap.stages]]`` tables, checked at construction against ``Stage.constraints``.
"""

from __future__ import annotations

from dataclasses import dataclass

from facewrap.params import Interval, validate

__all__ = ["Stage", "rigid_schedule", "blendshape_schedule", "affine_schedule",
           "hybrid_schedule", "graph_schedule"]


@dataclass
class Stage:
    """One stage of the non-rigid ICP schedule (stiff to loose).

    Attributes
    ----------
    iterations : int
        Maximum ICP iterations (closest scan points + one damped Gauss–Newton step).
    smooth_weight : float
        Weight of the model's smoothness regulariser (graph eq. 7, affine
        stiffness; per edge, relative to the mean data residual).  Called
        ``stiffness`` in the NICP literature; named like every other weight here.
    landmark_weight : float
        Weight of the landmark term (mean over landmarks) relative to the data
        term (mean over scan points).
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
        Fraction of the fitted vertices that get a scan point in this stage
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
        (``WrapSettings.weight_range``).  The default keeps weights in their
        range without forcing them to its edges; a tenfold larger one cost
        accuracy on strong expressions (docs/benchmarks.md).
    stretch_weight : float
        Weight of the Tikhonov term on a stretching pose's log-stretch (the
        hybrid's blendshape pre-fit, :mod:`~facewrap.wrapping.models.blendshape`).
        Smaller ones fit the built-in sample's most anisotropic identities better
        (seed 3, 8 % wider and 7 % shorter: 2.04 mm mean without a stretch, 1.51 at
        this weight, 0.65 at 3e-4) but take part of a smile for a wider face on
        ICT's identities (identity005 smiling, p95 0.89 -> 1.11 mm at 3e-3); at
        this weight ICT's cases stay within 0.03 mm.
    """
    iterations: int = 10
    smooth_weight: float = 1.0
    landmark_weight: float = 1.0
    blend_weight: float = 1e-6
    data_weight: float = 1.0
    robust_scale: float = 0.0
    sample: float = 1.0
    node_spacing_factor: float = 1.0
    bound_weight: float = 1e-4
    stretch_weight: float = 1e-2

    #: allowed values of every field, checked at construction (:mod:`facewrap.params`)
    constraints = {
        "iterations": Interval(int, 1, None),
        "smooth_weight": Interval(float, 0, None),
        "landmark_weight": Interval(float, 0, None),
        "blend_weight": Interval(float, 0, None),
        "data_weight": Interval(float, 0, None),
        "robust_scale": Interval(float, 0, None),
        "sample": Interval(float, 0, 1, closed="right"),
        "node_spacing_factor": Interval(float, 0, None, closed="neither"),
        "bound_weight": Interval(float, 0, None),
        "stretch_weight": Interval(float, 0, None),
    }

    def __post_init__(self):
        validate(self)


def rigid_schedule() -> list[Stage]:
    """Pose (and scale) only: no regulariser to relax, landmarks kept light."""
    return [Stage(iterations=10, smooth_weight=0.0, landmark_weight=0.1, sample=0.3),
            Stage(iterations=5, smooth_weight=0.0, landmark_weight=0.1)]


def blendshape_schedule() -> list[Stage]:
    """A landmark-only stage pulls the weights into the scan's expression, then the
    data term refines them."""
    return [Stage(iterations=4, landmark_weight=1.0, blend_weight=1e-7, data_weight=0.0),
            Stage(iterations=6, landmark_weight=0.3, blend_weight=1e-8, sample=0.3),
            Stage(iterations=6, landmark_weight=0.1, blend_weight=1e-8)]


def affine_schedule() -> list[Stage]:
    """Per-vertex affine transforms, relaxed tenfold over five stages."""
    return [Stage(iterations=3, smooth_weight=10.0, landmark_weight=1.0),
            Stage(iterations=3, smooth_weight=3.0, landmark_weight=0.5),
            Stage(iterations=3, smooth_weight=1.0, landmark_weight=0.2),
            Stage(iterations=3, smooth_weight=0.3, landmark_weight=0.1),
            Stage(iterations=3, smooth_weight=0.1, landmark_weight=0.1)]


def hybrid_schedule() -> list[Stage]:
    """Blendshapes plus graph: the graph starts stiff so that the blendshapes, not
    the graph, take the expression, and relaxes once the weights have settled.

    No landmark-only stage: the blendshape pre-fit of :func:`~facewrap.wrapping.wrap`
    did that job.  The robust floors are the graph model's: smaller ones wrote
    off the nose wings and temples of a real scan of another identity as outliers.
    Only the first stage runs on the coarse graph: a second one there cost
    accuracy (docs/benchmarks.md).  That stage fits 15 % of the vertices (some
    twenty per node of the coarse graph): as accurate as 30 %, for half its
    closest points and Gram rows; sparser samples in the later stages cost
    accuracy (docs/benchmarks.md).
    """
    return [Stage(iterations=5, smooth_weight=10.0, landmark_weight=0.5, blend_weight=1e-8,
                  robust_scale=0.06, sample=0.15, node_spacing_factor=2.0),
            Stage(iterations=5, smooth_weight=1.0, landmark_weight=0.2, blend_weight=1e-8,
                  robust_scale=0.03, sample=0.3),
            Stage(iterations=5, smooth_weight=0.1, landmark_weight=0.1, blend_weight=1e-8,
                  robust_scale=0.015, sample=0.3),
            Stage(iterations=5, smooth_weight=0.03, landmark_weight=0.1, blend_weight=1e-8,
                  sample=0.5)]


def graph_schedule() -> list[Stage]:
    """The deformation graph alone, coarse graph first.

    Without blendshapes a wide-open jaw leaves the chin and neck far from the
    scan after the landmark stage; larger robust floors keep pulling them in.
    """
    return [Stage(iterations=4, smooth_weight=1.0, landmark_weight=1.0, data_weight=0.0,
                  node_spacing_factor=2.0),
            Stage(iterations=5, smooth_weight=1.0, landmark_weight=0.5, robust_scale=0.06,
                  sample=0.3, node_spacing_factor=2.0),
            Stage(iterations=5, smooth_weight=0.3, landmark_weight=0.2, robust_scale=0.03,
                  sample=0.3, node_spacing_factor=2.0),
            Stage(iterations=5, smooth_weight=0.1, landmark_weight=0.1, robust_scale=0.015,
                  sample=0.3),
            Stage(iterations=5, smooth_weight=0.03, landmark_weight=0.1, sample=0.5)]
