"""Plausibility checks of a wrap's inputs: refuse what cannot fit, warn and fix the rest.

A wrap fits whatever it is given; these checks catch the inputs that make it fit
the wrong thing silently (issue 16):

* :func:`check_reflection` — the landmarks need a mirror image to match (a mirrored
  scan or landmark file): refused, unless ``WrapSettings.allow_mirrored``.
* :func:`check_landmark_residuals` — after a robust similarity, some landmark is
  farther from its target than the landmarks are from their centre, or two
  landmarks fit far better swapped: a wrong order, pairing or left/right swap.
  Expressions move landmarks too (an open jaw drops the chin and lips by up to
  two thirds of the spread on the built-in sample and the ICT cases), but move
  neighbours alike: no swap fits them better, and a stable landmark (eyes,
  brows, nose) that moves apart from its neighbours is named (:func:`local_misfit`).
* :func:`duplicated_landmarks` — two landmarks at the same point.
* :func:`unique_faces` — faces listed twice (same three vertices) are dropped;
  vertices at one position (a triangle soup) merged; fins on non-manifold edges
  (:func:`~facewrap.geometry.edge_runs.dangling_fins`) and spikes left out.
* :func:`opposed_normal_fraction` — the scan's faces turned away from the aligned
  template's (every face flipped, or pieces wound against each other): each
  piece is wound one way and turned to face the template for the fit.
* :func:`check_scale` — a similarity scale that suggests other units.

:func:`checked_scan` runs the scan's checks; :func:`check_landmarks` the
first three on the pairs.  Every check returns its warnings as one-line strings,
each starting with what it is about ("scan: ", "scan landmarks: ", "template
landmarks: "), so a job can put the file's name there.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry import (ClosestPointTree, closest_compatible_points, face_normals,
                               vertex_normals)
from facewrap.geometry.edge_runs import dangling_fins, edge_runs
from facewrap.geometry.duplicates import unique_faces, welded
from facewrap.geometry.normals import (SPIKE_LIMIT, coherent_orientation, disagreeing_edges,
                                       outwardness, spike_vertices)
from facewrap.geometry.similarity import (MIRROR_RATIO, Similarity, mirror_fit,
                                         similarity_transform)
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh

__all__ = ["MIRROR_RATIO", "RESIDUAL_LIMIT", "SCALE_RANGE", "OPPOSED_LIMIT", "OPPOSED_SAMPLE",
           "landmark_spread", "robust_similarity", "check_reflection", "swapped_pairs",
           "mispaired_landmarks", "LOCAL_LIMIT", "local_misfit", "check_landmark_residuals",
           "duplicated_landmarks", "check_landmarks", "unique_faces", "opposed_normal_fraction",
           "dangling_fins", "checked_scan", "check_scale", "UNSCALED_LIMIT",
           "check_unscaled_size", "LACY_LIMIT", "border_fraction", "INWARD_LIMIT"]

#: warn when a landmark stays farther than this (fraction of the landmarks' spread)
#: from its target after the robust similarity
RESIDUAL_LIMIT = 1.0
#: similarity scales outside this range suggest template and scan in other units
#: (cm to mm, 10, is common and fine)
SCALE_RANGE = (0.05, 20.0)
#: the scan's faces are taken as flipped when more than this fraction of the
#: template vertices near the scan face the opposite way
OPPOSED_LIMIT = 0.5
#: a template whose faces face into the head by more than this (see
#: :func:`~facewrap.geometry.normals.outwardness`: heads 0.3 to 0.8) is flipped
INWARD_LIMIT = -0.1
#: about this many template vertices (every k-th) estimate that fraction
OPPOSED_SAMPLE = 2000
#: with scaling off, warn when the landmarks put the scan this much larger or
#: smaller than the template (a relative size): the fit cannot make up for it
#: (the sample's scan 10 % larger: 0.37 -> 6.2 mm median error)
UNSCALED_LIMIT = 0.05
#: a scan with more than this fraction of its triangles on a border (one full of
#: holes, a triangle soup) keeps its border correspondences: rejecting them
#: would leave none (the sample's scan with half its triangles dropped)
LACY_LIMIT = 0.5
#: a stable landmark (eyes, brows, nose) moved apart from its neighbours by more than
#: this fraction of the spread is misplaced (james: 20 mm off, 0.33; eyes shut, 0.15)
LOCAL_LIMIT = 0.25
#: landmarks off by less than this (fraction of the spread) are never called swapped
SWAP_MINIMUM = 0.3
#: landmarks closer than this (fraction of the landmarks' spread) are the same point
SAME_POINT = 1e-6


def landmark_spread(points) -> float:
    """Root-mean-square distance of ``points`` (k, 3) from their centroid."""
    P = np.asarray(points, dtype=np.float64)
    return float(np.sqrt(((P - P.mean(axis=0)) ** 2).sum(axis=1).mean()))


def robust_similarity(sources, targets, weights=None, *, scale: bool = True,
                      iterations: int = 15) -> tuple[Similarity, np.ndarray]:
    """Similarity of ``sources`` onto ``targets`` that outliers do not drag.

    Iteratively reweighted Umeyama with Cauchy weights whose width shrinks from
    twice the sources' spread to a tenth of it (graduated, so the reweighting
    does not lock onto the first fit's tilt), then stays there: a few mis-paired
    landmarks keep their large residuals instead of spreading them over all.

    Parameters
    ----------
    sources, targets : (k, 3) float, k >= 3
    weights : (k,) float, optional
        Prior weights of the pairs (``alignment_weights``).
    scale : bool
        Estimate a uniform scale.
    iterations : int
        Reweightings (>= 4).

    Returns
    -------
    similarity : Similarity
    residuals : (k,) float64
        Distances left after it, in the sources' units, over their spread.

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> X = rng.normal(size=(20, 3))
    >>> Y = 3 * X + 1
    >>> Y[0] += 10
    >>> S, r = robust_similarity(X, Y)
    >>> round(S.scale, 3), bool(r[0] > 1), bool(r[1:].max() < 1e-3)
    (3.0, True, True)
    """
    X, Y = np.asarray(sources, np.float64), np.asarray(targets, np.float64)
    prior = np.ones(len(X)) if weights is None else np.asarray(weights, np.float64)
    spread = landmark_spread(X)
    widths = np.full(iterations, 0.1)
    widths[:-3] = np.geomspace(2.0, 0.1, max(iterations - 3, 0))
    w = prior
    for width in widths:
        similarity = similarity_transform(X, Y, weights=w, scale=scale)
        residuals = (np.linalg.norm(similarity.apply(X) - Y, axis=1)
                     / (similarity.scale * spread))
        w = prior / (1.0 + (residuals / width) ** 2)
    return similarity, residuals


def check_reflection(sources, targets, weights=None, *, scale: bool = True,
                     allow_mirrored: bool = False) -> list[str]:
    """Refuse landmark pairs that only a mirror image matches.

    The best proper similarity (det +1) is compared with the best improper one
    (the sources mirrored first); only when the mirrored fit leaves less than
    ``MIRROR_RATIO`` of the proper fit's residual is the input called mirrored.

    Parameters
    ----------
    sources, targets : (k, 3) float
    weights : (k,) float, optional
    scale : bool
    allow_mirrored : bool
        Warn instead of refusing.

    Returns
    -------
    list of str
        The warning (with ``allow_mirrored``), else empty.

    Raises
    ------
    ValueError
        For a mirrored input.
    """
    proper, improper = mirror_fit(sources, targets, weights, scale=scale)
    if not improper < MIRROR_RATIO * proper:
        return []
    message = (f"scan landmarks: they match a mirror image of the template's (residual "
               f"{improper:.3g} mirrored against {proper:.3g} not, in scan units): is the "
               "scan or its landmark file mirrored (left and right swapped)?")
    if not allow_mirrored:
        raise ValueError(message + " (set allow_mirrored to fit it anyway)")
    return [message]


def swapped_pairs(aligned, targets, spread: float) -> np.ndarray:
    """Pairs of landmarks that would fit far better with their targets swapped.

    Both must be off by more than ``SWAP_MINIMUM`` of ``spread`` and the swap must
    more than halve their summed distance: an expression moves neighbours alike
    (an open mouth drops both lips) and does not do that.

    Parameters
    ----------
    aligned : (k, 3) float
        Template landmarks under the similarity.
    targets : (k, 3) float
        Their scan partners.
    spread : float
        The aligned landmarks' spread.

    Returns
    -------
    (p, 2) int64
        Index pairs ``i < j``.
    """
    C = np.linalg.norm(aligned[:, None] - targets[None], axis=2) / spread
    own = np.diag(C)
    pair_own = own[:, None] + own[None]
    far = own > SWAP_MINIMUM
    swap = far[:, None] & far[None] & (C + C.T < 0.5 * pair_own)
    return np.argwhere(np.triu(swap, k=1)).astype(np.int64)


def mispaired_landmarks(sources, targets, weights=None, *, scale: bool = True
                        ) -> tuple[Similarity, np.ndarray, np.ndarray]:
    """The robust similarity, its residuals and the landmarks it calls mis-paired.

    Returns
    -------
    similarity : Similarity
    residuals : (k,) float64
        Over the sources' spread (:func:`robust_similarity`).
    flagged : (k,) bool
        Residual above ``RESIDUAL_LIMIT``, one of a :func:`swapped_pairs` pair, or
        (with weights that tell the stable landmarks) a stable landmark moved
        apart from its neighbours (:func:`local_misfit` over ``LOCAL_LIMIT``).
    """
    X, Y = np.asarray(sources, np.float64), np.asarray(targets, np.float64)
    similarity, residuals = robust_similarity(X, Y, weights, scale=scale)
    flagged = residuals > RESIDUAL_LIMIT
    spread = similarity.scale * landmark_spread(X)
    aligned = similarity.apply(X)
    flagged[swapped_pairs(aligned, Y, spread).ravel()] = True
    if weights is not None and np.ptp(weights) > 0:   # named: the stable ones known
        stable = np.asarray(weights) >= np.max(weights)
        flagged |= stable & (local_misfit(aligned, Y) > LOCAL_LIMIT * spread)
    return similarity, residuals, flagged


def local_misfit(aligned, targets, neighbours: int = 4) -> np.ndarray:
    """(k,) float64: how far each landmark's move (target minus aligned point)
    differs from the median move of its ``neighbours`` nearest landmarks.

    An expression moves neighbours alike; a landmark put in the wrong place alone.

    >>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 0, 0.]])
    >>> Y = X + [0, 0, 1.0]; Y[4, 1] += 3
    >>> local_misfit(X, Y, 2).round(2).tolist()
    [0.0, 0.0, 0.0, 0.0, 3.0]
    """
    A, Y = np.asarray(aligned, np.float64), np.asarray(targets, np.float64)
    D = np.linalg.norm(A[:, None] - A[None], axis=2)
    np.fill_diagonal(D, np.inf)
    near = np.argsort(D, axis=1, kind="stable")[:, :min(neighbours, len(A) - 1)]
    moves = Y - A
    return np.linalg.norm(moves - np.median(moves[near], axis=1), axis=1)


def check_landmark_residuals(sources, targets, landmarks: Landmarks, weights=None, *,
                             scale: bool = True, show: int = 3) -> list[str]:
    """Warn about landmarks that a robust similarity leaves far from their targets
    or that fit far better swapped (:func:`swapped_pairs`).

    Parameters
    ----------
    sources, targets : (k, 3) float
        The paired template and scan landmark positions.
    landmarks : Landmarks
        The template landmarks in pair order (their labels name the worst).
    weights : (k,) float, optional
    scale : bool
    show : int
        How many of the worst landmarks to name.

    Returns
    -------
    list of str
        One warning naming the worst landmarks, their residuals in the template's
        units and as a percentage of the landmarks' spread, and (when one is) the
        landmark whose place each target is nearest; else empty.
    """
    X, Y = np.asarray(sources, np.float64), np.asarray(targets, np.float64)
    similarity, residuals, flagged = mispaired_landmarks(X, Y, weights, scale=scale)
    bad = np.flatnonzero(flagged)
    if not len(bad):
        return []
    spread = landmark_spread(X)
    aligned = similarity.apply(X)
    # where each target lies on the aligned template: another landmark's place
    # points at a wrong order or a left/right swap
    nearest = np.argmin(np.linalg.norm(aligned[None, :] - Y[bad, None], axis=2), axis=1)
    worst = np.argsort(-residuals[bad], kind="stable")[:show]
    parts = []
    for j in worst:
        i = bad[j]
        text = (f"{landmarks.label(i)} off by {residuals[i] * spread:.3g} "
                f"({100 * residuals[i]:.0f} %)")
        if nearest[j] != i:
            text += f", nearest {landmarks.label(nearest[j])}'s place"
        parts.append(text)
    return [f"scan landmarks: {len(bad)} of {len(X)} landmarks are far from their template "
            f"partners after the similarity (template units; % of the landmarks' "
            f"spread, {spread:.3g}): {'; '.join(parts)}: wrong order, pairing or a left/right "
            "swap? The fit follows them: check the landmark files"]


#: iBUG-68 landmarks that meet when the mouth or an eye is shut (upper and lower
#: inner lip, upper and lower lid): at the same point they are no duplicate
MAY_MEET = frozenset(frozenset((IBUG68_NAMES[a], IBUG68_NAMES[b])) for a, b in (
    (61, 67), (62, 66), (63, 65), (37, 41), (38, 40), (43, 47), (44, 46)))


def _may_meet(landmarks: Landmarks, a: int, b: int) -> bool:
    """Whether landmarks ``a`` and ``b`` are a shut mouth's or eye's pair."""
    names = landmarks.names
    if names is None:
        names = IBUG68_NAMES if len(landmarks) == len(IBUG68_NAMES) else None
    return names is not None and frozenset((names[a], names[b])) in MAY_MEET


def duplicated_landmarks(positions, landmarks: Landmarks, what: str) -> list[str]:
    """Warn about landmarks at the same point (or the same vertex), but for the
    pairs a shut mouth or eye brings together (:data:`MAY_MEET`).

    Parameters
    ----------
    positions : (k, 3) float
        Where ``landmarks`` are.
    landmarks : Landmarks
    what : str
        "template" or "scan", for the message.

    Returns
    -------
    list of str
        One warning naming up to three coinciding pairs, or empty.
    """
    P = np.asarray(positions, np.float64)
    if len(P) < 2:
        return []
    tolerance = SAME_POINT * max(landmark_spread(P), 1e-300)
    d = np.linalg.norm(P[:, None] - P[None], axis=2)
    i, j = np.nonzero(np.triu(d <= tolerance, k=1))
    keep = [k for k in range(len(i)) if not _may_meet(landmarks, int(i[k]), int(j[k]))]
    i, j = i[keep], j[keep]
    if not len(i):
        return []
    pairs = ", ".join(f"{landmarks.label(a)} and {landmarks.label(b)}"
                      for a, b in zip(i[:3], j[:3]))
    return [f"{what} landmarks: {len(i)} pair(s) at the same point ({pairs}"
            f"{', ...' if len(i) > 3 else ''}): a landmark given twice?"]


def check_landmarks(template_landmarks: Landmarks, template_positions,
                    scan_landmarks: Landmarks, scan_positions, pairs, weights, *,
                    scale: bool = True, allow_mirrored: bool = False
                    ) -> tuple[list[str], Similarity]:
    """The landmark checks of a wrap: duplicates on either side, reflection,
    residuals.

    Parameters
    ----------
    template_landmarks, scan_landmarks : Landmarks
        The full sets.
    template_positions, scan_positions : (a, 3), (b, 3) float
        Where they are.
    pairs : ((l,) int, (l,) int)
        ``pair_landmarks`` of the two sets.
    weights : (l,) float
        The pairs' alignment weights.

    Returns
    -------
    warnings : list of str
    similarity : Similarity or None
        The robust template → scan similarity (:func:`robust_similarity`), which
        a few mis-paired landmarks do not tilt: the scan checks place the template
        by it.  None when half the landmarks or more are mis-paired or the input
        is mirrored (nothing places the template then).

    Raises
    ------
    ValueError
        For a mirrored input (see :func:`check_reflection`).
    """
    ia, ib = pairs
    notes = duplicated_landmarks(template_positions, template_landmarks, "template")
    notes += duplicated_landmarks(scan_positions, scan_landmarks, "scan")
    X, Y = template_positions[ia], scan_positions[ib]
    mirrored = check_reflection(X, Y, weights, scale=scale, allow_mirrored=allow_mirrored)
    if mirrored:  # a mirrored input leaves every landmark far: said already
        return notes + mirrored, None
    notes += check_landmark_residuals(X, Y, template_landmarks.subset(ia), weights,
                                      scale=scale)
    similarity, _, flagged = mispaired_landmarks(X, Y, weights, scale=scale)
    return notes, similarity if flagged.mean() < 0.5 else None


def _opposed_votes(vertices, triangles, normals, tree: ClosestPointTree,
                   max_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """The scan triangle closest to each point that counts (near, not on a
    border), and whether it faces against the point's normal."""
    near = closest_compatible_points(tree, vertices, max_distance=max_distance,
                                     reject_border=True)
    # normals of the triangles met only, not of the whole scan
    scan_normals = face_normals(tree.vertices, np.asarray(triangles)[near.triangles])
    return near.triangles, np.einsum("ij,ij->i", scan_normals,
                                     np.asarray(normals)[near.index]) < 0


