"""Triangles a fit turned over, unfolded: by local smoothing (:func:`relax_flips`;
:func:`unfold_among` smooths only the vertices a projection left to its blend),
one corner at a time for slivers (:func:`settle_turned_corners`), or by stepping
back toward a pose with fewer folds (:func:`step_back_new_folds`).

"Turned" is the one test of :func:`facewrap.geometry.turned_triangles` (a normal
past 90 degrees from the reference pose's); triangles already folded over in the
reference (needles a modeller left inside out) are not counted.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import connected_components

from facewrap.geometry import (adjacent_triangle_pairs, face_normals, facing_apart,
                               folded_in, triangle_normals, turned, turned_triangles,
                               vertex_adjacency)
from facewrap.geometry.similarity import similarity_transform
from facewrap.mesh import Mesh
from facewrap.wrapping.blend import SmoothExtension

__all__ = ["relax_flips", "unfold_among", "settle_turned_corners", "step_back_new_folds",
           "turn_back_within"]


def step_back_new_folds(T, reference, before, after, fixed, *, step: float = 0.25,
                        rounds: int = 30, angle: float = 90.0, creases: bool = True
                        ) -> tuple[np.ndarray, np.ndarray]:
    """``after`` with the folds it made that ``before`` does not have brought back
    toward ``before``.

    A fold is a triangle turned past ``angle`` (90 degrees) from ``reference``, or
    (with ``creases``) a crease: two edge neighbours facing apart (their normals' dot
    product below 0).  Each round, the corners of the folds ``after`` still has and
    ``before`` has not move ``step`` of the way back to their ``before`` positions;
    after ``rounds`` they are there within 0.75**30 ~ 2e-4 of the way.  Small steps
    move only as many vertices, as little, as it takes: on ICT's head onto james, a second
    projection's one fold came back by moving 15 vertices (fit p95 1.907 -> 1.918
    mm), where putting vertices back at once moved 53 (2.030 mm).  Counting creases
    keeps a biharmonic fill from adding any (ICT's face onto james: 69 creased pairs
    with the harmonic blend, 143 with the fill unchecked, 43 checked).

    Parameters
    ----------
    T : (t, 3) int64
    reference : (n, 3) float
        Positions whose triangle orientation is right (the aligned template, the fit).
    before, after : (n, 3) float
        A pose with fewer folds, and the pose to keep wherever it folds nothing more.
    fixed : (n,) bool
        Vertices that never move.
    step : float
        In (0, 1].
    rounds : int
    angle : float
        Degrees: a triangle turned past it is a fold.
    creases : bool
        Count creases as folds.

    Returns
    -------
    vertices : (n, 3) float64
    moved : (n,) bool

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.], [1, 1, 0]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2]])
    >>> after = V.copy(); after[3] = [-0.5, -0.5, 0]      # turns triangle 1 over
    >>> out, moved = step_back_new_folds(T, V, V, after, np.zeros(4, bool))
    >>> moved.tolist(), bool(turned_triangles(out, V, T).any())   # both sides of the crease
    ([True, True, True, True], False)
    """
    was = turned_triangles(before, reference, T, angle)     # (checks the arrays too)
    T = np.asarray(T, dtype=np.int64)
    pairs = adjacent_triangle_pairs(T)                      # each shared edge once
    out = np.array(after, dtype=np.float64)
    before = np.asarray(before, dtype=np.float64)
    was_apart = facing_apart(before, T, pairs)
    # what folds in ``out``, kept per triangle and per shared edge and tested again
    # each round only where a corner moved: a round moves a few corners of a mesh
    reference_normals = triangle_normals(np.asarray(reference, dtype=np.float64), T)
    is_turned = turned(reference_normals, triangle_normals(out, T), angle)
    unit = face_normals(out, T)
    is_apart = np.einsum("ij,ij->i", unit[pairs[:, 0]], unit[pairs[:, 1]]) < 0
    moved = np.zeros(len(out), dtype=bool)
    for _ in range(rounds):
        new = is_turned & ~was
        # a crease too: neighbours facing apart that did not in ``before``
        if creases:
            new[pairs[is_apart & ~was_apart].ravel()] = True
        corners = np.zeros(len(out), dtype=bool)
        corners[T[new]] = True
        corners &= ~fixed
        if not corners.any():
            break
        moved |= corners
        out[corners] += step * (before[corners] - out[corners])
        touched = corners[T].any(axis=1)
        t = np.flatnonzero(touched)
        is_turned[t] = turned(reference_normals[t], triangle_normals(out, T[t]), angle)
        unit[t] = face_normals(out, T[t])
        p = np.flatnonzero(touched[pairs[:, 0]] | touched[pairs[:, 1]])
        is_apart[p] = np.einsum("ij,ij->i", unit[pairs[p, 0]], unit[pairs[p, 1]]) < 0
    return out, moved


#: relax_flips stops after this many rounds that unfold nothing, or (by default)
#: once it has relaxed this fraction of the vertices
_STALLED_ROUNDS = 3
_MOST_RELAXED = 0.02


def relax_flips(template: Mesh, reference, vertices, *, fixed=None, order: int = 1,
                rounds: int = 10, fewest: bool = False,
                most_relaxed: float | None = _MOST_RELAXED, each_region: bool = False,
                angle: float = 90.0) -> tuple[np.ndarray, np.ndarray]:
    """Unfold triangles that face away from ``reference``, by smoothing locally.

    A fit can leave a few triangles turned over where the scan ends, in a crease
    or beside a cavity.  Their vertices and one ring around them give up their
    displacement from ``reference`` and take the smooth extension of their
    neighbours' (:class:`~facewrap.wrapping.blend.SmoothExtension`); the relaxed
    region grows by a ring a round until no triangle is turned past ``angle`` (90 degrees), ``rounds`` are
    done (no region is wider than about ``rounds`` rings), three rounds unfold
    nothing more or ``most_relaxed`` of the vertices are relaxed.  With ``each_region``,
    only the connected pieces of the region that still hold a turned triangle
    grow, rounds that unfold nothing included (a wide fold unfolds all at once),
    and a piece that has not unfolded its triangles after ``rounds`` is put
    back as it was: one fold cluster that needs a wide region does not widen
    the others (nor, with ``most_relaxed`` None, stop them), and one that no
    region of that width unfolds (an expression's own turn, not a fold) is
    left alone.  Triangles already folded over
    in ``reference`` (facing away from every neighbour: needles a modeller left
    inside out) are not counted: the fit turning them with their neighbours is no
    fold.  Nothing else moves.

    Parameters
    ----------
    template : Mesh
        Topology.
    reference : (n, 3) float
        Positions whose orientation is right (the aligned template).
    vertices : (n, 3) float
        The fit.
    fixed : (n,) bool, optional
        Vertices that must not move (pinned ones).
    order : {1, 2}
    rounds : int
    fewest : bool
        Return the round that left the fewest triangles turned over (never more
        than ``vertices`` had) instead of the last one.  The last round's wider
        smoothing suits a fit that is projected again afterwards; a final pass
        wants the fewest folds.
    most_relaxed : float or None
        Fraction of the vertices after which no region grows (None: no such
        bound; ``rounds`` still bounds each region's width).
    each_region : bool
        Grow only the pieces of the region that still hold a fold, keep only
        those that unfold theirs (``fewest`` is then moot).  Growing
        them all (the default) smooths wider around folds already gone: a
        better start for a fit projected again afterwards (on ICT's ground-truth
        cases with the graph model, a tighter one).

    angle : float
        Degrees: a triangle turned past it is a fold.

    Returns
    -------
    vertices : (n, 3) float64
    relaxed : (n,) bool
        The vertices that moved.

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0)), -1).reshape(-1, 2)
    >>> V = np.c_[g, np.zeros(16)]
    >>> T = np.array([[i, i + 1, i + 5] for i in (0, 1, 2, 4, 5, 6, 8, 9, 10)]
    ...              + [[i, i + 5, i + 4] for i in (0, 1, 2, 4, 5, 6, 8, 9, 10)])
    >>> fit = V.copy(); fit[5] = [2.6, 2.6, 0]          # pushed past its neighbours
    >>> out, moved = relax_flips(Mesh(V, T), V, fit)
    >>> bool(np.allclose(out[5], [1, 1, 0])), int(moved.sum()) > 0
    (True, True)
    """
    V0 = np.asarray(reference, dtype=np.float64)
    X = np.asarray(vertices, dtype=np.float64)
    T = template.triangles
    n0 = face_normals(V0, T)
    folded = folded_in(n0, T)
    keep = np.zeros(len(X), dtype=bool) if fixed is None else np.asarray(fixed, bool)
    relaxed = np.zeros(len(X), dtype=bool)
    out = X
    A = None
    extend = None
    last, stalled = len(T) + 1, 0
    best = (len(T) + 1, X, relaxed)
    for _ in range(rounds):
        flipped = turned(n0, face_normals(out, T), angle) & ~folded
        if flipped.sum() < best[0]:
            best = (int(flipped.sum()), out, relaxed.copy())
        if not flipped.any():
            break
        stalled = stalled + 1 if flipped.sum() >= last else 0
        if (stalled >= _STALLED_ROUNDS and not each_region) or (
                most_relaxed is not None and relaxed.mean() > most_relaxed):
            break               # smoothing wider no longer helps
        last = int(flipped.sum())
        if A is None:
            A = vertex_adjacency(T, len(X)).tocsr()
            extend = SmoothExtension(template, order)
        if each_region:
            grown = _grown_where_folded(A, relaxed, T[flipped])
        else:
            grown = relaxed.copy()
            grown[T[flipped]] = True
            grown |= (A @ grown.astype(np.float64)) > 0
        relaxed |= grown & ~keep
        out = V0 + extend(X - V0, ~relaxed)
        out[~relaxed] = X[~relaxed]
    if each_region and relaxed.any():
        out, relaxed = _unfolded_regions_only(A, X, out, relaxed,
                                              T[turned(n0, face_normals(out, T), angle)
                                                & ~folded])
    elif fewest and turned(n0, face_normals(out, T), angle)[~folded].sum() >= best[0]:
        return best[1], best[2]
    return out, relaxed


def _unfolded_regions_only(A, X, out, relaxed, corners):
    """``out`` with each connected piece of ``relaxed`` that still touches a
    corner of the triangles ``corners`` (k, 3) still turned put back to ``X``: a
    triangle's corners lie in one piece at most (two pieces sharing an edge are
    one), so each piece unfolds its own triangles or leaves them as they were."""
    idx = np.flatnonzero(relaxed)
    _, label = connected_components(A[idx][:, idx], directed=False)
    touched = np.zeros(len(relaxed), dtype=bool)
    touched[corners] = True
    failed = np.zeros(label.max() + 1, dtype=bool)
    failed[label[touched[idx]]] = True
    back = idx[failed[label]]
    out, relaxed = out.copy(), relaxed.copy()
    out[back], relaxed[back] = X[back], False
    return out, relaxed


def _grown_where_folded(A, relaxed, corners) -> np.ndarray:
    """(n,) bool: ``relaxed`` and the ``corners`` (k, 3) of the triangles still
    turned, with each connected piece of them that holds such a corner grown by
    one ring of the vertex adjacency ``A`` (n, n); the pieces whose folds are
    gone stay as they are."""
    seeds = np.zeros(len(relaxed), dtype=bool)
    seeds[corners] = True
    region = relaxed | seeds
    idx = np.flatnonzero(region)
    _, label = connected_components(A[idx][:, idx], directed=False)
    live = np.zeros(label.max() + 1, dtype=bool)
    live[label[seeds[idx]]] = True
    active = np.zeros(len(relaxed), dtype=bool)
    active[idx[live[label]]] = True
    return region | ((A @ active.astype(np.float64)) > 0)


def unfold_among(template: Mesh, reference, vertices, free, *, counted=None
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`relax_flips` moving only the ``free`` (n,) bool vertices (those a
    projection left to its blend: the landing points stay on the scan), kept only
    when fewer of the ``counted`` (t,) bool triangles (default all) are turned
    past 90 degrees from ``reference`` than before.

    Returns
    -------
    vertices : (n, 3) float64
        ``vertices`` itself when nothing is kept.
    moved : (n,) bool

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.], [1, 1, 0]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2]])
    >>> fit = V.copy(); fit[3] = [-0.5, -0.5, 0]       # turns triangle 1 over
    >>> out, moved = unfold_among(Mesh(V, T), V, fit, np.array([0, 0, 0, 1], bool))
    >>> moved.tolist(), bool(turned_triangles(out, V, T).any())
    ([False, False, False, True], False)
    """
    T = template.triangles
    out, moved = relax_flips(template, reference, vertices, fixed=~np.asarray(free, bool),
                             fewest=True)
    counted = np.ones(len(T), bool) if counted is None else np.asarray(counted, bool)
    if not moved.any() or (turned_triangles(out, reference, T)[counted].sum()
                           >= turned_triangles(vertices, reference, T)[counted].sum()):
        return vertices, np.zeros(len(vertices), dtype=bool)
    return out, moved


