"""Production heads not made from ICT-FaceKit, built in code (for ``bench_other_heads``).

A studio's head is a skin with interior parts: eyeballs (a cornea shell over them),
rows of teeth with gums, a tongue, a mouth-socket bag behind the lips (its own piece,
or welded to the lips' inner loop), eye-occlusion shells hugging the eye rims, and
lashes: thin strips *outside* the skin.  This module dresses a bare skin with those
parts the way such heads have them, placed from the skin's own five landmarks
(inner eye corners, nose tip, mouth corners; iBUG 39, 42, 30, 48, 54) and from its
boundary loops (an eye or mouth opening is cut where the skin has none), and knows
which built vertex is which (the truth the roles are measured against).

Skins: MeshMonk's face template (a mask, eyes and mouth closed: openings cut),
Onizuka et al.'s generic head (eye openings, its own mouth socket joined to the
lips, a neck) and facewrap's built-in sample head (a mouth slit, its own
eyeballs).  Variants: the mouth bag welded to the lips or its own piece, quads or
every face triangulated, parts listed before the skin, mm or cm.  Everything is a
pure function of its arguments: no file is written.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facewrap.mesh import Mesh

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"
#: iBUG-68 indices of the five landmarks the parts are placed from
FIVE = (39, 42, 30, 48, 54)
#: labels of the built vertices; SKIN and SOCKET (a socket the skin had, or a mouth
#: bag welded to the lips) are one surface with the skin, the rest are pieces
SKIN, SOCKET, EYEBALL, CORNEA, TEETH, GUMS, TONGUE, BAG, OCCLUSION, LASHES = range(10)
LABELS = ("skin", "socket", "eyeball", "cornea", "teeth", "gums", "tongue", "bag",
          "occlusion", "lashes")


@dataclass
class Frame:
    """The head's axes from its five landmarks: x from the right eye to the left,
    y up (mouth to eyes), z forward (toward the nose tip); lengths in the skin's
    units."""
    eyes: np.ndarray          # (2, 3) eye centres estimated from the inner corners
    mouth: np.ndarray         # (3,) between the mouth corners
    axes: np.ndarray          # (3, 3) rows x, y, z
    eye_width: float
    mouth_width: float

    @classmethod
    def from_five(cls, P) -> "Frame":
        P = np.asarray(P, dtype=np.float64)
        x = P[1] - P[0]
        inner = float(np.linalg.norm(x))
        x /= inner
        mouth = 0.5 * (P[3] + P[4])
        y = 0.5 * (P[0] + P[1]) - mouth
        y -= (y @ x) * x
        y /= np.linalg.norm(y)
        z = np.cross(x, y)
        if (P[2] - 0.5 * (P[0] + P[1])) @ z < 0:      # the nose is in front
            z = -z
        eye_width = 0.9 * inner             # an eye is about as wide as the gap between
        eyes = np.array([P[0] - x * eye_width / 2, P[1] + x * eye_width / 2])
        return cls(eyes, mouth, np.array([x, y, z]), eye_width,
                   float(np.linalg.norm(P[4] - P[3])))

    def at(self, origin, local) -> np.ndarray:
        """Points given in this frame's axes (k, 3) about ``origin``."""
        return np.asarray(origin) + np.asarray(local) @ self.axes


@dataclass
class Built:
    """A head under construction: vertices, polygons, one label per vertex."""
    V: list = field(default_factory=list)
    F: list = field(default_factory=list)
    labels: list = field(default_factory=list)
    n: int = 0

    def add(self, V, F, label, shared=None) -> np.ndarray:
        """Add a piece (local ids in ``F``); ``shared`` maps its first local ids onto
        vertices already here (a bag welded to the lips).  Returns the new ids."""
        V = np.asarray(V, dtype=np.float64)
        k = 0 if shared is None else len(shared)
        ids = np.r_[np.asarray(shared, dtype=np.int64) if k else np.zeros(0, np.int64),
                    self.n + np.arange(len(V) - k)]
        self.V.append(V[k:])
        self.labels.append(np.full(len(V) - k, label))
        self.F += [ids[np.asarray(f)] for f in F]
        self.n += len(V) - k
        return ids

    def mesh(self) -> tuple[Mesh, np.ndarray]:
        return Mesh(np.vstack(self.V), list(self.F)), np.concatenate(self.labels)