def opposed_normal_fraction(vertices, triangles, normals, tree: ClosestPointTree,
                            max_distance: float) -> float:
    """Fraction of points whose closest scan triangle faces against their normal.

    ``vertices``, ``normals`` (n, 3): the aligned template's (or some of them);
    ``triangles`` (m, 3): the scan's, as in ``tree``; points farther from the scan
    than ``max_distance``, or closest to its border, do not count.  Returns a
    float in [0, 1]; NaN when no point counts.
    """
    opposed = _opposed_votes(vertices, triangles, normals, tree, max_distance)[1]
    return float(np.mean(opposed)) if len(opposed) else float("nan")


def _tidied_triangles(V, T, tree: ClosestPointTree | None = None
                      ) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """The scan's vertices welded and its triangles without repeats, fins and
    spikes (see :func:`checked_scan`), with a warning for each change; the scan's
    ``tree`` lends its edge runs and normals if nothing was welded or dropped."""
    notes = []
    W, T = welded(V, T)
    if len(W) < len(V):
        notes.append(f"scan: {len(V) - len(W)} of {len(V)} vertices repeat another's "
                     "position (a triangle soup, or seams split apart); merged for the "
                     "fit")
    keep = unique_faces(T)
    if not keep.all():
        notes.append(f"scan: {int((~keep).sum())} of {len(T)} triangles repeat another's "
                     "vertices (duplicated faces); the fit uses each once")
        T = T[keep]
    same = tree is not None and len(W) == len(V) and bool(keep.all())
    runs = tree.edge_runs if same else edge_runs(T)
    fins = dangling_fins(T, runs)
    own = tree.vertex_normals if same and tree.own_normals else None
    spikes = spike_vertices(W, T, runs=runs, normals=own)
    drop = fins | spikes[T].any(axis=1)
    if fins.any():
        notes.append(f"scan: {int(fins.sum())} triangle(s) hang off the surface by one "
                     "edge (non-manifold fins); left out of the fit")
    if spikes.any():
        notes.append(f"scan: {int(spikes.sum())} vertices stand far out of the surface "
                     f"around them (spikes, more than {SPIKE_LIMIT:g} times their "
                     "neighbours' spread); their triangles are left out of the fit")
    return W, T[~drop] if drop.any() else T, notes


