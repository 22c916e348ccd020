"""How the template's parts follow the skin, and stay on their side of it.

The template's parts (eyeballs, teeth, gums, tongue, lashes: :mod:`.roles`) are
not pulled by the scan.  :func:`follow_skin` moves each piece by a smooth warp of
space that carries the skin around it (its anchors: the skin vertices nearest to
each of its vertices, at most 200 of them spread by farthest-point sampling) as
the fit carried it: the biharmonic RBF warp of SPEC §1.2
(:class:`~facewrap.wrapping.warp.RBFWarp`).  With a blendshape fit the parts start
from the pose its weights made (the lower teeth dropped with the jaw its
``jawOpen`` opened) and only the skin's motion beyond that pose carries them: from
the neutral, the lips' motion alone carried every tooth (a pucker pushed them
forward 4 mm, a closed mouth over an open jaw left the lower teeth 14 mm high).
An eyeball moves with its socket and
lids, a tooth with the mouth socket and inner lips, whatever the deformation
model did between them, and being smooth the warp folds no triangle.  A closed
piece (no border: an eyeball, a tooth) is a solid body: it moves by the rigid
motion nearest to the warp when that leaves none of its vertices on the wrong
side of the skin (an eyeball squeezed between lids and a socket the scan moved
apart bends with them instead).  A part
vertex that still ends up on the other side of the skin than on the template
(signed distance by libigl's pseudonormal test; the skin is every triangle that is
not part) is put back at its template offset from the closest skin point, along
the skin's normal there (after three rounds ever nearer the skin: at a closed
eyelid the full offset crosses the lid's other sheet); vertices that touch the
skin on the template (closer than ``2e-4`` of its size) have no side to keep, nor have those whose closest skin
point on the template lies on the skin's border (a face region cut from its head:
an eyeball seen through the eyelids' opening lies beyond the skin, not in front of
or behind it, and putting it back "in front" along a border normal throws it
centimetres away).
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry import (boundary_edges, connected_components, farthest_point_sampling,
                               similarity_transform)
from facewrap.wrapping.roles import PART
from facewrap.wrapping.warp import RBFWarp

__all__ = ["follow_skin", "side_changes"]

_ANCHORS = 8           # skin vertices nearest to each part vertex that carry it
_MOST_ANCHORS = 200    # per piece: enough to follow a socket, a small solve
_CONTACT = 2e-4        # of the template's size: a part vertex this near touches the skin
_ON_EDGE = 1e-9        # a barycentric coordinate this small: the closest point is on an edge
_FULL_OFFSET_ROUNDS = 3  # put-back rounds at the template's offset, before nearer ones


def _signed(points, V, T):
    """Signed distances, closest points, normals there and closest triangles of
    ``points`` to ``(V, T)``."""
    import igl    # the compiled core, loaded on use
    S, I, C, N = igl.signed_distance(np.ascontiguousarray(points), V, T,
                                     igl.SignedDistanceType.SIGNED_DISTANCE_TYPE_PSEUDONORMAL)
    return S, C, N, np.asarray(I, dtype=np.int64)


def _on_border(C, I, V, T, border) -> np.ndarray:
    """(k,) bool: closest points ``C`` (k, 3), on triangles ``I`` (k,) of ``(V, T)``,
    that lie on its border: on a border edge, or at a corner that is a border vertex.
    ``border`` is :func:`_border` of ``T``."""
    edges, vertices = border
    if len(C) == 0 or not vertices.any():
        return np.zeros(len(C), dtype=bool)
    corners = T[I]
    P = V[corners]
    # barycentric coordinates of C: areas of the sub-triangles opposite each corner
    area = np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    sub = np.stack([np.linalg.norm(np.cross(P[:, (k + 1) % 3] - C, P[:, (k + 2) % 3] - C),
                                   axis=1) for k in range(3)], axis=1)
    low = sub < _ON_EDGE * np.maximum(area, 1e-300)[:, None]
    n = len(V)
    out = np.zeros(len(C), dtype=bool)
    for k in range(3):          # the edge opposite corner k
        a, b = corners[:, (k + 1) % 3], corners[:, (k + 2) % 3]
        out |= low[:, k] & np.isin(np.minimum(a, b) * n + np.maximum(a, b), edges)
    corner = corners[np.arange(len(C)), np.argmax(sub, axis=1)]
    return out | ((low.sum(axis=1) >= 2) & vertices[corner])


def _distinct(points, moves):
    """``points`` (k, 3) one per position, with the mean of their ``moves`` (k, 3):
    a skin may hold two vertices at one point (the lips of a closed mouth, a seam
    the fit may have parted), which a warp cannot take as two anchors.

    >>> P = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 0.]])
    >>> _distinct(P, np.array([[0, 0, 1], [0, 0, 0], [0, 0, 3.]]))[1].tolist()
    [[0.0, 0.0, 2.0], [0.0, 0.0, 0.0]]
    """
    _, first, inverse = np.unique(points.round(12), axis=0, return_index=True,
                                  return_inverse=True)
    inverse = inverse.ravel()
    mean = np.zeros((len(first), 3))
    np.add.at(mean, inverse, moves)
    return points[first], mean / np.bincount(inverse)[:, None]


def _border(T, n):
    """Border edges of ``T`` as keys ``min * n + max`` and the (n,) border-vertex mask."""
    E = np.sort(boundary_edges(T), axis=1)
    vertices = np.zeros(n, dtype=bool)
    vertices[E.ravel()] = True
    return E[:, 0] * n + E[:, 1], vertices


class _SkinSides:
    """The side of the skin (every triangle that is not part) each part vertex lies
    on in the aligned template ``R``, and the test of other positions against it."""

    def __init__(self, T, roles, R):
        self.part = np.flatnonzero(roles == PART)
        self.skin_T = T[(roles[T] != PART).all(axis=1)]
        self.usable = bool(len(self.part) and len(self.skin_T))
        self.border = _border(self.skin_T, len(R))
        contact = _CONTACT * float(np.linalg.norm(R.max(axis=0) - R.min(axis=0)))
        self.s0 = np.zeros(len(self.part))
        self.sided = np.zeros(len(self.part), dtype=bool)
        if self.usable:
            self.s0, C, _, I = _signed(R[self.part], R, self.skin_T)
            self.sided = (np.abs(self.s0) > contact) & ~_on_border(C, I, R, self.skin_T,
                                                                   self.border)

    def wrong(self, points, X, which=None):
        """Part vertices at ``points`` (of the parts ``which``, default all) against
        the skin of ``X``: (wrong side, closest skin points, skin normals there).  A
        vertex whose closest skin point is on the border, on the template or here,
        has no side."""
        which = slice(None) if which is None else which
        s1, C, N, I = _signed(points, X, self.skin_T)
        wrong = (np.sign(s1) != np.sign(self.s0[which])) & self.sided[which]
        if wrong.any():
            wrong[wrong] = ~_on_border(C[wrong], I[wrong], X, self.skin_T, self.border)
        return wrong, C, N


def side_changes(template_triangles, reference, vertices, roles) -> np.ndarray:
    """(p,) bool: part vertices (in id order) on the other side of the skin than on
    the aligned template (``reference``); see the module docstring.  Vertices that
    touch the skin on the template do not count.

    >>> import numpy as np
    >>> from facewrap.wrapping.roles import PART
    >>> V = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [1, 1, -1.]])
    >>> roles = np.array([0, 0, 0, PART], np.int8)
    >>> fit = V.copy(); fit[3, 2] = 1.0                  # came through the skin
    >>> side_changes([[0, 1, 2]], V, fit, roles).tolist()
    [True]
    """
    sides = _SkinSides(np.asarray(template_triangles, dtype=np.int64), np.asarray(roles),
                       np.asarray(reference, dtype=np.float64))
    if not sides.usable:
        return np.zeros(len(sides.part), dtype=bool)
    X = np.asarray(vertices, dtype=np.float64)
    return sides.wrong(X[sides.part], X)[0]


def follow_skin(template_triangles, reference, vertices, roles, *,
                rounds: int = 16, start=None) -> np.ndarray:
    """Move the template's part vertices with the skin nearest to them.

    Parameters
    ----------
    template_triangles : (t, 3) int64
    reference : (n, 3) float
        The aligned template.
    vertices : (n, 3) float
        The fit (skin vertices are kept as they are).
    roles : (n,) int8
        :func:`facewrap.wrapping.roles.vertex_roles`.
    rounds : int
        Passes of the side check (each only of the vertices the last put back).
    start : (n, 3) float, optional
        The pose the parts move from, the skin's motion measured from it: the pose
        a blendshape fit made (its jaw opened with the lower teeth, its eyes
        closed over still eyeballs), so only the skin's motion beyond it carries
        the parts; default ``reference``.  Sides are those of ``reference``.

    Returns
    -------
    (n, 3) float64

    Examples
    --------
    A part under a skin patch that the fit lifted: it is lifted alike.

    >>> import numpy as np
    >>> from facewrap.wrapping.roles import PART
    >>> g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    >>> skin = np.c_[g, np.zeros(25)]
    >>> T = np.array([[i, i + 1, i + 6] for i in range(19) if i % 5 < 4]
    ...              + [[i, i + 6, i + 5] for i in range(19) if i % 5 < 4])
    >>> R = np.vstack([skin, [[2.0, 2.0, -0.5]]])
    >>> roles = np.r_[np.zeros(25, np.int8), [PART]].astype(np.int8)
    >>> fit = R + [0, 0, 3.0]; fit[25] = [9, 9, 9]       # the model left it behind
    >>> out = follow_skin(T, R, fit, roles)
    >>> np.round(out[25], 6).tolist()
    [2.0, 2.0, 2.5]
    """
    T = np.asarray(template_triangles, dtype=np.int64)
    roles = np.asarray(roles)
    X = np.array(vertices, dtype=np.float64)
    R = np.asarray(reference, dtype=np.float64)
    S = R if start is None else np.asarray(start, dtype=np.float64)
    part = np.flatnonzero(roles == PART)
    skin = np.flatnonzero(roles != PART)
    if len(part) == 0 or len(skin) == 0:
        return X
    k = min(_ANCHORS, len(skin))
    from scipy.spatial import cKDTree   # only a template with parts needs it
    _, near = cKDTree(S[skin]).query(S[part], k=k)
    near = skin[np.asarray(near).reshape(len(part), k)]
    labels = connected_components(T, len(X))
    solid = np.ones(int(labels.max()) + 1, dtype=bool)
    solid[labels[boundary_edges(T)[:, 0]]] = False
    pieces = labels[part]
    rigid = X[part].copy()
    for piece in np.unique(pieces):
        mine = pieces == piece
        anchors = np.unique(near[mine].ravel())
        if len(anchors) > _MOST_ANCHORS:
            anchors = anchors[farthest_point_sampling(S[anchors], _MOST_ANCHORS)]
        warp = RBFWarp().fit(*_distinct(S[anchors], X[anchors] - S[anchors]))
        X[part[mine]] = warp.transform(S[part[mine]])
        if solid[piece]:
            rigid[mine] = similarity_transform(S[part[mine]], X[part[mine]],
                                               scale=False).apply(S[part[mine]])
    sides = _SkinSides(T, roles, R)
    if not sides.usable:
        return X
    if solid[pieces].any():
        kept = np.bincount(pieces, sides.wrong(rigid, X)[0], minlength=len(solid))
        # rigid only where that keeps the whole piece behind the skin: putting single
        # vertices of a rigid piece back would dent it
        whole = (solid & (kept == 0))[pieces]
        X[part[whole]] = rigid[whole]
    # only the vertices put back move (the skin does not), so each round checks
    # those again; past a few rounds they are put back ever nearer the skin: at a
    # thin sheet (an eyelid closed) the full template offset crosses the other side
    which = np.arange(len(part))
    for round_ in range(rounds):
        wrong, C, N = sides.wrong(X[part[which]], X, which)
        if not wrong.any():
            break
        which = which[wrong]
        n = N[wrong] / np.maximum(np.linalg.norm(N[wrong], axis=1, keepdims=True), 1e-300)
        nearer = 0.5 ** max(0, round_ - _FULL_OFFSET_ROUNDS + 1)
        X[part[which]] = C[wrong] + n * (nearer * sides.s0[which, None])
    return X
