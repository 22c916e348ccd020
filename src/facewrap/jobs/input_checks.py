"""Checks of a wrap's inputs that are legal but odd, for :mod:`facewrap.jobs.wrap_job`.

Each returns one line per oddity (counts; nothing is changed), or refuses what
cannot be fitted with an :class:`~facewrap.errors.InputError` naming the file:
:func:`survey_mesh` (repeated vertices, zero-area triangles, non-manifold edges,
loose pieces), :func:`weld_duplicates` (exact duplicate scan vertices merged, so
seams split by an exporter do not read as holes), :func:`check_landmark_spread`,
:func:`check_distinct_landmarks` (two template landmarks at one place),
:func:`unpaired_landmarks` (named landmarks left out of the pairing),
:func:`nothing_to_fit` (every vertex excluded or pinned), :func:`oversized_shapes`
(blendshapes larger than the head), :func:`check_model_settings` (a setting the
shapes or the model would drop), :func:`check_uv_layouts` (texture coordinates
that nothing can be baked from or into),
:func:`check_landmarks_on_scan`; :func:`check_scan` runs the scan's checks of a wrap
(and of each frame of a track) in one call.  Scans of one person or one sequence
(a rig's neutral and expressions, a track's frames) are checked together:
:func:`repeated_scans` (one scan given twice), :func:`check_scan_sizes` (a scan in
other units than the first), :func:`check_not_template` (the template among them)
and, after a track's fit, :func:`frames_of_another_head`.
"""

from __future__ import annotations

import hashlib

import numpy as np
import scipy.sparse as sp
from scipy.sparse import csgraph

from facewrap.errors import InputError
from facewrap.geometry.arrays import column_bounds
from facewrap.geometry.edge_runs import EdgeRuns, edge_runs, non_manifold_edge_count
from facewrap.geometry.duplicates import any_duplicate_positions, duplicate_rows
from facewrap.geometry import ClosestPointTree
from facewrap.geometry.normals import trusted_face_areas
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.texture.udim import triangle_tiles
from facewrap.units import UNKNOWN, format_distance, head_size, resolve_units
from facewrap.wrapping.models import model_spec

__all__ = ["doubled_areas", "check_surface", "survey_mesh", "weld_duplicates", "check_landmark_spread",
           "check_distinct_landmarks", "check_template_landmarks", "unpaired_landmarks",
           "nothing_to_fit", "oversized_shapes", "check_landmarks_on_scan", "check_scan",
           "check_uv_layouts", "check_model_settings", "repeated_scans",
           "check_scan_sizes", "check_not_template", "frames_of_another_head",
           "SCAN_SIZE_RATIO", "TRACKED_HEAD_SHAPE"]

#: :func:`frames_of_another_head`: a tracked frame's skull this far off frame 0's
#: surface (fraction of the face's size; :func:`~facewrap.rig.stabilise.unlike_neutral`)
#: is of another head.  Looser than a rig's: a frame without landmarks of its own
#: follows the fit before it and drifts (the sample: one person's frames 0.06 and
#: 0.10 %, another person's 0.31 %)
TRACKED_HEAD_SHAPE = 0.002

#: scans of one head (a rig's, a sequence's) whose sizes differ by more than this
#: factor are not in one unit: a scan cropped to the face and one with the neck
#: and shoulders differ by well under it, inches and centimetres by 2.54
SCAN_SIZE_RATIO = 2.0


def doubled_areas(mesh) -> np.ndarray:
    """(t,) float64: twice the area of each of ``mesh.triangles``."""
    return 2.0 * trusted_face_areas(mesh.vertices, mesh.triangles)


def check_surface(mesh: Mesh, path, what: str, purpose: str) -> np.ndarray:
    """Refuse a mesh that has no surface: no faces (a point cloud), coordinates
    whose size overflows, or every triangle of zero area.

    Parameters
    ----------
    mesh : Mesh
    path : path
        Named in the error.
    what : str
        What the mesh is ("scan", "result"), the error's subject.
    purpose : str
        Why it needs a surface, said after "has no faces; ".

    Returns
    -------
    (t,) float64
        Twice the area of each triangle (:func:`doubled_areas`), for the checks that
        follow.

    Raises
    ------
    InputError
        Naming the file.
    """
    if len(mesh.triangles) == 0:
        raise InputError(f"has no faces; {purpose}", path)
    size = mesh.scale()
    if not np.isfinite(size):
        raise InputError("coordinates are too large (the bounding box overflows)", path)
    area2 = doubled_areas(mesh)
    # relative to the size: a scan in metres has areas a million times a scan in mm's
    if size == 0 or not np.any(area2 > 1e-12 * size * size):
        raise InputError(f"{what} is degenerate: every triangle has zero area", path)
    return area2