#: settle_turned_corners gives up when more triangles than this are still turned:
#: a fit that bad needs more than corners moved
_MOST_SETTLED = 200
#: a triangle whose height over its longest edge is below this is a sliver: its
#: orientation is set by sub-micron differences between its corners
_SLIVER = 0.1


def settle_turned_corners(template: Mesh, reference, vertices, *, movable=None
                          ) -> tuple[np.ndarray, np.ndarray]:
    """Turn back slivers still facing away from ``reference``, one corner each.

    What :func:`relax_flips` cannot unfold is mostly a sliver: a triangle so thin
    (ICT-FaceKit has one 0.02 mm across, standing at 90 degrees to its neighbours)
    that its orientation is set by sub-micron differences between its corners, so
    any smooth deformation turns it either way.  Each turned sliver (height below
    a tenth of its longest edge) has its corner opposite that edge put back where
    the rigid motion of the vertices around the edge (their best rotation from
    ``reference`` to ``vertices``) carries it, relative to the edge's midpoint:
    it moves by about the sliver's width.  A corner is moved only when that leaves
    fewer triangles around it turned past 90 degrees.  A triangle of fair shape
    that is still turned is left alone: its turn is the fit's (a rolled lip), not
    round-off.

    Parameters
    ----------
    template : Mesh
        Topology.
    reference : (n, 3) float
        Positions whose orientation is right.
    vertices : (n, 3) float
        The fit.
    movable : (n,) bool, optional
        Corners that may move (default all).

    Returns
    -------
    vertices : (n, 3) float64
    moved : (n,) bool

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [.5, .01, 0], [.5, 1, 0], [.5, -1, 0]])
    >>> T = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 0], [0, 4, 1]])   # 0 1 2: a sliver
    >>> fit = V.copy(); fit[2, 1] = -.01            # its corner slips across: turned
    >>> out, moved = settle_turned_corners(Mesh(V, T), V, fit)
    >>> moved.tolist(), bool(np.allclose(out[2], V[2]))
    ([False, False, True, False, False], True)
    """
    R = np.asarray(reference, dtype=np.float64)
    out = np.array(vertices, dtype=np.float64)
    T = template.triangles
    n0 = face_normals(R, T)
    counted = ~folded_in(n0, T)
    may = np.ones(len(out), bool) if movable is None else np.asarray(movable, bool)
    moved = np.zeros(len(out), dtype=bool)
    todo = np.flatnonzero(turned(n0, face_normals(out, T), 90.0) & counted)
    if not len(todo) or len(todo) > _MOST_SETTLED:
        return out, moved
    edges = np.linalg.norm(R[T[todo][:, [1, 2, 0]]] - R[T[todo]], axis=2)   # (k, 3)
    longest = edges.max(axis=1)
    # twice the area over the longest edge
    height = (np.linalg.norm(triangle_normals(R, T[todo]), axis=1)
              / np.maximum(longest, np.finfo(float).tiny))
    slivers = height < _SLIVER * longest
    adjacency = vertex_adjacency(T, len(out)).tocsr()
    for f, k in zip(todo[slivers], edges[slivers].argmax(axis=1)):   # a handful
        a, b, c = T[f, k], T[f, (k + 1) % 3], T[f, (k + 2) % 3]
        if may[c] and _settle_corner(out, R, T, n0, counted, adjacency, a, b, c):
            moved[c] = True
    return out, moved


