"""Which template vertices the scan pulls, and which follow the skin.

A production head is more than the skin a scanner records: eyeballs, teeth,
gums, tongue, lashes and tear films are separate pieces, and the skin itself
turns into cavities no outside camera sees (nostrils, the mouth socket, the eye
sockets behind the eyeballs, ear canals).  Pulled onto a scan, those land on
the lips, the eyelids or the nose, and the teeth come through the lips.  So by
default only what a scanner can see is pulled (:func:`find_hidden_surface`,
from the template alone); everything else follows the skin by the deformation
model and the smooth extension of the projection.

Each template vertex gets one role (:data:`VERTEX_ROLES`):

``fitted``    pulled onto the scan;
``part``      a piece that is not skin (its own connected component);
``cavity``    skin no outside camera sees;
``excluded``  left out by the user (``exclude``, or outside ``fit_mask``);
``pinned``    kept where the landmark similarity puts it (the user's ``pinned``).

>>> VERTEX_ROLES.index("cavity") == CAVITY
True
"""

from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from facewrap.evaluate import VERTEX_ROLE_NAMES
from facewrap.geometry import boundary_edges, connected_components, face_areas
from facewrap.geometry.checks import as_vertex_mask
from facewrap.geometry.visibility import outside_views
from facewrap.io.cache import content_key, load_arrays, save_arrays

__all__ = ["VERTEX_ROLES", "FITTED", "PART", "CAVITY", "EXCLUDED", "PINNED",
           "HiddenSurface", "find_hidden_surface", "vertex_roles", "role_ranges",
           "landmarks_on_parts",
           "role_counts"]

#: role names, indexed by the codes of :func:`vertex_roles` (the one table, kept where
#: the measures that read a run's roles can see it)
VERTEX_ROLES = VERTEX_ROLE_NAMES
FITTED, PART, CAVITY, EXCLUDED, PINNED = range(len(VERTEX_ROLES))

#: a piece other than the largest is skin when it has at least this share of the
#: largest's area and most of it is seen (a face template split at the ears)
_SKIN_AREA_SHARE = 0.1
_SKIN_SEEN_SHARE = 0.5
#: a skin vertex is seen when this many of that many directions around the head see it
_VIEWS_NEEDED = 2
_VIEW_DIRECTIONS = 64
#: a piece other than the largest is skin only when most of it is seen from this many
#: directions: a skin piece is open to the outside (a face template split at the
#: ears: its vertices seen from 9-31 of the 64), a mouth bag behind the lips is
#: glimpsed through the opening (1-7; a face mask's bag was taken for skin and
#: pulled onto the lips, benchmarks/bench_other_heads.py)
_PIECE_VIEWS_NEEDED = 8

#: the on-disk entries of :func:`find_hidden_surface` (:mod:`facewrap.io.cache`); bump
#: the version whenever the result of the same template would change (the rules here
#: or the line casting of :func:`facewrap.geometry.visibility.outside_views`)
_CACHE_KIND = "hidden-surface"
_CACHE_VERSION = 4
#: the RMS radius of the skin in the frame the lines are cast in (see :func:`_normalised`)
_FRAME_RADIUS = 100.0


@dataclass(frozen=True)
class HiddenSurface:
    """What of a template a scanner cannot record (see :func:`find_hidden_surface`).

    Attributes
    ----------
    part : (n,) bool
        Vertices of pieces that are not skin (and vertices in no triangle).
    cavity : (n,) bool
        Skin vertices no outside camera sees.
    skin_pieces : int
        Connected pieces counted as skin.
    """
    part: np.ndarray
    cavity: np.ndarray
    skin_pieces: int

    @property
    def hidden(self) -> np.ndarray:
        """(n,) bool: ``part | cavity``."""
        return self.part | self.cavity


def _closed_pieces(T, labels, pieces: int) -> np.ndarray:
    """(pieces,) bool: pieces without a border edge (eyeballs: solid, they hide
    what lies behind them; an open tear film or lash strip does not)."""
    open_ = np.zeros(pieces, dtype=bool)
    E = boundary_edges(T)
    if len(E):
        open_[np.unique(labels[E[:, 0]])] = True
    return ~open_


