"""Remove the rigid head motion of an expression against the neutral (issue 19).

A person's expression scans are taken with their head turned and moved a little
each time.  Wrapped in the template's topology, each expression still carries that
motion; before its shape can tell the rig anything, the motion is taken out by
aligning the vertices that ride on the skull -- forehead top, temples, nose
bridge, the back of the head -- onto the neutral's.

Those vertices come from the template's profile (ICT-FaceKit's
``idx_to_rigid_verts``) or are found with :func:`least_moving`: the vertices that
move least across the template's shapes (or across a stabilised capture).  Some of
them still move a little in some expressions (a brow raise lifts the forehead's
lower edge), so the rigid fit is reweighted (iteratively reweighted least squares,
a Cauchy weight on each vertex's residual against the median): vertices the
expression moves lose their say and the skull's pose is what is left
(:func:`stabilise`).

That pose is only as good as the wraps' vertex positions, and a wrap slides along
smooth skin by a fraction of a millimetre: on ICT-FaceKit the rigid-vertex pose
was 0.15-0.5 mm off.  :func:`refine_pose` then registers a *prediction* of the
expression (the rig's, at the weights that best explain the stabilised wrap)
onto the expression's scan surface by point-to-plane rigid ICP: the sliding does
not enter (the surface has none), the expression's own motion is modelled by the
prediction, and every vertex both scans saw can take part.  The prediction is not
the person's expression, though, and errs most where the expression moves the
skin most (a smile 1.4 times stronger on one side than the rig's pulls the pose
toward that side): each vertex's pair is weighed by the inverse of a variance that
grows with how far the prediction moves it from the neutral.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry.checks import as_points, as_vertex_ids
from facewrap.geometry.normals import vertex_normals
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.wrapping.align import rigid_icp

__all__ = ["least_moving", "stabilise", "refine_pose", "Stabilised", "unlike_neutral",
           "OTHER_HEAD_SHAPE", "NO_EXPRESSION", "ROBUST_SCALE",
           "ROBUST_ITERATIONS", "REFINE_STILL_ERROR", "REFINE_MOTION_ERROR",
           "REFINE_DISTANCE", "REFINE_POINTS", "REFINE_TOLERANCE"]

#: residuals are weighed against this many times their median (Cauchy's ``c``): a
#: vertex moved by the expression by three times the typical residual has a tenth
#: of the weight of a still one
ROBUST_SCALE = 1.0
#: reweighting rounds (the pose settles in well under this on the sample and ICT)
ROBUST_ITERATIONS = 20
#: :func:`refine_pose` weighs a vertex's pair by 1 / sigma^2, sigma^2 = (a * size)^2 +
#: (b * motion)^2: how far off the prediction is likely to be there.  ``a`` is this,
#: a fraction of the face's bounding-box diagonal: 0.1 mm on ICT-FaceKit's head
#: (381 mm), the error of a vertex the expression leaves still (wrap, noise) ...
REFINE_STILL_ERROR = 2.6e-4
#: ... and ``b`` is this share of the prediction's own move from the neutral (the
#: person's expression differs most from the rig's where the skin moves most).
#: Only a / b counts: a vertex predicted to move 1 mm (on ICT) keeps half the
#: weight of a still one, 3 mm a tenth.  Measured with bench_rig's example scans
#: (identities 004-006, six sets of six expressions, each under a head motion of
#: 5-15 degrees and 5-20 mm; wraps of main c493afb): mean stabilisation error
#: 0.072 mm, 4 of 36 over 0.1 mm, against 0.109 mm and 20 of 36 with the former
#: unweighted ICP trimmed to its best 80 % of pairs.  That 1 mm knee had the best
#: mean (0.5 / 0.7 / 2 / 4 mm: 0.076 / 0.074 / 0.078 / 0.090); a trim of 90 or 80 %
#: on top (0.080 / 0.081) or Cauchy weights on the residual (0.074-0.075) did worse
REFINE_MOTION_ERROR = 0.1
#: :func:`refine_pose` pairs points no farther apart than this fraction of the
#: face's size (3.8 mm on ICT-FaceKit's head)
REFINE_DISTANCE = 0.01
#: at most about this many vertices take part (every k-th of them)
REFINE_POINTS = 3000
#: the refinement stops when a step moves the points by less than this fraction of
#: their extent (RMS): 2 micrometres on a face, fifty times under the 0.1 mm the
#: pose must reach; rigid ICP's own default (1e-7) took twice the steps for the
#: same pose to four decimals (bench_rig, ICT identity 004's six examples)
REFINE_TOLERANCE = 1e-5


#: :func:`unlike_neutral`: an expression's wrap whose skull-rigid vertices lie
#: farther than this fraction of the face's size from the neutral's, along the
#: neutral's normals (median, after a robust rigid fit on them alone,
#: :func:`stabilise`), is of another head.  Along the normals: a wrap slides along
#: the skin (ICT-FaceKit: 0.15-0.5 mm), which says nothing of the skull's shape and
#: put the plain distances of one person's expressions within 1.5 times of another
#: person's.  The sample: one person's expressions and a re-scan of the neutral
#: 0.04-0.06 %, two other identities 0.18 and 0.33 %; ICT-FaceKit (bench_rig's
#: example scans): identity 004's expressions 0.05 %, identity 005's 0.12 %
OTHER_HEAD_SHAPE = 0.0009
#: ... and one whose every seen vertex (99.5th percentile) stays within this fraction
#: of the neutral's shows no expression: the neutral given again, moved or
#: re-exported (the same file: 0.002 %; a re-scan of the neutral, which no measure
#: tells from an expression at 15 % of its strength, 0.4 %)
NO_EXPRESSION = 0.0005


def unlike_neutral(expression, neutral, triangles, rigid, seen=None, *,
                   reference: str = "the neutral's", still: bool = False,
                   limit: float = OTHER_HEAD_SHAPE) -> str | None:
    """Why a stabilised expression cannot be the neutral's person making a face, or
    None: a skull of another shape (another person's scan), or no expression at all.

    Judged after the fit (the wraps and the stabilisation are what tell the skull
    from the face); nothing is changed.

    Parameters
    ----------
    expression, neutral : (n, 3) float
        The stabilised expression's vertices (:attr:`Stabilised.vertices`) and the
        neutral's, in one topology.
    triangles : (t, 3) int
        The topology's triangles (the neutral's normals are measured along).
    rigid : (r,) int
        The skull-rigid vertices.
    seen : (n,) bool, optional
        The vertices both scans saw (a wrap only follows elsewhere).
    reference : str
        What ``neutral`` is, in the line ("frame 0's" for a sequence).
    still : bool
        No expression is no oddity (a sequence's frames may hold still).
    limit : float
        The skull's distance (fraction of the face's size) beyond which it is of
        another head: :data:`OTHER_HEAD_SHAPE` for wraps with landmarks of their own.

    Returns
    -------
    str or None
        One line beginning ``"scan: "`` (the file is named by the caller), sizes as
        fractions of the face's (no unit needed).
    """
    X, V = np.asarray(expression, np.float64), np.asarray(neutral, np.float64)
    seen = np.ones(len(V), dtype=bool) if seen is None else np.asarray(seen, bool)
    if seen.sum() < 4:
        return None
    size = float(np.linalg.norm(V[seen].max(axis=0) - V[seen].min(axis=0)))
    d = np.linalg.norm(X - V, axis=1)
    ids = np.asarray(rigid)[seen[rigid]]
    ids = ids if len(ids) else np.asarray(rigid)
    normals = vertex_normals(V, triangles)
    across = np.abs(np.einsum("ij,ij->i", X[ids] - V[ids], normals[ids]))
    skull = float(np.median(across)) / size
    if skull > limit:
        return (f"scan: where the skull is rigid its fit lies {100 * skull:.2g} % of the "
                f"face's size off {reference} surface (one person's expressions: under "
                f"{100 * limit:.2g} %): another person's scan?")
    most = float(np.percentile(d[seen], 99.5)) / size
    if not still and most < NO_EXPRESSION:
        return (f"scan: shows no expression (its fit is the neutral's within "
                f"{100 * most:.2g} % of the face's size): the neutral scan again?")
    return None


def least_moving(poses, rest, fraction: float = 0.1, among=None) -> np.ndarray:
    """The ``fraction`` of vertices whose largest move over ``poses`` is smallest.

    Parameters
    ----------
    poses : (k, n, 3) float
        Shapes (or stabilised scans) of one topology; ``k`` may be 0.
    rest : (n, 3) float
        Their rest positions (the neutral).
    fraction : float
        Share of the vertices kept (at least 3 are).
    among : (n,) bool, optional
        The candidates (say, the vertices a scan saw); ``fraction`` is of them.

    Returns
    -------
    (m,) int64
        Sorted vertex ids.

    Examples
    --------
    >>> rest = np.zeros((10, 3))
    >>> poses = np.zeros((1, 10, 3)); poses[0, :, 0] = np.arange(10)
    >>> least_moving(poses, rest, 0.3).tolist()
    [0, 1, 2]
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, len(rest), 3)
    rest = np.asarray(rest, dtype=np.float64)
    most = (np.linalg.norm(poses - rest[None], axis=2).max(axis=0) if len(poses)
            else np.zeros(len(rest)))
    ids = np.arange(len(rest)) if among is None else np.flatnonzero(among)
    k = min(len(ids), max(3, int(fraction * len(ids))))
    return np.sort(ids[np.argsort(most[ids], kind="stable")[:k]]).astype(np.int64)