def survey_mesh(mesh, path, what: str, pieces: bool = True, *,
                areas: np.ndarray | None = None, runs: EdgeRuns | None = None
                ) -> list[str]:
    """One line per oddity of a mesh's triangles (counts; nothing is changed).

    ``pieces``: also report disconnected pieces (not for templates, whose eyes and
    teeth are separate pieces by design).  ``areas`` (:func:`doubled_areas`) and
    ``runs`` (:func:`~facewrap.geometry.edge_runs.edge_runs`) of the mesh when the
    caller has them (a scan's :class:`~facewrap.geometry.ClosestPointTree` does).
    Every step is a sort or linear: one sort of the edges for the non-manifold
    count; the pieces from two edges of each triangle.
    """
    out = []
    T = mesh.triangles
    n = mesh.n_vertices
    stray = n - len(mesh.surface_vertex_ids)
    if stray and stray < n:
        out.append(f"{path}: {what} has {stray} vertices no face uses (left out of its "
                   "size and units)")
    repeated = (T[:, 0] == T[:, 1]) | (T[:, 1] == T[:, 2]) | (T[:, 0] == T[:, 2])
    if repeated.any():
        out.append(f"{path}: {what} has {int(repeated.sum())} triangle(s) with a "
                   "repeated vertex")
    area2 = doubled_areas(mesh) if areas is None else areas
    scale = mesh.scale()
    flat = (area2 <= 1e-12 * scale * scale) & ~repeated
    if flat.any():
        out.append(f"{path}: {what} has {int(flat.sum())} zero-area triangle(s)")
    # an edge's triangles are a run; runs longer than two are non-manifold (the
    # triangles with a repeated vertex do not count)
    nm = non_manifold_edge_count(edge_runs(T) if runs is None else runs,
                                 ~repeated if repeated.any() else None)
    if nm:
        out.append(f"{path}: {what} has {nm} non-manifold edge(s) (shared by more "
                   "than two triangles)")
    if not pieces:
        return out
    # each edge once when the runs name them (half the links of a million-triangle
    # scan: 30 ms saved), else two edges of each triangle, which join its three
    # corners without a sort (a triangle with a repeated vertex still joins the others)
    if runs is not None:
        a, b = runs.ends.T
    else:
        a, b = T[:, :2].T.reshape(-1), T[:, 1:].T.reshape(-1)
    links = sp.csr_matrix((np.ones(len(a), np.int8), (a, b)), shape=(n, n))
    labels = csgraph.connected_components(links, directed=False)[1]
    used = np.zeros(n, dtype=bool)
    used[T.ravel()] = True
    sizes = np.bincount(labels[used])
    sizes = sizes[sizes > 0]
    if len(sizes) > 1:
        out.append(f"{path}: {what} has {len(sizes)} disconnected pieces (the largest "
                   f"has {int(sizes.max())} of {int(used.sum())} vertices)")
    return out


def weld_duplicates(mesh, landmarks, path):
    """Merge exactly coincident scan vertices; returns (mesh, landmarks, warning).

    Triangle count and order, UVs and normals per corner are kept, so triangle ids
    of surface landmarks and texture baking are unaffected.
    """
    if not any_duplicate_positions(mesh.vertices):
        return mesh, landmarks, None
    first, inverse = duplicate_rows(mesh.vertices)
    dupes = mesh.n_vertices - len(first)
    offsets = mesh.face_offsets
    kw = mesh.corner_attributes()
    if mesh.vertex_colors is not None:
        kw.update(vertex_colors=mesh.vertex_colors[first])
    welded = Mesh(mesh.vertices[first], (offsets, inverse[mesh.face_indices]),
                  face_materials=mesh.face_materials, materials=mesh.materials,
                  face_groups=mesh.face_groups, groups=mesh.groups, mtllib=mesh.mtllib,
                  texture=mesh.texture, **kw)
    if np.any(landmarks.vertex >= 0):
        v = np.where(landmarks.vertex >= 0, inverse[np.maximum(landmarks.vertex, 0)], -1)
        landmarks = Landmarks(v, landmarks.triangle, landmarks.barycentric,
                              landmarks.points, landmarks.names)
    return welded, landmarks, (f"{path}: scan has {dupes} duplicate vertices (same "
                               "position); merged for fitting")


