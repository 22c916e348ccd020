"""The last stages of a wrap: :func:`project` onto the scan and :func:`finish_fit`.

After the model's fit, the template is projected onto the scan along its normals
(:mod:`facewrap.wrapping.projection`); then triangles the fit turned over are
unfolded in two passes and landed again (:mod:`facewrap.wrapping.unfold`),
pinned vertices are put back (:func:`pin`) and the template's parts follow the
skin (:mod:`facewrap.wrapping.follow`).
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry import turned_triangles
from facewrap.geometry.similarity import Similarity
from facewrap.wrapping.blend import smooth_extension
from facewrap.wrapping.follow import follow_skin
from facewrap.wrapping.problem import WrapProblem
from facewrap.wrapping.projection import Projection, project_to_surface, seen_fit_p95
from facewrap.wrapping.roles import FITTED, PART, PINNED
from facewrap.wrapping.unfold import (relax_flips, settle_turned_corners,
                                     step_back_new_folds, turn_back_within,
                                     unfold_among)

__all__ = ["project", "pin", "finish_fit"]


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
    return project_to_surface(problem.skin_mesh, problem.tree, vertices=vertices,
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
    each in a region as wide as it needs (:data:`_WIDE_UNFOLD`), and triangles
    left on the edge of a fold turned a little further back
    (:data:`_ON_THE_EDGE`).  The landmarks' vertices are held where the fit put
    them unless that leaves more folds; then they slide with the unfolding, and
    ``landmarks_slid`` says how far (the wrap warns when it is far).  ``rest`` (n, 3)
    is the pose a triangle is turned over from: the expression the blend weights
    make (:attr:`ModelFit.rest`), so a lip rolled by a pucker shape is not
    "unfolded"; default the aligned template.

    Returns
    -------
    vertices : (n, 3) float64
    summary : dict
        ``pinned``, ``unfolded`` and ``settled`` (vertices), ``landmarks_slid``
        (scan units: how far the unfolding moved a landmark's vertex; 0 when held).
    """
    initial_projection = projection
    template, roles = problem.template, problem.roles
    aligned = similarity.apply(template.vertices)
    summary = {"pinned": int(np.count_nonzero(roles == PINNED)), "unfolded": 0}
    out = vertices
    if problem.settings.unfold:
        upright = aligned if rest is None else rest
        pinned = roles == PINNED
        out, projection, unfolded = _unfold(problem, upright, vertices, projection, pinned)
        # the unfolding must not slide the landmarks along the scan (a wide region
        # relaxed toward the unfitted skin beyond a scan's border moved the jaw
        # points of a head of other proportions 10-33 mm): unfolded again with
        # their vertices held, kept if that leaves no more folds and the landmarks
        # nearer their targets
        marked = _landmark_vertices(problem)
        slid = float(np.linalg.norm(out[marked] - vertices[marked], axis=1).max(initial=0.0))
        summary["landmarks_slid"] = slid
        if slid > problem.settings.landmark_tolerance * template.with_vertices(vertices).scale():
            held = _unfold(problem, upright, vertices, initial_projection, pinned | marked)
            if (_fold_count(problem, held[0], upright) <= _fold_count(problem, out, upright)
                    and _landmark_error(problem, held[0]) < _landmark_error(problem, out)):
                out, projection, unfolded = held
                summary["landmarks_slid"] = 0.0
        summary.update(unfolded)
    out = pin(problem, out, similarity, projection)
    out = follow_skin(template.triangles, aligned, out, roles, start=rest)
    return out, summary


#: degrees: the turn from the rest pose the finish leaves a triangle within, short
#: of 90 so that no fold appears from a pose a little different.  ICT's face onto
#: james (hybrid) kept 1-5 triangles at 89.6-89.95 degrees from the fit's rest,
#: 90.0-90.9 from the template posed by the fitted weights alone, and 17-23 of its
#: fitting set past 88; with this margin 0-3 past 88 and none past 90 from either
#: pose, for a fit p95 0.000-0.012 mm higher (three seeds of the folds test)
_ON_THE_EDGE = 88.0

