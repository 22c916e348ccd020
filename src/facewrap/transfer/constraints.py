"""What pins a gradient energy: marker pairs and the tether of loose components.

Deformation gradients say nothing about where a mesh is, only how it is shaped, so
every transfer energy needs something fixed: the markers (source vertex ↔ target
vertex pairs: hard constraints of the correspondence deformation, the anchor of
the transfer, the landmarks of the avatar), and, for connected components that
contain none of them (an eyeball, a loose tooth), a tiny pull toward their rest
positions (:data:`TETHER_WEIGHT`) so that they turn about their own centre.
"""

from __future__ import annotations

import numpy as np

from facewrap.errors import InputError
from facewrap.geometry import connected_components
from facewrap.geometry.checks import as_whole_indices
from facewrap.geometry.similarity import MIRROR_RATIO, mirror_fit, similarity_transform
from facewrap.wrapping.plausibility import landmark_spread, robust_similarity, swapped_pairs

__all__ = ["check_markers", "marker_placement", "untethered_vertices", "tether_weights",
           "TETHER_WEIGHT", "SIZE_RATIO"]

#: the markers put the target at more than this many times the source's size, or
#: less than its inverse: other units, most likely (cm to mm, 10, is common and fine;
#: Sumner's cat and lion, ICT's head and Onizuka's avatars stay within 2)
SIZE_RATIO = 20.0

#: Weight, relative to the mean diagonal of a normal matrix, of the tiny pull toward
#: rest positions that fixes the translation of components without any constraint.
TETHER_WEIGHT = 1e-8


def check_markers(markers, n_source: int, n_target: int, path=None
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Validate marker pairs against the two meshes.

    Parameters
    ----------
    markers : (src, tgt) pair of (m,) int arrays, or (m, 2) int
    n_source, n_target : int
        Vertex counts.
    path : str, optional
        Marker file to name in errors.

    Returns
    -------
    source, target : (m,) int64

    Raises
    ------
    InputError
        No markers, or an id out of range.
    """
    pair = isinstance(markers, tuple) and len(markers) == 2
    try:   # ids 2.5 are no vertex: refused, not cast to vertex 2
        ids = ([as_whole_indices(m, "markers").reshape(-1) for m in markers] if pair
               else as_whole_indices(markers, "markers"))
    except ValueError as exc:
        raise InputError(str(exc), path) from None
    if pair:
        src, tgt = ids
    elif ids.ndim != 2 or ids.shape[1] != 2:
        raise InputError(f"markers must be (m, 2) pairs, got shape {ids.shape}", path)
    else:
        src, tgt = ids[:, 0], ids[:, 1]
    if len(src) != len(tgt) or len(src) == 0:
        raise InputError("need at least one (source, target) marker pair", path)
    for name, ids, n in (("source", src, n_source), ("target", tgt, n_target)):
        bad = (ids < 0) | (ids >= n)
        if np.any(bad):
            k = int(np.argmax(bad))
            raise InputError(f"marker {k}: {name} vertex {int(ids[k])} out of range "
                             f"(the {name} mesh has {n} vertices)", path)
    return src, tgt


def marker_placement(source_points, target_points) -> list[str]:
    """Warnings about how the marker pairs place the target against the source.

    Marker pairs that a mirror image fits far better than the source itself
    (:func:`~facewrap.geometry.similarity.mirror_fit`) have left and right swapped,
    or one mesh is mirrored: the correspondence would pair a left eye with a right
    one.  A similarity that scales by more than :data:`SIZE_RATIO` up or down says
    the meshes are in other units.  Markers some of which fit far better with their
    targets exchanged (:func:`~facewrap.wrapping.plausibility.swapped_pairs`: the left
    eye's markers paired with the right eye's, the rest right) are said too; shapes
    as unlike as a horse and a camel, or a face and Mario's, exchange none.  Fewer
    than three pairs place nothing: the meshes are taken where they are.

    Parameters
    ----------
    source_points, target_points : (m, 3) float
        The markers on the source and on the target, paired.

    Returns
    -------
    list of str
        One line each, about the marker file (the caller names it).

    Examples
    --------
    >>> P = np.array([[1.0, 0, 0], [0, 1, 0], [0, 0, 1], [2, 1, 3], [-1, 2, 0.5]])
    >>> marker_placement(P, 3 * P + 1)
    []
    >>> marker_placement(P, P * [-1, 1, 1])[0][:39]
    'they match a mirror image of the source'
    >>> marker_placement(P, P / 1000)[0][:47]
    "they put the target at 0.001 times the source's"
    """
    X = np.asarray(source_points, dtype=np.float64)
    Y = np.asarray(target_points, dtype=np.float64)
    if len(X) < 3:
        return [f"only {len(X)} marker pair(s): the meshes are taken as placed (three or "
                "more align them), and little guides the correspondence"]
    out = []
    proper, mirrored = mirror_fit(X, Y)
    if mirrored < MIRROR_RATIO * proper:
        out.append(f"they match a mirror image of the source: residual {mirrored:.3g} "
                   f"mirrored against {proper:.3g} not, in target units (left and right "
                   "swapped in the marker file, or a mirrored mesh?)")
    else:
        out += _exchanged(X, Y)
    size = similarity_transform(X, Y).scale
    if not 1.0 / SIZE_RATIO <= size <= SIZE_RATIO:
        out.append(f"they put the target at {size:.3g} times the source's size (more than "
                   f"{SIZE_RATIO:g} times up or down): are both meshes in the same units?")
    return out


def _exchanged(X: np.ndarray, Y: np.ndarray) -> list[str]:
    """One line when some marker pairs fit far better with their targets exchanged
    (part of the file's left and right swapped), else none."""
    similarity, _ = robust_similarity(X, Y)
    pairs = swapped_pairs(similarity.apply(X), Y,
                          similarity.scale * landmark_spread(X))
    if not len(pairs):
        return []
    i, j = pairs[0]
    return [f"{len(np.unique(pairs))} markers fit far better with their targets "
            f"exchanged (markers {i} and {j}, 0-based, among them): left and right "
            "swapped for some of them, or the pairs out of order?"]


def untethered_vertices(T, n: int, fixed_ids) -> np.ndarray:
    """(n,) bool: vertices of connected components that contain no fixed vertex.

    Their translation is free in every gradient energy; callers add a tiny pull
    toward their rest positions (:data:`TETHER_WEIGHT`, so an eyeball turns about
    its own centre).

    Parameters
    ----------
    T : (t, 3) int64
    n : int
        Vertex count.
    fixed_ids : (m,) int
        Constrained vertices.

    Examples
    --------
    >>> untethered_vertices(np.array([[0, 1, 2], [3, 4, 5]]), 6, [1]).tolist()
    [False, False, False, True, True, True]
    """
    comp = connected_components(T, n)
    has = np.zeros(int(comp.max()) + 1 if n else 0, dtype=bool)
    has[comp[np.asarray(fixed_ids, dtype=np.int64)]] = True
    return ~has[comp]


def tether_weights(matrix, loose) -> np.ndarray:
    """The diagonal that tethers the ``loose`` unknowns of a normal matrix to their
    rest values: :data:`TETHER_WEIGHT` of its mean diagonal on each.

    Parameters
    ----------
    matrix : (m, m) scipy.sparse matrix
    loose : (m,) bool or float
        The unknowns to tether (:func:`untethered_vertices`, padded to ``m``).

    Returns
    -------
    (m,) float64

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> tether_weights(sp.diags([1.0, 3.0]), np.array([False, True])).tolist()
    [0.0, 2e-08]
    """
    return TETHER_WEIGHT * float(matrix.diagonal().mean()) * loose