def grid(rows: int, cols: int, closed: bool) -> list:
    """Quads of a rows × cols grid of points (row-major), closed along the rows."""
    F = []
    for i in range(rows - 1):
        for j in range(cols if closed else cols - 1):
            a, b = i * cols + j, i * cols + (j + 1) % cols
            F.append([a, b, b + cols, a + cols])
    return F


def _fan(ring, centre, first: bool) -> list:
    """Triangles closing ``ring`` at ``centre``, oriented as :func:`grid`'s quads
    when the ring is the grid's ``first`` row (else its last): one oriented surface,
    so that a signed distance or a visibility test reads one side of it."""
    F = [[ring[(j + 1) % len(ring)], ring[j], centre] for j in range(len(ring))]
    return F if first else [f[::-1] for f in F]


def sphere(centre, radii, frame: Frame, rings: int = 10, segments: int = 20):
    """A closed UV ellipsoid (quads, triangle fans at the poles), outward."""
    lat = np.linspace(-np.pi / 2, np.pi / 2, rings + 2)[1:-1]
    lon = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    local = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)
    local = np.vstack([local.reshape(-1, 3), [[0, 0, -1], [0, 0, 1]]]) * radii
    n = rings * segments
    F = grid(rings, segments, True)
    F += _fan(np.arange(segments), n, True) + _fan(np.arange(n - segments, n), n + 1, False)
    return frame.at(centre, local), F


def cap(centre, radius, frame: Frame, angle: float, rings: int = 5, segments: int = 20):
    """An open spherical cap about +z (a cornea), outward."""
    lat = np.linspace(np.pi / 2 - angle, np.pi / 2, rings + 1)[:-1]
    lon = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    la, lo = np.meshgrid(lat, lon, indexing="ij")
    local = np.stack([np.cos(la) * np.cos(lo), np.cos(la) * np.sin(lo), np.sin(la)], -1)
    local = np.vstack([local.reshape(-1, 3), [[0, 0, 1]]]) * radius
    n = rings * segments
    return frame.at(centre, local), grid(rings, segments, True) + _fan(
        np.arange(n - segments, n), n, False)


def arch(frame: Frame, depth: float, radius: float, span: float, low: float, high: float,
         thickness: float, steps: int = 16):
    """A closed curved box along a horizontal arc (a row of teeth, gums): the arc's
    front ``depth`` behind the mouth, ``radius`` its curvature, ``span`` its half
    angle, from ``low`` to ``high`` on the vertical axis."""
    t = np.linspace(-span, span, steps)
    section = [(0.0, low), (0.0, high), (thickness, high), (thickness, low)]
    P = []
    for a in t:
        for inset, h in section:
            r = radius - inset
            P.append([r * np.sin(a), h, r * np.cos(a) - radius - depth])
    P = np.array(P)
    ends = np.array([P[:4].mean(axis=0), P[-4:].mean(axis=0)])
    n = len(P)
    F = grid(steps, 4, True) + _fan(np.arange(4), n, True) + _fan(np.arange(n - 4, n), n + 1,
                                                                   False)
    F = [f[::-1] for f in F]
    return frame.at(frame.mouth, np.vstack([P, ends])), F


def outward(V, F, inside) -> list:
    """``F`` turned so that its normals point away from ``inside`` on the whole."""
    V = np.asarray(V)
    total = 0.0
    for f in F:
        p = V[np.asarray(f)]
        total += np.cross(p[1] - p[0], p[2] - p[0]) @ (p.mean(axis=0) - inside)
    return F if total >= 0 else [list(f)[::-1] for f in F]


def loop_near(mesh_V, F, point, within: float):
    """The boundary loop of the polygons ``F`` whose centroid is nearest ``point``, if
    within ``within``; else None."""
    import igl
    from facewrap.mesh import triangulate_polygons
    from facewrap.mesh import polygons_from_list
    T = triangulate_polygons(*polygons_from_list(F))[0] if F else np.zeros((0, 3), int)
    loops = [np.asarray(L) for L in igl.boundary_loop_all(np.asarray(T, dtype=np.int64))]
    if not loops:
        return None
    best = min(loops, key=lambda L: np.linalg.norm(mesh_V[L].mean(axis=0) - point))
    return best if np.linalg.norm(mesh_V[best].mean(axis=0) - point) < within else None


def cut_opening(V, F, frame: Frame, centre, half_width, half_height) -> list:
    """``F`` without the front polygons inside an ellipse about ``centre`` (an eye or
    mouth opening cut in a skin that has none)."""
    keep = []
    for f in F:
        d = (V[np.asarray(f)] - centre) @ frame.axes.T
        inside = ((d[:, 0] / half_width) ** 2 + (d[:, 1] / half_height) ** 2 < 1).all()
        if not (inside and (np.abs(d[:, 2]) < 2 * half_width).all()):
            keep.append(f)
    return keep