def check_landmark_spread(points: np.ndarray, path) -> None:
    """Landmarks must span a plane at least, or the alignment is undetermined."""
    P = points - points.mean(axis=0)
    s = np.linalg.svd(P, compute_uv=False)
    if len(points) < 3 or s[0] == 0 or s[1] <= 1e-6 * s[0]:
        raise InputError("landmarks are all at one point or on one line; the "
                         "alignment needs at least three landmarks not in a line", path)


def check_distinct_landmarks(points: np.ndarray, names, path) -> None:
    """Two template landmarks at one position (a vertex id listed twice) are refused.

    The landmark warp needs one place per landmark: two at one point would pull it
    toward two scan points at once (the RBF system is singular).  A scan landmark
    given twice is only odd, and the wrap's plausibility checks name it.
    """
    first, inverse = duplicate_rows(points)
    owner = first[inverse]          # the first landmark at each one's position
    twice = np.flatnonzero(owner != np.arange(len(points)))
    if len(twice):
        i, j = int(owner[twice[0]]), int(twice[0])
        label = (lambda k: str(k) if names is None else f"{k} ({names[k]})")
        raise InputError(f"landmarks {label(i)} and {label(j)} are at the same position "
                         f"({len(twice)} such pair(s)): each landmark needs a place of "
                         "its own (a vertex id listed twice?)", path)


def check_template_landmarks(template, landmarks: Landmarks, path) -> None:
    """The template landmarks of a wrap or a track, checked as one: they span a plane
    and each has a place of its own.

    Parameters
    ----------
    template : Mesh
    landmarks : Landmarks
        On ``template``.
    path : path
        Where they come from (their file, a template profile or the template when
        detected), named in errors.

    Raises
    ------
    InputError
        From :func:`check_landmark_spread` or :func:`check_distinct_landmarks`.
    """
    points = landmarks.positions(template)
    check_landmark_spread(points, path)
    check_distinct_landmarks(points, landmarks.names, path)


def unpaired_landmarks(template: Landmarks, scan: Landmarks, template_path,
                       scan_path) -> list[str]:
    """One line naming the landmarks left out of a pairing by name, if any.

    Named sets pair by the names they share and the rest is dropped: legal (a scan
    may carry a subset), but a typo or another naming scheme drops landmarks the
    user meant to fit, so the count and an example are said.
    """
    if template.names is None or scan.names is None:
        return []
    common = set(template.names) & set(scan.names)
    out = []
    for lm, path, what in ((scan, scan_path, "scan"), (template, template_path,
                                                        "template")):
        alone = [n for n in lm.names if n not in common]
        if alone and common:
            out.append(f"{path}: {len(alone)} of {len(lm)} {what} landmarks pair with no "
                       f"landmark of the same name and are left out (e.g. {alone[0]!r}); "
                       f"the fit uses the {len(common)} shared names")
    return out


def nothing_to_fit(n_vertices: int, held: dict) -> list[str]:
    """One line when the vertex lists of ``held`` (path → (k,) int ids: excluded,
    pinned) together cover every template vertex: nothing is pulled onto the scan,
    and the result is the landmark alignment alone, which looks like a fit."""
    covered = np.zeros(n_vertices, dtype=bool)
    for ids in held.values():
        covered[ids] = True
    if not covered.all():
        return []
    files = " and ".join(str(p) for p in held)
    return [f"{files}: every template vertex is excluded or pinned; nothing is pulled "
            "onto the scan (the result only follows the landmarks)"]