@dataclass(frozen=True)
class Stabilised:
    """An expression with its head motion removed.

    Attributes
    ----------
    vertices : (n, 3) float64
        The expression moved onto the neutral's head pose.
    pose : Similarity
        Rigid (scale 1): expression → neutral.  ``pose.inverse()`` is the head
        motion of the expression.
    weights : (m,) float64
        Final weight of each rigid vertex in [0, 1] (low: moved by the expression).
    residual : float
        Weighted RMS distance of the rigid vertices after alignment (mesh units).
    """

    vertices: np.ndarray
    pose: Similarity
    weights: np.ndarray
    residual: float


def stabilise(expression, neutral, rigid, *, iterations: int = ROBUST_ITERATIONS,
              scale: float = ROBUST_SCALE) -> Stabilised:
    """The rigid motion that puts ``expression``'s skull back on ``neutral``'s.

    Parameters
    ----------
    expression, neutral : (n, 3) float
        The same topology (both wrapped from one template).
    rigid : (m,) int
        The skull-rigid vertex ids (m >= 3, not collinear).
    iterations : int
        Reweighting rounds (Umeyama without scale, Cauchy weights).
    scale : float
        Cauchy's constant, times the median residual.

    Returns
    -------
    Stabilised

    Examples
    --------
    A head turned by 10 degrees, its jaw (a tenth of the rigid set) dropped too:

    >>> rng = np.random.default_rng(0)
    >>> X = rng.normal(size=(200, 3))
    >>> c, s = np.cos(0.17), np.sin(0.17)
    >>> R = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]])
    >>> moved = X.copy(); moved[:20, 1] -= 2.0
    >>> out = stabilise(moved @ R.T + [1, 2, 3], X, np.arange(200))
    >>> bool(np.abs(out.vertices[20:] - X[20:]).max() < 1e-6)
    True
    """
    X = np.asarray(expression, dtype=np.float64)
    Y = np.asarray(neutral, dtype=np.float64)
    if X.shape != Y.shape or Y.ndim != 2 or Y.shape[1] != 3:
        # two topologies: rows would pair unrelated vertices
        raise ValueError(f"expression and neutral must be (n, 3), one topology, got "
                         f"{X.shape} and {Y.shape}")
    ids = as_vertex_ids(rigid, len(Y), "rigid", at_least=3)
    # (only the rigid rows must be finite: the others, NaN where unknown, just move)
    P, Q = as_points(X[ids], "expression's rigid vertices"), \
        as_points(Y[ids], "neutral's rigid vertices")
    w = np.ones(len(ids))
    pose = similarity_transform(P, Q, scale=False)
    for _ in range(iterations):
        r = np.linalg.norm(pose.apply(P) - Q, axis=1)
        # the floor keeps an exact fit (noise-free) from dividing by zero
        sigma = scale * max(float(np.median(r)), 1e-9 * (float(np.abs(Q).max()) + 1.0))
        w_new = 1.0 / (1.0 + (r / sigma) ** 2)
        if np.allclose(w_new, w, atol=1e-6):
            break
        w = w_new
        pose = similarity_transform(P, Q, weights=w, scale=False)
    r = np.linalg.norm(pose.apply(P) - Q, axis=1)
    return Stabilised(pose.apply(X), pose, w, float(np.sqrt((w * r ** 2).sum() / w.sum())))