def compact(V, F):
    """(V, F) without the vertices no polygon uses, and the kept old ids."""
    used = np.unique(np.concatenate([np.asarray(f) for f in F]))
    new = np.full(len(V), -1)
    new[used] = np.arange(len(used))
    return np.asarray(V)[used], [new[np.asarray(f)] for f in F], used


def _eye_parts(b: Built, frame: Frame, eye, rim, tree) -> None:
    """An eyeball with a cornea, an occlusion band on its rim and upper lashes
    (lashes only where the skin has eyeballs of its own: ``rim`` None)."""
    ew, z, y = frame.eye_width, frame.axes[2], frame.axes[1]
    r = 0.42 * ew
    c = eye - z * 1.15 * r             # the front just behind the lids' level
    if rim is not None:
        _eyeball(b, frame, c, r, rim)
    _lashes(b, frame, eye, tree)


def _eyeball(b: Built, frame: Frame, c, r, rim) -> None:
    ew, z = frame.eye_width, frame.axes[2]
    b.add(*sphere(c, r, frame), EYEBALL)
    V, F = cap(c + z * 0.45 * r, 0.62 * r, frame, np.radians(55))
    b.add(V, F, CORNEA)
    P = b_vertices(b)
    ring0 = P[rim] + 0.03 * (P[rim].mean(axis=0) - P[rim]) - z * 0.01 * ew
    ring1 = P[rim] + 0.3 * (P[rim].mean(axis=0) - P[rim])
    ring1 = c + (ring1 - c) / np.linalg.norm(ring1 - c, axis=1, keepdims=True) * (r + 0.01 * ew)
    b.add(np.vstack([ring0, ring1]), grid(2, len(rim), True), OCCLUSION)


def _lashes(b: Built, frame: Frame, eye, tree) -> None:
    ew, y, z = frame.eye_width, frame.axes[1], frame.axes[2]
    # lashes: a strip rooted just off the upper lid's skin, reaching out and up
    a = np.linspace(np.radians(20), np.radians(160), 12)
    local = np.c_[0.45 * ew * np.cos(a), 0.2 * ew * np.sin(a), np.zeros(len(a))]
    hit = tree.query(frame.at(eye, local))
    root = hit.points + hit.normals * 0.02 * ew
    tip = root + z * 0.15 * ew + y * 0.15 * ew
    b.add(np.vstack([root, tip]), grid(2, len(a), False), LASHES)


def b_vertices(b: Built) -> np.ndarray:
    return np.vstack(b.V)


#: the mouth bag's rings behind the lips: share of the ellipse (against the lips'
#: loop), depth, half width and half height (of the mouth's width)
_BAG_RINGS = ((0.5, 0.06, 0.5, 0.35), (1.0, 0.12, 0.55, 0.4), (1.0, 0.35, 0.55, 0.42),
              (1.0, 0.65, 0.45, 0.35), (1.0, 0.85, 0.3, 0.2))