def oversized_shapes(shapes: dict, template: Mesh, path, what: str = "template"
                     ) -> list[str]:
    """One line naming the blendshapes that move a vertex farther than half the
    template's size: no expression does, a shape in other units (or of another
    head, mirrored, moved or turned) does, and the fit would quietly give it no
    weight, or a transfer carry it over (``what``: the neutral's name in the line)."""
    size = template.scale()
    moves = {name: _farthest_move(V, template.vertices) for name, V in shapes.items()}
    big = [name for name, m in moves.items() if m > 0.5 * size]
    # a shape shrunk to a point (metres against millimetres) moves no vertex far
    used = template.surface_vertex_ids      # the vertices template.scale() measures
    every = len(used) == template.n_vertices
    ratio = {name: _diagonal(V if every else V[used]) / size
             for name, V in shapes.items()} if size > 0 else {}
    other = [name for name, r in ratio.items() if not 0.8 <= r <= 1.25 and name not in big]
    out = []
    if big:
        out.append(f"{path}: {len(big)} shape(s) move a vertex farther than half the "
                   f"{what}'s size (e.g. {big[0]!r}, {moves[big[0]] / size:.3g} times its "
                   f"size): other units, mirrored or moved, or not this {what}'s shapes?")
    if other:
        out.append(f"{path}: {len(other)} shape(s) are not of the {what}'s size (e.g. "
                   f"{other[0]!r}, {ratio[other[0]]:.3g} times it): in other units?")
    return out


def check_model_settings(settings, shapes: dict | None, path) -> None:
    """Refuse settings the model or the shapes would drop silently: ICP ``stages``
    for a model fitted in closed form (rbf), or ``pca_components`` without
    blendshapes, with a model that fits no blend weights, or asking for more
    components than there are shapes (the basis has one axis per shape).

    Parameters
    ----------
    settings : WrapSettings or None
    shapes : dict of str to (n, 3) float, or None
        The blendshapes read from ``path``.
    path : path or None
        The blendshapes folder, named in the error.
    """
    if settings is None:
        return
    spec = model_spec(settings.model, has_blendshapes=bool(shapes))
    if settings.stages is not None and spec.schedule is None:
        raise InputError(f"stages ([[wrap.stages]]) are given but the model "
                         f"{spec.name!r} is fitted in closed form, without ICP stages: "
                         "they would have no effect")
    k = settings.pca_components
    if k is None:
        return
    what = f"pca_components (--pca-components) is {k}"
    if not shapes:
        raise InputError(f"{what} but no blendshapes are given: components of which "
                         "shapes?")
    if k > len(shapes):
        raise InputError(f"{what} but the folder holds {len(shapes)} shape(s); use at "
                         f"most {len(shapes)}", path)
    if not spec.needs_blendshapes:
        raise InputError(f"{what} but the model {spec.name!r} fits no blendshapes: "
                         "it would have no effect (use the blendshape or hybrid model)")


def _diagonal(V) -> float:
    """The bounding-box diagonal of ``V`` (n, 3), by columns (see
    :func:`~facewrap.geometry.arrays.column_bounds`)."""
    lo, hi = column_bounds(V)
    return float(np.linalg.norm(hi - lo))


def _farthest_move(V, R) -> float:
    """The longest of the moves ``V − R`` (n, 3): a row-wise dot product, several
    times faster than ``np.linalg.norm(..., axis=1)`` on 53 shapes per wrap."""
    d = np.asarray(V, dtype=np.float64) - R
    return float(np.sqrt(np.einsum("ij,ij->i", d, d).max(initial=0.0)))


def check_landmarks_on_scan(points: np.ndarray, names, tree, scale: float, path,
                            unit: str = UNKNOWN) -> list[str]:
    """Scan landmarks should lie on (or near) the scan surface; distances are said
    in ``unit`` (the scan's, see :func:`~facewrap.units.resolve_units`)."""
    d = tree.query(points).distances
    far = d > 0.05 * scale
    if np.median(d) > 0.1 * scale:
        raise InputError(f"landmarks are not on the scan: median distance to its "
                         f"surface {format_distance(np.median(d), unit)}, scan size "
                         f"{format_distance(scale, unit)} (wrong landmark file, or "
                         "other units?)", path)
    if far.any():
        worst = int(np.argmax(d))
        label = names[worst] if names is not None else str(worst)
        return [f"{path}: {int(far.sum())} landmark(s) lie off the scan surface "
                f"(farthest: {label}, {format_distance(d[worst], unit)} away; scan size "
                f"{format_distance(scale, unit)})"]
    return []


