"""The fitting options shared by ``facewrap wrap``, ``facewrap track`` and ``facewrap rig``.

Choices and defaults come from :class:`~facewrap.wrapping.WrapSettings` (its
field defaults and its constraint table, :func:`facewrap.params.choices_of`), so
the options, job files and the library never disagree.
"""

from __future__ import annotations

import dataclasses

from facewrap.jobs.wrap_job import OUTPUT_FRAMES, WrapJob
from facewrap.errors import InputError
from facewrap.params import SettingsError, choices_of
from facewrap.wrapping import WrapSettings

__all__ = ["add_fit_options", "add_wrap_file_options", "wrap_settings_from_args",
           "option_name"]

_DEFAULTS = {f.name: f.default for f in dataclasses.fields(WrapSettings)}


def _allowed(field: str) -> str:
    """The allowed values of a WrapSettings field in words, from its constraint table."""
    rule = WrapSettings.constraints[field]
    return " or ".join(r.describe() for r in (rule if isinstance(rule, tuple) else (rule,)))


def _choice_option(p, option: str, field: str, help: str, type=str) -> None:
    p.add_argument(option, default=_DEFAULTS[field], type=type,
                   choices=list(choices_of(WrapSettings, field)), help=help)


def add_wrap_file_options(p) -> None:
    """Add the input files of one wrap besides template and scan (landmarks, profile,
    vertex sets, texture: the :class:`~facewrap.jobs.WrapJob` fields) to ``p``."""
    p.add_argument("--template-landmarks",
                   help="template vertex ids (text) or facewrap landmark JSON (default: "
                        "the template profile's)")
    p.add_argument("--scan-landmarks",
                   help="scan points: 'x y z' text, menpo .ljson or facewrap JSON "
                        "(default: the 68 iBUG points detected on the scan, and on the "
                        "template when it has no landmarks; needs facewrap[landmarks])")
    p.add_argument("--template-profile", metavar="FILE",
                   help="the template's landmarks and fitting vertices: ICT-FaceKit's "
                        "vertex_indices.json or a facewrap profile (default: one found "
                        "beside the template; 'none' for none)")
    p.add_argument("--fit-mask", metavar="FILE",
                   help="template vertex ids to pull onto the scan, and only those")
    p.add_argument("--pin", metavar="FILE",
                   help="template vertex ids kept exactly where the landmark alignment "
                        "puts them")
    p.add_argument("--texture", help="scan texture image to bake into the template UVs")
    p.add_argument("--texture-size", type=int, default=WrapJob.texture_size)