def _mouth_parts(b: Built, frame: Frame, bag: str, rim) -> None:
    """Teeth rows with gums, a tongue, and a mouth bag from the lips' inner loop
    (``bag``: "welded" shares the loop's vertices, "separate" is its own piece,
    "none" when the skin has its own socket)."""
    mw, x, y, z = frame.mouth_width, *frame.axes
    R = 0.6 * mw
    span = 0.45 * mw / R
    for lo, hi, label, depth, thick in ((0.01, 0.18, TEETH, 0.15, 0.14),
                                        (-0.18, -0.01, TEETH, 0.15, 0.14),
                                        (0.12, 0.26, GUMS, 0.17, 0.2),
                                        (-0.26, -0.12, GUMS, 0.17, 0.2)):
        b.add(*arch(frame, depth * mw, R, span, lo * mw, hi * mw, thick * mw), label)
    b.add(*sphere(frame.mouth - y * 0.1 * mw - z * 0.5 * mw, [0.28 * mw, 0.3 * mw, 0.07 * mw],
                  _tongue_frame(frame)), TONGUE)
    if bag == "none":
        return
    P = b_vertices(b)
    lips = P[rim]
    # angles along the lips' loop, in the mouth's frame (the parts are placed there)
    d = (lips - frame.mouth) @ frame.axes.T / mw
    theta = _loop_angles(d)
    rings = [lips if bag == "welded" else
             lips + 0.05 * (frame.mouth - lips) - z * 0.03 * mw]
    # rings behind the lips (:data:`_BAG_RINGS`): the first half the lips' loop, the
    # rest ellipses about the mouth; the bag balloons at once behind the lips, as a
    # mouth does, and holds the teeth, gums and tongue.  Depths count from the
    # loop's deepest point (the corners, round the face), so no ring comes out in
    # front of the lips
    back = min(float(d[:, 2].min()), 0.0)
    for share, depth, half_width, half_height in _BAG_RINGS:
        ellipse = np.c_[half_width * np.cos(theta), half_height * np.sin(theta),
                        np.full(len(theta), back)]
        local = (1 - share) * d + share * ellipse - [0.0, 0.0, depth]
        rings.append(frame.at(frame.mouth, local * mw))
    V = np.vstack(rings + [frame.at(frame.mouth, np.array([[0.0, 0.0, back - 0.95]]) * mw)])
    n = len(rim)
    F = grid(len(rings), n, True) + _fan(np.arange(len(V) - 1 - n, len(V) - 1), len(V) - 1,
                                              False)
    # the bag's normals face the mouth's inside, as the lips' skin it continues
    F = outward(V, F, frame.mouth - z * 0.45 * mw)
    F = [f[::-1] for f in F]
    if bag == "welded":
        b.add(V, _matching(b, rim, F), SOCKET, shared=rim)
    else:
        b.add(V, F, BAG)


def _loop_angles(d) -> np.ndarray:
    """An angle per vertex of a lip loop ``d`` (k, 3), in its own order and in the
    mouth's frame: 0 at the right corner, π/2 mid upper lip, π at the left corner,
    3π/2 mid lower lip, by length along the loop.  Not the angle about a centre: a
    slit curved like a smile has upper-lip vertices below the corners' midpoint, and
    rings laid out by such angles fold onto themselves."""
    k = len(d)
    right, left = int(np.argmax(d[:, 0])), int(np.argmin(d[:, 0]))
    step = np.linalg.norm(np.roll(d, -1, axis=0) - d, axis=1)
    theta = np.zeros(k)
    arcs = [np.arange(right, right + ((left - right) % k) + 1) % k,
            np.arange(left, left + ((right - left) % k) + 1) % k]
    upper = 0 if d[arcs[0], 1].mean() > d[arcs[1], 1].mean() else 1
    for which, arc in enumerate(arcs):
        length = np.r_[0.0, np.cumsum(step[arc[:-1]])]
        from_right = length if arc[0] == right else length[-1] - length
        fraction = from_right / max(length[-1], 1e-300)
        # the upper arc from the right corner: 0 → π; the lower: 2π → π
        theta[arc] = np.pi * fraction if which == upper else 2 * np.pi - np.pi * fraction
    return theta


def _tongue_frame(frame: Frame) -> Frame:
    """The frame turned a quarter about its x axis (the tongue's poles point
    forward/back), a rotation, so that the tongue's normals still point out."""
    x, y, z = frame.axes
    return Frame(frame.eyes, frame.mouth, np.array([x, z, -y]), frame.eye_width,
                 frame.mouth_width)


def _matching(b: Built, rim, F) -> list:
    """``F`` (local ids, its first ``len(rim)`` the rim) turned to agree with the
    skin's orientation along the rim (a welded piece is one oriented surface)."""
    directed = set()
    for f in b.F:
        f = list(f)
        directed |= {(f[i], f[(i + 1) % len(f)]) for i in range(len(f))}
    rim = list(rim)
    f = list(F[0])                   # its one edge along the rim, as it runs
    k = next(i for i in range(len(f)) if f[i] < len(rim) and f[(i + 1) % len(f)] < len(rim))
    edge = (rim[f[k]], rim[f[(k + 1) % len(f)]])
    return [list(f)[::-1] for f in F] if edge in directed else F