#: the second unfolding pass: each fold the first left in a region of its own, as
#: wide as it needs up to 12 rings (kept only if it unfolds), no budget shared
_WIDE_UNFOLD = {"rounds": 12, "most_relaxed": None, "each_region": True}


def _unfold(problem: WrapProblem, upright, vertices, projection: Projection | None,
            fixed) -> tuple[np.ndarray, Projection | None, dict]:
    """The unfolding passes of :func:`finish_fit` with ``fixed`` (n,) bool vertices
    held: (vertices, the projection they were landed by, ``unfolded`` and
    ``settled`` vertex counts)."""
    skin, roles = problem.skin_mesh, problem.roles      # the folds repaired are the skin's
    out = vertices
    relaxed, settled = np.zeros((2, len(out)), dtype=bool)
    for extra in ({}, _WIDE_UNFOLD):
        out, more = relax_flips(skin, upright, out, fixed=fixed, order=_UNFOLD_ORDER,
                                **extra)
        if more.any() and projection is not None:
            out, projection, again = _project_unfolded(
                problem, upright, out, projection, more if extra else None, fixed)
            more |= again
        relaxed |= more
        # slivers, one corner each (the second pass would smooth wide in vain)
        out, corners = settle_turned_corners(skin, upright, out,
                                             movable=~fixed & (roles != PART))
        settled |= corners
    # a triangle left on the edge of a fold is one from a pose a degree away
    # (the template posed by the fitted weights alone)
    out, edge = turn_back_within(skin, upright, out, _ON_THE_EDGE, fixed=fixed,
                                 order=_UNFOLD_ORDER)
    relaxed |= edge
    return out, projection, {"unfolded": int(relaxed.sum()), "settled": int(settled.sum())}


def _fold_count(problem: WrapProblem, vertices, upright) -> int:
    """Triangles of the skin turned past 90 degrees from ``upright``: the fitted
    skin's and its cavities' (a fold an inner lip holds shows as much)."""
    return int(turned_triangles(vertices, upright, problem.skin_mesh.triangles).sum())


def _landmark_error(problem: WrapProblem, vertices) -> float:
    """The largest distance of a landmark on ``vertices`` from its target."""
    at = problem.landmarks.positions(vertices, problem.template.triangles)
    return float(np.linalg.norm(at - problem.targets, axis=1).max(initial=0.0))


def _landmark_vertices(problem: WrapProblem) -> np.ndarray:
    """(n,) bool: the template vertices its paired landmarks lie on (the corners of
    a surface landmark's triangle)."""
    landmarks = problem.landmarks
    out = np.zeros(problem.template.n_vertices, dtype=bool)
    out[landmarks.vertex[landmarks.vertex >= 0]] = True
    on = landmarks.triangle >= 0
    out[problem.template.triangles[landmarks.triangle[on]].ravel()] = True
    return out


def _project_unfolded(problem: WrapProblem, upright, unfolded, projection: Projection,
                      region, fixed) -> tuple[np.ndarray, Projection, np.ndarray]:
    """``unfolded`` onto the scan again, keeping the orientation of ``upright``
    (what the new blend turns over unfolded among the vertices not projected,
    what still folds stepped back toward ``unfolded``).  With ``region`` (n,)
    bool, either every vertex or only the region's take the new landing points,
    whichever fits tighter (:func:`~facewrap.wrapping.projection.seen_fit_p95`):
    landing everything again can lose more elsewhere than the region gains.
    Returns the positions, projection and moved vertices."""
    skin, roles = problem.skin_mesh, problem.roles
    T = skin.triangles
    again = project(problem, unfolded, upright=upright)
    landed, moved = unfold_among(skin, upright,
                                 np.where(fixed[:, None], unfolded, again.vertices),
                                 ~fixed & ~again.projected)
    picks = [(landed, again, moved)] + ([] if region is None else [
        (np.where(region[:, None], landed, unfolded), projection, moved & region)])
    stepped = [(step_back_new_folds(T, upright, unfolded, out, fixed), kept,
                moved) for out, kept, moved in picks]
    (out, back), kept, moved = min(stepped, key=lambda c: seen_fit_p95(
        problem.tree, c[0][0][roles == FITTED]))     # the first of equals: everything
    return out, kept, moved | back