def refine_pose(prediction, triangles, tree, pose: Similarity, vertices,
                motion) -> Similarity:
    """``pose`` (expression → neutral) refined against the expression's scan surface.

    Weighted point-to-plane rigid ICP of ``prediction`` onto the scan: each pair
    weighs 1 / ((:data:`REFINE_STILL_ERROR` * size)^2 + (:data:`REFINE_MOTION_ERROR`
    * ``motion``)^2), the inverse of how far off the prediction is likely to be at
    that vertex, ``size`` the prediction's bounding-box diagonal.  Pairs farther
    apart than :data:`REFINE_DISTANCE` of the size or whose normals differ by more
    than 60 degrees are left out.

    Parameters
    ----------
    prediction : (n, 3) float
        The expression as the rig predicts it, in the neutral's frame.
    triangles : (t, 3) int
        Of the template's topology.
    tree : ClosestPointTree
        The expression's scan.
    pose : Similarity
        The pose so far (:func:`stabilise`).
    vertices : (m,) int
        The vertices that take part (the ones both scans saw).
    motion : (n,) float
        How far the prediction moves each vertex from the neutral (its units, >= 0):
        ``norm(prediction - neutral, axis=1)``.  Zeros: every vertex trusted alike.

    Returns
    -------
    Similarity
        Rigid: expression → neutral.

    Examples
    --------
    The sample head (mm) turned by 3 degrees and moved 2 mm, its scan predicted
    exactly (nothing moves), is put back in place:

    >>> from facewrap.geometry import ClosestPointTree
    >>> from facewrap.sample import make_template
    >>> head = make_template(16).mesh
    >>> c, s = np.cos(0.05), np.sin(0.05)
    >>> turn = Similarity(np.array([[c, -s, 0], [s, c, 0], [0, 0, 1.0]]), [2.0, 0, 0], 1.0)
    >>> tree = ClosestPointTree(turn.apply(head.vertices), head.triangles)
    >>> found = refine_pose(head.vertices, head.triangles, tree, Similarity(),
    ...                     np.arange(head.n_vertices), np.zeros(head.n_vertices))
    >>> bool(np.abs(found.compose(turn).apply(head.vertices) - head.vertices).max() < 1e-3)
    True
    """
    X = np.asarray(prediction, dtype=np.float64)
    ids = np.asarray(vertices, dtype=np.int64)
    moved = np.asarray(motion, dtype=np.float64).reshape(-1)
    if moved.shape != (len(X),):
        raise ValueError(f"motion must be ({len(X)},), got {moved.shape}")
    # a few thousand points pin six degrees of freedom; more only cost queries
    ids = ids[::max(1, len(ids) // REFINE_POINTS)]
    size = float(np.linalg.norm(np.ptp(X, axis=0))) or 1.0
    # where the rig predicts the expression moves the skin, the person's own
    # expression likely differs from it (unevenly, one side more): such pairs would
    # pull the skull's pose along, so they count less the more the skin moves
    weights = 1.0 / ((REFINE_STILL_ERROR * size) ** 2
                     + (REFINE_MOTION_ERROR * moved[ids]) ** 2)
    return rigid_icp(X[ids], tree, vertex_normals(X, triangles)[ids], pose.inverse(),
                     trim=1.0, max_distance=REFINE_DISTANCE * size, tol=REFINE_TOLERANCE,
                     weights=weights).transform.inverse()