def _normalised(V, T, weights) -> np.ndarray:
    """``V`` centred on the area centroid of the triangles ``weights`` (t,) weighs
    and scaled to their RMS radius :data:`_FRAME_RADIUS`.

    The visibility test casts lines in float32, and libigl's line casting offsets
    them by an absolute 1e-5: in this frame the same head gives the same cavities
    in any units and wherever it is placed.  (Not turned to its principal axes:
    the directions are a fixed set, so a head exported Z-up or facing the other way
    can still differ on vertices seen from about two directions; see
    ``benchmarks/bench_head_variants.py``.)

    >>> V = np.random.default_rng(0).normal(size=(50, 3)) * [3, 2, 1]
    >>> T = np.arange(48).reshape(16, 3)
    >>> a, b = _normalised(V, T, np.ones(16)), _normalised(7 * V + 40, T, np.ones(16))
    >>> bool(np.allclose(a, b))
    True
    """
    C = V[T].mean(axis=1)
    w = weights / max(float(weights.sum()), 1e-300)
    centre = w @ C
    radius = float(np.sqrt(w @ ((C - centre) ** 2).sum(axis=1))) or 1.0
    return (V - centre) * (_FRAME_RADIUS / radius)


def _seen(V, T, labels, candidate, closed, normals_out: bool,
          needed: int = _VIEWS_NEEDED) -> np.ndarray:
    """Outside visibility of the candidate pieces' vertices (from ``needed``
    directions), hidden by the candidates and the closed pieces."""
    vertices = np.flatnonzero(candidate[labels])
    occluders = (candidate | closed)[labels[T[:, 0]]]
    return outside_views(V, T if normals_out else T[:, ::-1], vertices=vertices,
                         occluders=occluders, needed=needed,
                         directions=_VIEW_DIRECTIONS)


def find_hidden_surface(V, T) -> HiddenSurface:
    """Find the pieces and cavities of a template that a scanner cannot see.

    The skin is the connected piece of largest area, and any other piece with at
    least a tenth of its area that is mostly seen from outside (from 8 of 64
    directions: a mouth bag glimpsed through the lips is not).  Every other piece
    is a *part*.  Skin vertices seen from fewer than two of 64 directions around the
    head (:func:`facewrap.geometry.visibility.outside_views`, hidden by the skin and
    by closed parts such as eyeballs) are *cavities*.  A template whose normals
    point inwards is read the other way round.

    Parameters
    ----------
    V : (n, 3) float64
    T : (t, 3) int64

    Returns
    -------
    HiddenSurface

    Examples
    --------
    The built-in sample head: its mouth and eyes are pieces of their own, or
    cavities:

    >>> from facewrap.sample import make_template
    >>> t = make_template().mesh
    >>> h = find_hidden_surface(t.vertices, t.triangles)
    >>> bool(h.hidden.mean() < 0.5)
    True
    """
    V = np.asarray(V, dtype=np.float64)
    T = np.asarray(T, dtype=np.int64)
    n = len(V)
    labels = connected_components(T, n)
    pieces = int(labels.max()) + 1 if n else 0
    area = np.bincount(labels[T[:, 0]], face_areas(V, T), minlength=pieces)
    used = np.zeros(n, dtype=bool)
    used[T.ravel()] = True
    if not used.any():
        return HiddenSurface(np.ones(n, dtype=bool), np.zeros(n, dtype=bool), 0)
    largest = int(np.argmax(area))
    candidate = area >= _SKIN_AREA_SHARE * area[largest]
    closed = _closed_pieces(T, labels, pieces) & ~candidate
    tri_area = face_areas(V, T)
    V = _normalised(V, T, np.where(candidate[labels[T[:, 0]]], tri_area, 0.0))
    outward = True
    seen = _seen(V, T, labels, candidate, closed, normals_out=True)
    cand_v = candidate[labels] & used
    if seen[cand_v].mean() < 0.25:       # normals point inwards: look the other way
        flipped = _seen(V, T, labels, candidate, closed, normals_out=False)
        if flipped[cand_v].sum() > seen[cand_v].sum():
            seen, outward = flipped, False
    skin = candidate.copy()
    if candidate.sum() > 1:   # is each other large piece skin, open to the outside?
        well_seen = _seen(V, T, labels, candidate, closed, outward, _PIECE_VIEWS_NEEDED)
        share = np.bincount(labels[well_seen], minlength=pieces) / np.maximum(
            np.bincount(labels, minlength=pieces), 1)
        skin &= share >= _SKIN_SEEN_SHARE
    skin[largest] = True
    skin_v = skin[labels] & used
    return HiddenSurface(part=~skin_v, cavity=skin_v & ~seen,
                         skin_pieces=int(skin.sum()))