def check_scan(scan: Mesh, landmarks: Landmarks | None, path, landmarks_path=None, *,
               survey: bool = True, units: str = "auto"):
    """Every check of a scan (and its landmarks) before it is fitted.

    Parameters
    ----------
    scan : Mesh
    landmarks : Landmarks or None
        The scan's landmarks; None (a track frame that follows the fit of the one
        before) leaves out the landmark checks.
    path, landmarks_path : path
        The files named in errors and warnings.
    survey : bool
        Also merge duplicate vertices and survey the mesh (:func:`survey_mesh`);
        off, only the refusals and the landmark warnings (a track, whose frames
        are fitted as they are).
    units : str
        The unit choice (``"auto"`` infers it from the scan's size): distances in
        the messages carry it.

    Returns
    -------
    scan : Mesh
        Duplicate vertices merged (:func:`weld_duplicates`).
    landmarks : Landmarks or None
        Their vertex ids moved with the merge.
    tree : ClosestPointTree or None
        Of the scan, built for the landmark check (None without landmarks).
    notes : list of str
        One warning line per legal-but-odd feature.

    Raises
    ------
    InputError
        Naming the file: no faces, coordinates whose size overflows, every
        triangle of zero area, landmarks in a line or off the surface.
    """
    area2 = check_surface(scan, path, "scan", "a scan must be a surface")
    size = scan.scale()
    notes = []
    if survey and landmarks is not None:
        scan, landmarks, welded = weld_duplicates(scan, landmarks, path)
        notes += [welded] if welded else []
    # the tree's edge runs serve the survey too (one sort of a million triangles'
    # edges); welding kept the triangles, and so their areas, as they were
    tree = None if landmarks is None else ClosestPointTree(scan.vertices, scan.triangles)
    if survey:
        notes += survey_mesh(scan, path, "scan", areas=area2,
                             runs=None if tree is None else tree.edge_runs)
        if len(scan.triangles) < 100:
            notes.append(f"{path}: scan has only {len(scan.triangles)} triangle(s)")
    if landmarks is None:
        return scan, None, None, notes
    points = landmarks.positions(scan)
    check_landmark_spread(points, landmarks_path or path)
    notes += check_landmarks_on_scan(points, landmarks.names, tree, size,
                                     landmarks_path or path,
                                     resolve_units(units, scan.surface_points())[0])
    return scan, landmarks, tree, notes


def check_uv_layouts(template: Mesh, scan: Mesh, template_path, scan_path) -> list[str]:
    """The texture coordinates of a bake: the template's lie in UDIM tiles, the
    scan's in its image.

    A template triangle whose UVs lie outside every tile (``u < 0`` or ``u >= 10``,
    ``v < 0`` or ``v >= 100``: a layout moved or scaled by mistake) is baked into no
    image; a scan's UVs beyond ``[0, 1]`` (a UDIM tile other than 1001, a layout
    meant to repeat) read the image's border texels, one smeared colour.

    Returns
    -------
    list of str
        A line per layout partly outside.

    Raises
    ------
    InputError
        When either mesh has no texture coordinates or a layout of zero area, or no
        template triangle lies in a tile (the baked images would be empty).
    """
    if scan.triangle_uvs is None:
        raise InputError("the scan has no texture coordinates to bake from", scan_path)
    if template.triangle_uvs is None:
        raise InputError("the template has no UV layout to bake into", template_path)
    # a layout collapsed to points or lines: the template's baked into nothing (an
    # all-black image), the scan's read as one texel (one flat colour), silently
    for mesh, path, what in ((template, template_path, "nothing would be baked"),
                             (scan, scan_path, "the baked texture would be one colour")):
        uv = mesh.uvs[mesh.triangle_uvs]
        e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
        if not np.any(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) > 1e-12):
            raise InputError("every triangle's texture coordinates have zero area (the UV "
                             f"layout is collapsed to points or lines): {what}", path)
    outside = int(np.count_nonzero(triangle_tiles(template) < 0))
    total = len(template.triangles)
    if outside == total:
        raise InputError("no triangle's texture coordinates lie in a UDIM tile (u in "
                         "[0, 10), v in [0, 100)): nothing would be baked", template_path)
    notes = []
    if outside:
        notes.append(f"{template_path}: {outside} of {total} template triangles have "
                     "texture coordinates outside the UDIM tiles (u in [0, 10), v in "
                     "[0, 100)): they are left out of the baked texture")
    centroids = scan.uvs[scan.triangle_uvs].mean(axis=1)
    with np.errstate(invalid="ignore"):
        off = int(np.count_nonzero(np.any((centroids < 0) | (centroids > 1), axis=1)))
    if off:
        notes.append(f"{scan_path}: {off} of {len(centroids)} scan triangles have texture "
                     "coordinates outside [0, 1] (beyond the image): they take the "
                     "colour of its border")
    return notes


