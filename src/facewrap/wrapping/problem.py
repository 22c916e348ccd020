"""The checked inputs of a wrap: :class:`WrapProblem`, made by :func:`prepare_wrap`.

Landmarks paired (and template landmarks given as points snapped onto the
template), the model resolved from its registry entry, the plausibility checks
run, the scan checked and its tree built, and every template vertex given its
role (fitted, a part that follows, pinned).  The stages of
:mod:`facewrap.wrapping.stages` read everything they need from it.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.checks import as_shape_dict
from facewrap.landmarks import Landmarks, pair_landmarks, snap_to_surface
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import expect_instance
from facewrap.wrapping.likeness import check_likeness
from facewrap.wrapping.models import ModelSpec, model_spec
from facewrap.wrapping.models.graph import DEFAULT_GRAPH_CACHE, GraphCache
from facewrap.wrapping.plausibility import (LACY_LIMIT, border_fraction, check_landmarks,
                                           check_scale, check_unscaled_size, checked_scan)
from facewrap.wrapping.roles import (FITTED, PART, cached_hidden_surface, landmarks_on_parts,
                                    vertex_roles)
from facewrap.wrapping.settings import WrapSettings

__all__ = ["WrapProblem", "prepare_wrap", "alignment_weights", "SNAP_TOLERANCE",
           "check_wrap_arguments"]


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
    landmark_ids : (l,) int64
        Which of the template landmarks given to :func:`prepare_wrap` those are.
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
    landmark_ids: np.ndarray
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

    @cached_property
    def skin_mesh(self) -> Mesh:
        """The template's vertices with only the skin's polygons (none with a vertex
        of a part; all of them when the template is all parts): what the fit's
        frame, its deformation graph, the projection and the fold repairs are made
        of.  The parts (eyeballs, teeth, tongue) follow the skin at the end
        (:mod:`facewrap.wrapping.follow`) and their positions during the fit are
        never used, so the skin's fit must not depend on them: they moved the
        frame's centre and size (and every tolerance in it); as graph nodes tied to
        the nearest skin nodes a row of teeth or a tongue held the lips' and jaw's
        nodes together like a strut (ICT's full head opening its jaw by the graph
        model, ``benchmarks/bench_head_expressions.py``); and their triangles, turned
        in the fit, spent the budgets the skin's fold repairs need.  Part vertices
        are skinned to the nearest skin nodes instead.  Quads stay quads: the
        repairs walk the polygons' rings."""
        t = self.template
        part = self.roles == PART
        starts = np.r_[0, np.cumsum(t.face_sizes)[:-1]]
        keep = ~np.logical_or.reduceat(part[t.face_indices], starts)
        if keep.all() or not keep.any():
            return t
        offsets = np.r_[0, np.cumsum(t.face_sizes[keep])].astype(np.int64)
        return Mesh(t.vertices, (offsets, t.face_indices[np.repeat(keep, t.face_sizes)]))

    @property
    def skin_triangles(self) -> np.ndarray:
        """(t', 3) int64: the triangles of :attr:`skin_mesh`."""
        return self.skin_mesh.triangles