def _hidden_surface_key(V, T) -> str:
    """The content key of a template's hidden surface: its arrays and every setting
    the result depends on."""
    return content_key(np.ascontiguousarray(V, np.float64),
                       np.ascontiguousarray(T, np.int64), _SKIN_AREA_SHARE,
                       _SKIN_SEEN_SHARE, _VIEWS_NEEDED, _VIEW_DIRECTIONS)


def _load_hidden_surface(key: str, n: int) -> HiddenSurface | None:
    """The stored hidden surface of ``key`` for ``n`` vertices, or None (absent,
    corrupt, or not of this template's size)."""
    found = load_arrays(_CACHE_KIND, key, ("part", "cavity", "skin_pieces"),
                        version=_CACHE_VERSION)
    if found is None:
        return None
    part, cavity, pieces = found["part"], found["cavity"], found["skin_pieces"]
    if not (part.shape == cavity.shape == (n,) and part.dtype == cavity.dtype == bool
            and pieces.shape == () and pieces.dtype.kind == "i"):
        return None
    return HiddenSurface(part, cavity, int(pieces))


class _HiddenSurfaceCache:
    """Hidden surfaces by template content: the last few in this process, and every
    one found before on disk (:mod:`facewrap.io.cache`; finding one casts ~10⁶ lines,
    0.2–0.9 s for a production head, and a batch, a sequence or the next
    ``facewrap wrap`` uses the same template again)."""

    def __init__(self, size: int = 4):
        self.size = size
        self._items: OrderedDict = OrderedDict()
        # wraps on threads share it: a lookup and another's eviction must not
        # interleave (found, then evicted: a KeyError); the search runs outside
        self._lock = threading.Lock()

    def __call__(self, V, T) -> HiddenSurface:
        key = _hidden_surface_key(V, T)
        with self._lock:
            if key in self._items:
                self._items.move_to_end(key)
                return self._items[key]
        found = _load_hidden_surface(key, len(V))
        if found is None:
            found = find_hidden_surface(V, T)
            save_arrays(_CACHE_KIND, key, {"part": found.part, "cavity": found.cavity,
                                           "skin_pieces": np.int64(found.skin_pieces)},
                        version=_CACHE_VERSION)
        with self._lock:
            self._items[key] = found
            while len(self._items) > self.size:
                self._items.popitem(last=False)
        return found

    def clear(self) -> None:
        """Forget the hidden surfaces held in this process (those on disk stay)."""
        with self._lock:
            self._items.clear()


#: the hidden surface of a template, from this process's last templates, the disk
#: cache, or found (and stored); ``cached_hidden_surface.clear()`` empties the first
cached_hidden_surface = _HiddenSurfaceCache()


def vertex_roles(n: int, hidden: HiddenSurface | None = None, *, exclude=None,
                 fit_mask=None, pinned=None) -> np.ndarray:
    """The role code (:data:`VERTEX_ROLES`) of each of ``n`` template vertices.

    Parameters
    ----------
    n : int
    hidden : HiddenSurface, optional
        Parts and cavities that follow (None: every vertex may be fitted).
    exclude : (n,) bool or int array, optional
        Vertices the user leaves out (parts and cavities among them keep those
        roles).
    fit_mask : (n,) bool or int array, optional
        The only vertices the user wants fitted (a template profile's fitting
        vertices, say): these are pulled even where ``hidden`` calls them a cavity,
        since the template's author knows better than a test on its shape; of the
        others, parts and cavities keep those roles and the rest are ``excluded``.
    pinned : (n,) bool or int array, optional
        Vertices kept where the similarity puts them (they win over every other role).

    Returns
    -------
    (n,) int8

    Raises
    ------
    ValueError
        Naming the argument, for ids outside ``[0, n)`` or masks of another length.

    Examples
    --------
    >>> vertex_roles(5, exclude=[1], fit_mask=[0, 1, 2, 3], pinned=[0]).tolist()
    [4, 3, 0, 0, 3]
    >>> h = HiddenSurface(np.array([0, 0, 0, 1, 1], bool), np.array([1, 0, 0, 0, 0], bool), 1)
    >>> vertex_roles(5, h, exclude=[0, 1, 4]).tolist()
    [2, 3, 0, 1, 1]
    >>> vertex_roles(5, h, fit_mask=[0, 1]).tolist()      # the mask wins over a cavity
    [0, 0, 3, 1, 1]
    """
    found = np.full(n, FITTED, dtype=np.int8)       # what the template's shape says
    if hidden is not None:
        found[hidden.cavity] = CAVITY
        found[hidden.part] = PART
    pulled = (found == FITTED if fit_mask is None
              else as_vertex_mask(fit_mask, n, "fit_mask"))
    pulled &= ~as_vertex_mask(exclude, n, "exclude", default=False)
    # what a vertex is wins over why it is left out: an excluded eyeball is still
    # a part, and follows as one
    roles = np.where(pulled, FITTED, np.where(found == FITTED, EXCLUDED, found))
    roles = roles.astype(np.int8)
    roles[as_vertex_mask(pinned, n, "pinned", default=False)] = PINNED
    return roles