def _settle_corner(out, R, T, n0, counted, adjacency, a, b, c) -> bool:
    """Corner ``c`` put where the rigid motion of the vertices around edge ``ab``
    carries it from ``R`` (in ``out``, in place), if that leaves fewer triangles
    around ``c`` turned past 90 degrees."""
    hood = np.union1d(adjacency[a].indices, adjacency[b].indices)
    hood = hood[hood != c]
    if len(hood) < 3:
        return False
    rotation = similarity_transform(R[hood], out[hood], scale=False).rotation
    place = (out[a] + out[b]) / 2 + rotation @ (R[c] - (R[a] + R[b]) / 2)
    around = np.flatnonzero((T == c).any(axis=1) & counted)
    before = turned(n0[around], face_normals(out, T[around]), 90.0).sum()
    kept = out[c].copy()
    out[c] = place
    if turned(n0[around], face_normals(out, T[around]), 90.0).sum() < before:
        return True
    out[c] = kept
    return False


def turn_back_within(template: Mesh, reference, vertices, angle: float, *, fixed=None,
                     order: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Triangles turned past ``angle`` degrees from ``reference`` brought within it,
    moving their corners only as far as it takes.

    For a margin below 90 degrees: a triangle an unfolding left at 89.9 degrees
    from one pose is past 90 from a pose a degree away.  Where
    :func:`relax_flips` (at ``angle``, each region as wide as it needs) turns
    such a triangle back, its corners step a tenth of the way at a time toward
    the relaxed pose (:func:`step_back_new_folds`, creases not counted) until it
    is within ``angle``; far less than the relaxation moves them.  Nothing
    changes when that would leave more triangles turned past 90 degrees.

    Parameters
    ----------
    template : Mesh
        Topology.
    reference : (n, 3) float
        Positions whose orientation is right.
    vertices : (n, 3) float
        The fit.
    angle : float
        Degrees.
    fixed : (n,) bool, optional
        Vertices that must not move.
    order : {1, 2}
        Of the relaxation's smooth extension.

    Returns
    -------
    vertices : (n, 3) float64
    moved : (n,) bool

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> g = np.stack(np.meshgrid(np.arange(4.0), np.arange(4.0)), -1).reshape(-1, 2)
    >>> V = np.c_[g, np.zeros(16)]
    >>> T = np.array([[i, i + 1, i + 5] for i in (0, 1, 2, 4, 5, 6, 8, 9, 10)]
    ...              + [[i, i + 5, i + 4] for i in (0, 1, 2, 4, 5, 6, 8, 9, 10)])
    >>> fit = V.copy(); fit[5, 2] = 10.0       # its triangles turn 84-86 degrees
    >>> out, moved = turn_back_within(Mesh(V, T), V, fit, 80.0)
    >>> bool(turned_triangles(fit, V, T, 80.0).any()), bool(turned_triangles(out, V, T,
    ...                                                                      80.0).any())
    (True, False)
    >>> round(float(out[5, 2]), 2)       # part of the way down (relaxed, it would be 0)
    3.87
    """
    T = template.triangles
    X = np.array(vertices, dtype=np.float64)
    unmoved = np.zeros(len(X), bool)
    fixed = np.zeros(len(X), bool) if fixed is None else np.asarray(fixed, bool)
    toward, relaxed = relax_flips(template, reference, X, fixed=fixed, order=order,
                                  angle=angle, rounds=12, most_relaxed=None,
                                  each_region=True)
    if not relaxed.any():          # (most fits: nothing to turn, or nothing turns it)
        return X, unmoved
    out, moved = step_back_new_folds(T, reference, toward, X, fixed, angle=angle,
                                     step=0.1, rounds=60, creases=False)
    # (a corner stepped part of the way can turn a neighbour over: then nothing moves)
    if turned_triangles(out, reference, T).sum() > turned_triangles(X, reference, T).sum():
        return X, unmoved
    return out, moved