def dress(V, F, five, *, bag: str = "separate", eyes: bool = True,
          labels=None) -> tuple[Mesh, np.ndarray]:
    """A bare skin ``(V, F)`` with production parts, placed from its five landmark
    positions ``five`` (5, 3) (iBUG 39, 42, 30, 48, 54).  Openings are cut where the
    skin has none.  Returns the head (skin first) and one label per vertex."""
    from facewrap.geometry import ClosestPointTree
    frame = Frame.from_five(five)
    ew, mw = frame.eye_width, frame.mouth_width
    F = [np.asarray(f) for f in F]
    for eye in frame.eyes if eyes else ():
        if loop_near(V, F, eye, ew) is None:
            F = cut_opening(V, F, frame, eye, 0.42 * ew, 0.16 * ew)
    if bag != "none" and loop_near(V, F, frame.mouth, 0.3 * mw) is None:
        F = cut_opening(V, F, frame, frame.mouth, 0.4 * mw, 0.05 * mw)
    V, F, kept = compact(V, F)
    b = Built()
    b.add(V, F, SKIN)
    if labels is not None:            # parts the skin came with (the sample's eyeballs)
        b.labels[0] = np.asarray(labels)[kept]
    from facewrap.mesh import polygons_from_list, triangulate_polygons
    tree = ClosestPointTree(V, triangulate_polygons(*polygons_from_list(F))[0])
    for eye in frame.eyes:
        _eye_parts(b, frame, eye, loop_near(V, F, eye, ew) if eyes else None, tree)
    rim = loop_near(V, F, frame.mouth, 0.3 * mw) if bag != "none" else None
    _mouth_parts(b, frame, bag, rim)
    return b.mesh()


def _nearest_vertices(V, points) -> np.ndarray:
    from scipy.spatial import cKDTree
    return cKDTree(V).query(np.asarray(points, dtype=np.float64))[1]


def meshmonk_head(bag: str = "separate"):
    """MeshMonk's face template (mm, triangles, eyes and mouth closed): (head,
    labels, {iBUG index: vertex id})."""
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_landmarks
    folder = DATA / "scans" / "meshmonk"
    skin = read_mesh(folder / "Template.obj")
    points = read_landmarks(folder / "TemplateLandmarks.csv").points
    head, labels = dress(skin.vertices, skin.polygons(), points, bag=bag)
    ids = _nearest_vertices(head.vertices[labels == SKIN], points)
    return head, labels, dict(zip(FIVE, ids.tolist()))


def onizuka_head(bag: str = "none"):
    """Onizuka et al.'s generic head (mm, triangles, eye openings, its own mouth
    socket joined to the lips, a neck), with its 51 landmarks (iBUG 17-67)."""
    from facewrap.io import read_mesh
    skin = read_mesh(DATA / "onizuka2019" / "blendshapes" / "00m.obj")
    ids = np.loadtxt(DATA / "onizuka2019" / "landmarks" / "SOURCE" /
                     "FACIAL_LANDMARKS.txt", dtype=np.int64)
    ibug = dict(zip(range(17, 68), ids.tolist()))
    five = skin.vertices[[ibug[i] for i in FIVE]]
    head, labels = dress(skin.vertices, skin.polygons(), five, bag=bag)
    # the skin kept every vertex (its openings were there): ids unchanged
    return head, labels, ibug


def sample_head(bag: str = "welded"):
    """facewrap's built-in sample head (mm, quads, a mouth slit, its own eyeballs
    and lid shells), with its 68 landmarks."""
    from facewrap.sample import make_template
    t = make_template()
    m = t.mesh
    labels = np.full(m.n_vertices, SKIN)
    for name in ("eyeball_left", "eyeball_right"):
        labels[np.asarray(t.parts[name])] = EYEBALL
    ibug = dict(enumerate(np.asarray(t.landmarks.vertex).tolist()))
    head, out = dress(m.vertices, m.polygons(), m.vertices[[ibug[i] for i in FIVE]], bag=bag,
                      eyes=False, labels=labels)
    return head, out, ibug


def variant(head: Mesh, labels, ibug: dict, *, triangles: bool = False,
            parts_first: bool = False, scale: float = 1.0):
    """The head as another exporter writes it: every face triangulated, its parts'
    vertices and faces listed before the skin's, scaled (``0.1``: mm to cm)."""
    F = [head.triangles[i] for i in range(len(head.triangles))] if triangles \
        else head.polygons()
    labels = np.asarray(labels)
    order = np.arange(head.n_vertices)
    if parts_first:
        order = np.r_[np.flatnonzero(labels > SOCKET), np.flatnonzero(labels <= SOCKET)]
        new = np.empty_like(order)
        new[order] = np.arange(len(order))
        skin_face = [bool((labels[np.asarray(f)] <= SOCKET).all()) for f in F]
        F = [new[np.asarray(f)] for k in (False, True) for f, s in zip(F, skin_face)
             if s == k]
        ibug = {k: int(new[v]) for k, v in ibug.items()}
    return Mesh(scale * head.vertices[order], list(F)), labels[order], ibug