def role_ranges(roles) -> dict:
    """Each role's vertices as half-open ``[start, stop)`` id ranges (for JSON).

    >>> role_ranges(np.array([0, 0, 1, 1, 0, 2], np.int8))
    {'fitted': [[0, 2], [4, 5]], 'part': [[2, 4]], 'cavity': [[5, 6]], 'excluded': [], 'pinned': []}
    """
    r = np.asarray(roles)
    change = np.flatnonzero(np.diff(r)) + 1
    starts = np.concatenate([[0], change]) if len(r) else np.zeros(0, np.int64)
    stops = np.concatenate([change, [len(r)]]) if len(r) else np.zeros(0, np.int64)
    out = {name: [] for name in VERTEX_ROLES}
    for a, b in zip(starts.tolist(), stops.tolist()):
        out[VERTEX_ROLES[int(r[a])]].append([a, b])
    return out


def role_counts(roles) -> dict:
    """Vertices per role name.

    >>> role_counts(np.array([0, 0, 2], np.int8))
    {'fitted': 2, 'part': 0, 'cavity': 1, 'excluded': 0, 'pinned': 0}
    """
    counts = np.bincount(np.asarray(roles, dtype=np.int64), minlength=len(VERTEX_ROLES))
    return {name: int(c) for name, c in zip(VERTEX_ROLES, counts)}


def landmarks_on_parts(landmarks, roles, triangles) -> list[str]:
    """A warning naming the template landmarks on a part (a piece that is not
    skin: an eyeball, the teeth), which a scanner does not see and the fit does not
    pull: ids pointing at the wrong piece of a template with parts pull its skin
    toward scan points that belong elsewhere, silently.

    Parameters
    ----------
    landmarks : Landmarks
        The template's, snapped onto it (vertices or surface points).
    roles : (n,) int8
        :func:`vertex_roles`.
    triangles : (t, 3) int
        The template's triangulation (surface points lie on its triangles).

    Returns
    -------
    list of str
        One line starting ``"template landmarks: "``, or none.

    Examples
    --------
    >>> from facewrap.landmarks import Landmarks
    >>> roles = np.array([FITTED, FITTED, PART], dtype=np.int8)
    >>> landmarks_on_parts(Landmarks.from_vertices([0, 1]), roles, [[0, 1, 2]])
    []
    >>> landmarks_on_parts(Landmarks.from_vertices([0, 2]), roles, [[0, 1, 2]])[0][:48]
    'template landmarks: 1 of 2 landmarks (1) lie on '
    """
    roles = np.asarray(roles)
    on_part = np.zeros(len(landmarks), dtype=bool)
    vertex, triangle = landmarks.vertex, landmarks.triangle
    on_part[vertex >= 0] = roles[vertex[vertex >= 0]] == PART
    corners = np.asarray(triangles, dtype=np.int64)[triangle[triangle >= 0]]
    on_part[triangle >= 0] = (roles[corners] == PART).all(axis=1)
    if not on_part.any():
        return []
    which = np.flatnonzero(on_part)
    labels = ", ".join(landmarks.label(int(i)) for i in which[:6])
    return [f"template landmarks: {len(which)} of {len(landmarks)} landmarks ({labels}"
            f"{', ...' if len(which) > 6 else ''}) lie on a part that is not skin (an "
            "eyeball, teeth: the scanner does not see it, the fit does not pull it); "
            "ids pointing at the wrong piece of the template?"]