def _oriented(T, tree: ClosestPointTree, aligned, normals, max_distance,
              template_flipped: bool = False) -> tuple[np.ndarray, list[str]]:
    """The scan's triangles wound one way per piece and facing the template
    (see :func:`checked_scan`); a scan turned only to face a flipped template is
    not said to be flipped (the template is)."""
    if disagreeing_edges(T, tree.edge_runs) == 0:
        opposed = (float("nan") if aligned is None else
                   opposed_normal_fraction(aligned, T, normals, tree, max_distance))
        if not opposed > OPPOSED_LIMIT:
            return T, []
        if template_flipped:
            return T[:, ::-1], []
        return T[:, ::-1], [f"scan: {100 * opposed:.0f} % of the scan under the template "
                            "faces inward (its faces are flipped); the fit uses them "
                            "reversed"]
    flip, patch, bad = coherent_orientation(T, tree.edge_runs)
    U = np.where(flip[:, None], T[:, ::-1], T)
    # each patch faces the template by the vote of the template points over it;
    # a patch no point reaches keeps the winding most of its triangles had
    votes = np.bincount(patch, minlength=len(T)).astype(np.float64)
    against = np.bincount(patch, flip.astype(np.float64), minlength=len(T))
    turn = against > 0.5 * votes
    if aligned is not None:
        met, opposed = _opposed_votes(aligned, U, normals,
                                      ClosestPointTree(tree.vertices, U), max_distance)
        counted = np.bincount(patch[met], minlength=len(T))
        opposite = np.bincount(patch[met], opposed.astype(np.float64), minlength=len(T))
        turn = np.where(counted > 0, opposite > 0.5 * counted, turn)
    U = np.where((flip ^ turn[patch])[:, None], T[:, ::-1], T)
    changed = int(np.sum(flip ^ turn[patch]))
    return U, [f"scan: its triangles are wound inconsistently ({bad} edges between "
               f"triangles wound against each other); the fit turns {changed} of "
               f"{len(T)} so each piece faces one way, outward"]