def repeated_scans(meshes, labels) -> list[str]:
    """One line per scan that is, vertex for vertex and face for face, an earlier
    one of ``meshes`` (a rig's neutral given again as an expression, a sequence's
    frame written twice): it tells the fit nothing the first did not.

    ``labels`` name the scans in the lines (a file, ``"frame 2 (f2.obj)"``).
    """
    seen: dict[bytes, str] = {}
    out = []
    for mesh, label in zip(meshes, labels):
        key = _content_key(mesh)
        if key in seen:
            out.append(f"{label}: the same scan as {seen[key]} (every vertex and face "
                       "alike)")
        else:
            seen[key] = label
    return out


def _content_key(mesh: Mesh) -> bytes:
    """A digest of ``mesh``'s vertices and triangles: equal for copies of one mesh."""
    digest = hashlib.blake2b(digest_size=16)
    for a in (mesh.vertices, mesh.triangles):
        digest.update(np.ascontiguousarray(a).tobytes())
    return digest.digest()


def check_not_template(template: Mesh, meshes, paths) -> None:
    """Refuse a scan (a track's frame, a rig's expression) that is the template
    itself, vertex for vertex: the template kept in the scans' folder is taken for a
    frame, and its fit is of another head than the person's.

    Raises
    ------
    InputError
        Naming the scan's file.
    """
    key = _content_key(template)
    for mesh, path in zip(meshes, paths):
        if _content_key(mesh) == key:
            raise InputError("is the template itself, not a scan (the template kept "
                             "among the scans?)", path)


def check_scan_sizes(meshes, paths, first: str = "the first scan") -> None:
    """Refuse a scan of one head (a rig's expression, a sequence's frame) whose size
    is more than :data:`SCAN_SIZE_RATIO` times that of ``meshes[0]`` or less than
    its inverse: another unit (a scan in metres among millimetres), which the wrap
    would fit as a head ten or a thousand times the size, or not at all.

    Raises
    ------
    InputError
        Naming the scan's file (``paths[k]``), its size against ``first``'s.
    """
    ref = head_size(meshes[0].surface_points())
    for mesh, path in zip(meshes[1:], paths[1:]):
        size = head_size(mesh.surface_points())
        ratio = size / ref if ref > 0 else 1.0
        if not 1.0 / SCAN_SIZE_RATIO <= ratio <= SCAN_SIZE_RATIO:
            raise InputError(f"the head is {ratio:.3g} times the size of the one in "
                             f"{first} (another unit? the scans of one head must share "
                             "one)", path)


def frames_of_another_head(frames, template: Mesh, blendshapes: dict | None) -> list:
    """``(frame, line)`` for each frame of a track whose fit, stabilised on the
    skull (the template's vertices its shapes move least), is of another head than
    frame 0's: a scan of another person in the sequence, fitted as if it were an
    expression (:func:`~facewrap.rig.stabilise.unlike_neutral`; the fits unchanged).

    Without shapes nothing tells the skull from the face: no line.
    """
    if not blendshapes or len(frames) < 2:
        return []
    # deferred: a wrap, which reads its inputs here too, does not load the rig
    from facewrap.rig.stabilise import least_moving, stabilise, unlike_neutral
    first = frames[0]
    seen0 = (np.ones(template.n_vertices, dtype=bool) if first.projection is None
             else first.projection.projected)
    rigid = least_moving(np.stack([np.asarray(v, np.float64) for v in blendshapes.values()]),
                         template.vertices, among=seen0)
    out = []
    for i, f in enumerate(frames[1:], start=1):
        seen = seen0 if f.projection is None else seen0 & f.projection.projected
        ids = rigid[seen[rigid]]
        moved = stabilise(f.vertices, first.vertices, ids if len(ids) >= 3 else rigid)
        note = unlike_neutral(moved.vertices, first.vertices, first.mesh.triangles, rigid,
                              seen, reference="frame 0's", still=True,
                              limit=TRACKED_HEAD_SHAPE)
        out += [(i, note)] if note else []
    return out
