"""Settings of a wrap: one dataclass, its table of allowed values, the model names.

:class:`WrapSettings` holds every choice of :func:`facewrap.wrapping.wrap`; its
``constraints`` table is the one place the allowed values live (the CLI and job
files read their choices from it, :func:`facewrap.params.validate` checks it at
construction).  :data:`MODELS` lists the models a wrap can use: "auto" plus every
entry of :data:`facewrap.wrapping.models.MODEL_REGISTRY`.
"""

from __future__ import annotations

from dataclasses import dataclass

from facewrap.params import (Empty, Flag, Instances, Interval, NoneAllowed, Options, Pair,
                             validate)
from facewrap.wrapping.icp.schedule import Stage
from facewrap.wrapping.icp.terms import ROBUST_NORMS
from facewrap.wrapping.models import MODEL_REGISTRY
from facewrap.wrapping.warp import KERNELS

__all__ = ["WrapSettings", "MODELS"]

#: the ``model`` values of :class:`WrapSettings`: "auto" and every registered model
MODELS = ("auto", *MODEL_REGISTRY)


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
    stretch : bool
        Let the hybrid's blendshape pre-fit stretch the template along its
        principal axes too, as heads differ in proportions
        (:mod:`~facewrap.wrapping.models.blendshape`); only with ``scale``.
    rigid_refine : bool
        Refine the similarity with trimmed point-to-plane ICP (good when landmarks
        are few or noisy; off by default because expressions bias it).
    kernel, smoothing : see :class:`~facewrap.wrapping.warp.RBFWarp`.
    project : bool
        Move vertices onto the scan at the end (SPEC §1.3).
    max_distance : float, optional
        Longest projection move and longest accepted ICP scan-point distance; default 5 %
        of the template size.
    max_normal_angle : float
        Degrees; larger differences between template and scan normals are rejected.
    blend_order : {1, 2}
        How the projection blends the vertices it did not land: 1 harmonic; 2
        (default) biharmonic across the gaps among the vertices that may be
        projected, stepped back to harmonic wherever it would turn a triangle the
        harmonic blend leaves upright, or crease two neighbours it leaves facing
        the same way (:func:`~facewrap.wrapping.projection.project_to_surface`).  A
        harmonic blend sags between landing points: on ICT's face region onto
        james the fill takes the fit's p95 from 1.47 to 0.94 mm with fewer folds
        (docs/benchmarks.md, real scans).  Parts and cavities follow harmonically
        either way, and unfolding smooths harmonically.
    stages : list of Stage, optional
        The non-rigid ICP schedule (stiff to loose); None = the model's default
        (see :func:`facewrap.wrapping.icp.schedule.default_schedule`).
    node_spacing : float, optional
        Deformation-graph node spacing as a fraction of the template's bounding
        box diagonal (default 0.05: a few hundred nodes on a face).
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
        Ignore scan points on the scan's border (holes, crop).
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
        another identity that leaves them visibly off, and the pull brings them
        (and the fit around them) closer without moving the ground-truth cases
        (``bench_realscan``, ``bench_nicp``; docs/benchmarks.md).
    landmark_tolerance : float
        How far a landmark may stay from its target, as a fraction of the
        template's size (default 0.002, a fraction of a millimetre on a head);
        0 keeps landmarks exactly, which costs accuracy on the ground-truth
        cases (landmarks are noisy): pin only landmarks you trust.
    allow_mirrored : bool
        Fit landmarks that only a mirror image of the template matches (a mirrored
        scan or landmark file) with a warning instead of refusing them
        (:func:`~facewrap.wrapping.plausibility.check_reflection`).
    fit_hidden : bool
        Off (the default), only what a scanner can see is pulled onto the scan: the
        template's pieces that are not skin (eyeballs, teeth, tongue, lashes) and
        its cavities (nostrils, mouth and eye sockets) follow the skin instead
        (:func:`~facewrap.wrapping.roles.find_hidden_surface`).  On: every vertex
        not excluded is pulled.  A ``fit_mask`` given to :func:`wrap` decides what is
        pulled; outside it, parts and cavities follow as such (unless this is on).
    unfold : bool
        Unfold triangles the fit turned over (facing away from the aligned
        template) by smoothing them and a ring around them
        (:func:`~facewrap.wrapping.unfold.relax_flips`); pinned vertices stay.
    """
    model: str = "auto"
    scale: bool = True
    stretch: bool = True
    rigid_refine: bool = False
    kernel: str = "biharmonic"
    smoothing: float = 0.0
    project: bool = True
    max_distance: float | None = None
    max_normal_angle: float = 60.0
    blend_order: int = 2
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
    allow_mirrored: bool = False
    fit_hidden: bool = False
    unfold: bool = True

    #: allowed values of every field, checked at construction (:mod:`facewrap.params`);
    #: the CLI and job files take their choices from here
    constraints = {
        "model": Options(*MODELS),
        "scale": Flag(),
        "stretch": Flag(),
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
        "allow_mirrored": Flag(),
        "fit_hidden": Flag(),
        "unfold": Flag(),
    }

    def __post_init__(self):
        validate(self)
        if self.weight_range is not None:
            r = tuple(float(x) for x in self.weight_range)
            self.weight_range = r or None

    def blend_bounds(self):
        """The weight range the blend models use (None: unbounded)."""
        return None if self.pca_components else self.weight_range