def checked_scan(scan: Mesh, tree: ClosestPointTree | None, aligned_template,
                 template_triangles, mask=None) -> tuple[Mesh, ClosestPointTree, list[str]]:
    """The scan as the fit should see it, with its tree and a warning per change.

    Vertices at one position merged (a soup is a surface again); duplicated
    faces dropped; fins (:func:`~facewrap.geometry.edge_runs.dangling_fins`) and
    the triangles of spikes (:func:`~facewrap.geometry.normals.spike_vertices`)
    left out; each piece wound
    one way (:func:`~facewrap.geometry.normals.coherent_orientation`), facing the
    aligned template.

    Parameters
    ----------
    scan : Mesh
    tree : ClosestPointTree or None
        The scan's tree, if built (rebuilt only when the scan changes).
    aligned_template : (n, 3) float or None
        Template vertices under the landmark similarity; None when nothing places
        the template (mis-paired landmarks): which way the scan faces is not
        checked (pieces wound against each other still agree after).
    template_triangles : (t, 3) int
    mask : (n,) bool, optional
        Template vertices that take part (not excluded ones).

    Returns
    -------
    scan : Mesh
        ``scan`` itself when nothing was changed, else a triangle mesh of its
        (welded) vertices (UVs dropped: the fit needs none).
    tree : ClosestPointTree
    warnings : list of str
    """
    V, T, notes = _tidied_triangles(scan.vertices, scan.triangles, tree)
    if notes or tree is None:
        tree = ClosestPointTree(V, T)
    aligned = normals = None
    template_flipped = False
    if aligned_template is not None:
        aligned = np.asarray(aligned_template, np.float64)
        normals = vertex_normals(aligned, template_triangles)
        # a template wound inward makes a good scan look flipped: name the template
        template_flipped = outwardness(aligned, template_triangles) < INWARD_LIMIT
        if mask is not None:
            aligned, normals = aligned[mask], normals[mask]
        # a fraction: every k-th of the vertices estimates it as well as all of them
        # (to a percent at 2,000 points; the test is 50 %), for a fifth of the queries
        step = max(1, len(aligned) // OPPOSED_SAMPLE)
        aligned, normals = aligned[::step], normals[::step]
    U, turned = _oriented(T, tree, aligned, normals, 0.05 * scan.scale(),
                          template_flipped)
    if template_flipped:
        notes.append("template: its faces are flipped (they face into the head); the "
                     "scan is matched to them, and the result keeps the template's "
                     "winding")
    if turned:
        notes += turned
        T, tree = U, ClosestPointTree(V, U)
    if notes:
        scan = Mesh(V, T)
    return scan, tree, notes


def check_scale(scale: float) -> list[str]:
    """A warning when the template is scaled by more than ``SCALE_RANGE`` allows."""
    lo, hi = SCALE_RANGE
    if lo <= scale <= hi:
        return []
    return [f"scan: the template was scaled by {scale:.4g} to fit the scan (more than "
            f"{1 / lo:g} times up or down): are both in the same units?"]


def check_unscaled_size(sources, targets, weights=None) -> list[str]:
    """A warning when scaling is off but the landmarks say the sizes differ.

    Parameters
    ----------
    sources, targets : (k, 3) float
        Paired template and scan landmark positions.
    weights : (k,) float, optional

    Returns
    -------
    list of str
        One line when the robust similarity with a free scale scales by more than
        ``UNSCALED_LIMIT`` (relative) either way, else none.

    Examples
    --------
    >>> X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1.]])
    >>> check_unscaled_size(X, 1.02 * X), len(check_unscaled_size(X, 1.2 * X))
    ([], 1)
    """
    free = robust_similarity(np.asarray(sources, np.float64), np.asarray(targets, np.float64),
                             weights, scale=True)[0].scale
    if abs(np.log(free)) <= np.log1p(UNSCALED_LIMIT):
        return []
    return [f"scan landmarks: they put the scan at {free:.3g} times the template's size, "
            "but scaling is off (scale = false): the fit cannot make up the difference "
            "(other units, or another head size?)"]


def border_fraction(tree: ClosestPointTree) -> float:
    """Fraction of the scan's triangles with a corner on a border (see
    :attr:`~facewrap.geometry.ClosestPointTree.boundary_triangles`)."""
    return float(np.mean(tree.boundary_triangles))