def _nothing_pulled(fit_mask, exclude, pinned, model: str) -> str:
    """Why no template vertex is left for the scan to pull, naming the argument
    (the ICP would only find no scan point, naming ``max_distance``)."""
    if fit_mask is not None:
        why = ("fit_mask (--fit-mask), with exclude (--exclude) and pinned (--pin), "
               "leaves no template vertex")
    elif exclude is not None or pinned is not None:
        why = "exclude (--exclude) and pinned (--pin) leave no template vertex"
    else:
        why = ("every template vertex is a part or a cavity (settings.fit_hidden pulls "
               "them)")
    return (f"{why} to pull onto the scan: the {model!r} model needs some (the 'rbf' "
            "model warps by the landmarks alone)")


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
    if s.stages is not None:   # the result's settings must not be the caller's stages
        s.stages = [replace(stage) for stage in s.stages]
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
              if not s.fit_hidden else None)
    roles = vertex_roles(template.n_vertices, hidden, exclude=exclude, fit_mask=fit_mask,
                         pinned=pinned)
    excluded = roles != FITTED
    if excluded.all() and spec.fitted_by_icp:
        raise ValueError(_nothing_pulled(fit_mask, exclude, pinned, s.model))
    notes = landmarks_on_parts(template_landmarks, roles, template.triangles)
    template_points = template_landmarks.positions(template)
    scan_points = scan_landmarks.positions(scan)
    weights = alignment_weights(template_landmarks, ia)
    checked, similarity = check_landmarks(template_landmarks, template_points,
                                          scan_landmarks, scan_points, (ia, ib), weights,
                                          scale=s.scale, allow_mirrored=s.allow_mirrored)
    notes += checked
    aligned = None
    if similarity is not None:
        notes += check_scale(similarity.scale)
        aligned = similarity.apply(template.vertices)
    if not s.scale:
        notes += check_unscaled_size(template_points[ia], scan_points[ib], weights)
    scan, tree, scan_notes = checked_scan(scan, scan_tree, aligned, template.triangles,
                                          mask=~excluded)
    if aligned is not None:   # a scan of another object passes every check above
        scan_notes += check_likeness(aligned, ~excluded, similarity.apply(
            template_points[ia]), scan_points[ib], tree)
    bordered = border_fraction(tree)
    if s.reject_boundary and bordered > LACY_LIMIT:
        s.reject_boundary = False
        scan_notes.append(f"scan: {100 * bordered:.0f} % of its triangles "
                          "touch a border (full of holes, or a triangle soup?): the ICP "
                          "keeps scan points near borders (reject_boundary off), the "
                          "projection still leaves them")
    return WrapProblem(template, scan, tree, template_landmarks.subset(ia), ia,
                       template_points[ia], scan_points[ib], weights, roles, excluded,
                       blendshapes, s, spec,
                       DEFAULT_GRAPH_CACHE if graph_cache is None else graph_cache,
                       tuple(notes + scan_notes))


def check_wrap_arguments(template, scan, template_landmarks, scan_landmarks, settings,
                         *, blendshapes=None, scan_tree=None, graph_cache=None
                         ) -> dict | None:
    """Check the arguments of :func:`~facewrap.wrapping.wrap` at the door: their
    types, finite meshes, landmark ids inside their meshes, a tree built on this
    scan, and blendshapes of the template's size.

    Parameters are those of :func:`~facewrap.wrapping.wrap`.

    Returns
    -------
    dict of str to (n, 3) float64, or None
        ``blendshapes`` checked, as read-only copies in a dict of their own.

    Raises
    ------
    TypeError
        An argument of the wrong kind (a dict for the settings, an array for a mesh).
    ValueError
        Starting with what it is about (``"scan: ..."``, ``"template landmarks:
        ..."``), as the wrap's other refusals do.
    """
    check_mesh(template, "template")
    check_mesh(scan, "scan")
    expect_instance(settings, WrapSettings, "settings", optional=True)
    expect_instance(graph_cache, GraphCache, "graph_cache", optional=True)
    for what, mesh, landmarks in (("template", template, template_landmarks),
                                  ("scan", scan, scan_landmarks)):
        expect_instance(landmarks, Landmarks, f"{what}_landmarks")
        try:
            landmarks.check(mesh.n_vertices, len(mesh.triangles))
        except ValueError as exc:
            raise ValueError(f"{what} landmarks: {exc}") from None
    if expect_instance(scan_tree, ClosestPointTree, "scan_tree", optional=True) is not None:
        if not (np.array_equal(scan_tree.triangles, scan.triangles)
                and np.array_equal(scan_tree.vertices, scan.vertices)):
            raise ValueError(f"scan_tree was built on another mesh ({len(scan_tree.vertices)} "
                             f"vertices, {len(scan_tree.triangles)} triangles) than the scan "
                             f"({scan.n_vertices}, {len(scan.triangles)})")
    if blendshapes is None:
        return None
    return as_shape_dict(blendshapes, template.n_vertices)


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
        raise ValueError(f"template landmarks: landmark {landmarks.label(i)} lies "
                         f"{moved[i]:.4g} template units from the template's surface "
                         f"(more than {limit:.4g}, {100 * SNAP_TOLERANCE:g} % of its size): "
                         "landmarks for another mesh or in other units?")
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