def add_fit_options(p, *, blendshapes_required: bool = False,
                    output_frame: bool = True) -> None:
    """Add the fitting options (see :class:`~facewrap.wrapping.WrapSettings`) to ``p``.

    ``blendshapes_required``: ``--blendshapes`` must be given (a rig's shapes);
    ``output_frame``: offer ``--output-frame`` (not where outputs stay on the scan).
    """
    p.add_argument("--blendshapes", metavar="DIR", required=blendshapes_required,
                   help="folder of meshes in the template's topology (shape = file - "
                        "template)")
    _choice_option(p, "--model", "model", "deformation model (default: hybrid with "
                   "--blendshapes, else graph)")
    p.add_argument("--exclude", help="template vertex ids not to fit (they follow)")
    p.add_argument("--node-spacing", type=float, default=_DEFAULTS["node_spacing"],
                   help="graph node spacing, fraction of template size (default "
                        "%(default)s)")
    _choice_option(p, "--robust", "robust", "robust norm of the data term (default "
                   "%(default)s)")
    p.add_argument("--pca-components", type=int, default=_DEFAULTS["pca_components"],
                   help="fit this many PCA components of the blendshapes")
    # a switch that undoes an option given beside it: refused, not one silently winning
    weights = p.add_mutually_exclusive_group()
    weights.add_argument("--weight-range", type=float, nargs=2, metavar=("LO", "HI"),
                   default=_DEFAULTS["weight_range"],
                   help="range of the blend weights (default 0 1, an expression "
                        "rig's); see --no-weight-range")
    weights.add_argument("--no-weight-range", action="store_true",
                   help="let blend weights take any value (identity or corrective "
                        "shapes used with negative or > 1 weights)")
    pull = p.add_mutually_exclusive_group()
    pull.add_argument("--landmark-tolerance", type=float,
                   default=_DEFAULTS["landmark_tolerance"], metavar="F",
                   help="landmarks left farther than this from their targets after "
                        "the fit (fraction of template size) are pulled to it; 0 keeps "
                        "them exactly (default %(default)s)")
    pull.add_argument("--no-landmark-pull", action="store_true",
                   help="leave the landmarks where the fit puts them")
    _choice_option(p, "--kernel", "kernel", "RBF kernel of the landmark warp")
    _choice_option(p, "--blend-order", "blend_order", "blending of the displacement of "
                   "vertices that are not projected: 1 harmonic, 2 biharmonic across "
                   "the gaps, harmonic where that would fold a triangle "
                   "(default %(default)s)", type=int)
    p.add_argument("--smoothing", type=float, default=_DEFAULTS["smoothing"],
                   help="RBF smoothing for noisy landmarks (default 0)")
    p.add_argument("--max-distance", type=float, default=_DEFAULTS["max_distance"],
                   help="longest projection move, in scan units (default 5%% of the "
                        "template's size)")
    p.add_argument("--no-project", action="store_true", help="skip the projection")
    p.add_argument("--rigid-refine", action="store_true",
                   help="refine the alignment with rigid ICP")
    p.add_argument("--no-scale", action="store_true",
                   help="align with a rotation and translation only (the template is "
                        "already at the scan's size and units)")
    p.add_argument("--max-normal-angle", type=float, metavar="DEG",
                   default=_DEFAULTS["max_normal_angle"],
                   help="scan points whose normal differs from the template's by more "
                        f"than this many degrees are not matched ({_allowed('max_normal_angle')}; "
                        "default %(default)s)")
    p.add_argument("--point-weight", type=float, metavar="W",
                   default=_DEFAULTS["point_weight"],
                   help="weight of point-to-point against point-to-plane (weight 1) "
                        f"distances in the fit ({_allowed('point_weight')}; default "
                        "%(default)s)")
    if output_frame:
        p.add_argument("--output-frame", choices=OUTPUT_FRAMES,
                       default=WrapJob.output_frame,
                       help="write the result where the scan is ('scan') or mapped back "
                            "through the inverse of the landmark similarity so it "
                            "overlays the template ('template'; default %(default)s)")
    p.add_argument("--allow-mirrored", action="store_true",
                   help="fit landmarks that match a mirror image of the template's "
                        "(refused by default: usually a mirrored scan or landmark file)")
    p.add_argument("--fit-hidden", action="store_true",
                   help="also pull the template's parts (eyeballs, teeth, tongue, lashes) "
                        "and cavities (nostrils, mouth and eye sockets) onto the scan; by "
                        "default only what a scanner can see is pulled, the rest follows")


def wrap_settings_from_args(args) -> WrapSettings:
    """The :class:`~facewrap.wrapping.WrapSettings` of the fitting options.

    Raises
    ------
    InputError
        When WrapSettings refuses a value (e.g. a negative ``--node-spacing``),
        naming the option.
    """
    try:
        return _settings(args)
    except SettingsError as exc:
        raise InputError(exc.problem, option_name(exc.field)) from None


def option_name(field: str) -> str:
    """The command-line option that sets a :class:`WrapSettings` field.

    >>> option_name("node_spacing"), option_name("scale")
    ('--node-spacing', '--no-scale')
    """
    return _NEGATED.get(field, "--" + field.replace("_", "-"))


# fields set by a --no-... switch (the others are --field-name)
_NEGATED = {"scale": "--no-scale", "project": "--no-project",
            "landmark_pull": "--no-landmark-pull"}


def _settings(args) -> WrapSettings:
    return WrapSettings(model=args.model, kernel=args.kernel, smoothing=args.smoothing,
                        scale=not args.no_scale, max_normal_angle=args.max_normal_angle,
                        point_weight=args.point_weight,
                        project=not args.no_project, max_distance=args.max_distance,
                        rigid_refine=args.rigid_refine, node_spacing=args.node_spacing,
                        robust=args.robust, pca_components=args.pca_components,
                        weight_range=(None if args.no_weight_range
                                      else tuple(args.weight_range)),
                        blend_order=args.blend_order,
                        landmark_pull=not args.no_landmark_pull,
                        landmark_tolerance=args.landmark_tolerance,
                        allow_mirrored=args.allow_mirrored,
                        fit_hidden=args.fit_hidden)
