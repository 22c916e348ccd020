"""Re-baking a scan's texture into the template's UV layout (SPEC §1.4).

Every texel of the template's UV layout (:func:`rasterize_uv`) is followed to its
3-D point on the fitted template, to the closest scan point, to the scan's UV and
into the scan image (:func:`bake_texture`).  Every subject then has one image in
one shared layout, padded across UV seams so mip-mapping shows no seams.

Image convention (OBJ): ``v = 0`` is the bottom row of an image; texel
``(row, col)`` of an ``(H, W)`` image has its centre at
``u = (col + 0.5) / W``, ``v = 1 - (row + 0.5) / H``.  Images are ``uint8`` arrays
``(H, W, 3)`` (RGB) or ``(H, W, 4)`` (RGBA), read and written by
:mod:`facewrap.io.images`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.arrays import blocks_by_budget, stable_sort_order
from facewrap.geometry.scanline import triangle_row_spans
from facewrap.io.images import as_image, to_uint8
from facewrap.mesh import Mesh
from facewrap.texture.udim import FIRST_TILE, tile_origin, triangle_tiles
from facewrap.texture.uvs import checked_uv_mesh, trusted_scan_uvs

__all__ = ["BLOCK_TEXELS", "MAX_SIDE", "SEEN", "UVRaster", "rasterize_uv", "sample_image",
           "BakeResult", "scan_visibility", "bake_texture", "pad_texture",
           "interpolate_images"]

# A texel centre counts as inside a UV triangle when its barycentric coordinates are
# all >= -_INSIDE_TOL: texel centres exactly on a shared edge then belong to both
# triangles despite rounding (no cracks), and one of them is chosen as the owner.
_INSIDE_TOL = 1e-7
#: Texels rasterised and baked at once: a band of rows holds about this many, and so
#: does a block of candidates.  It bounds the memory a bake needs beyond its image
#: (~170 MB, where a whole 1024^2 layout at once took 550 MB and a 4096^2 one 6 GB),
#: and the closest-point queries run faster in such bands (cache) than all at once.
BLOCK_TEXELS = 1 << 18
#: the largest side of a baked image, pixels (a bake keeps ~64 bytes a texel: 16 GiB)
MAX_SIDE = 16384


def _rgb(image: np.ndarray) -> np.ndarray:
    """(H, W, 3) view of a checked (H, W, C) image: grey repeated, alpha dropped."""
    if image.shape[2] == 1:
        return np.repeat(image, 3, axis=2)
    return image[:, :, :3]


def _size(size) -> tuple[int, int]:
    """``size`` as ``(H, W)``: an int (square) or a pair of positive ints, each at
    most :data:`MAX_SIDE` (a size of 10**6 failed as a bare ``MemoryError``)."""
    pair = (size, size) if np.ndim(size) == 0 else tuple(np.asarray(size).tolist())
    if (len(pair) != 2 or any(isinstance(s, (bool, np.bool_)) or
                              not isinstance(s, (int, np.integer)) or s <= 0
                              for s in pair)):
        raise ValueError(f"size must be a positive int or a pair (H, W) of them, "
                         f"got {size!r}")
    if max(pair) > MAX_SIDE:
        raise ValueError(f"size must be at most {MAX_SIDE} pixels a side, got {size!r}")
    return int(pair[0]), int(pair[1])


def _non_negative(x, name: str) -> float:
    x = float(x)
    if not x >= 0:  # also rejects NaN
        raise ValueError(f"{name} must be >= 0, got {x}")
    return x


@dataclass(frozen=True, eq=False)
class UVRaster:
    """Which triangle covers each texel of a UV layout, and where in it.

    Attributes
    ----------
    pixels : (p, 2) int64
        ``(row, col)`` of each covered texel, in row-major order.
    triangles : (p,) int64
        Triangle of ``mesh.triangles`` owning the texel centre.
    barycentric : (p, 3) float64
        Coordinates of the texel centre in that triangle's UV triangle (non-negative,
        summing to 1); the same coordinates give the 3-D point on the surface.
    mask : (H, W) bool
        Covered texels.
    """

    pixels: np.ndarray
    triangles: np.ndarray
    barycentric: np.ndarray
    mask: np.ndarray

    def __len__(self) -> int:
        """Number of covered texels."""
        return self.pixels.shape[0]


def rasterize_uv(mesh: Mesh, size, tile: int = FIRST_TILE, only=None) -> UVRaster:
    """Rasterise one UV tile of a mesh's layout: the triangle under every texel centre.

    A texel belongs to a triangle when its centre lies inside the triangle's UV
    triangle (with a tolerance of 1e-7 in barycentric coordinates, so centres on a
    shared edge are never lost).  Where triangles overlap in UV space (shared edges,
    overlapping islands) the triangle with the centre deepest inside (largest
    smallest barycentric coordinate) owns the texel, the lower index on a tie.  Only
    the triangles of ``tile`` (by their UV centroid, :func:`~.udim.triangle_tiles`)
    are rasterised, in the tile's own [0, 1] square; what of them lies outside it
    is clipped away, not wrapped.

    Vectorised: the texels each row of a triangle can reach
    (:func:`~facewrap.geometry.scanline.triangle_row_spans`) are enumerated at once
    (``np.repeat`` / ``cumsum``), band of rows by band of rows.

    Parameters
    ----------
    mesh : Mesh
        With texture coordinates; ``mesh.triangles`` are rasterised with their
        per-corner UVs.
    size : int or (H, W) int
        Image size; an int means square.
    tile : int
        UDIM tile (1001 is the unit square, see :mod:`facewrap.texture.udim`).
    only : (t,) bool, optional
        Rasterise these triangles of ``mesh.triangles`` only (of those in ``tile``).

    Returns
    -------
    UVRaster
        Covered texels in row-major order, with their triangle and coordinates.

    Examples
    --------
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]],
    ...             uvs=[[0, 0], [1, 0], [1, 1], [0, 1.]], face_uvs=[[0, 1, 2, 3]])
    >>> r = rasterize_uv(quad, 4)
    >>> len(r), bool(r.mask.all())
    (16, True)
    >>> r.pixels[0].tolist(), int(r.triangles[0])   # top-left texel: u small, v big
    ([0, 0], 1)
    """
    mesh = checked_uv_mesh(mesh, "mesh")
    H, W = _size(size)
    keys, tris, barys = [], [], []
    for _, key, tri, bary in _raster_bands(mesh, H, W, tile, _checked_only(mesh, only)):
        keys.append(key)
        tris.append(tri)
        barys.append(bary)
    key = np.concatenate(keys) if keys else np.zeros(0, np.int64)
    mask = np.zeros(H * W, dtype=bool)
    mask[key] = True
    return UVRaster(pixels=np.stack([key // W, key % W], axis=1),
                    triangles=np.concatenate(tris) if tris else np.zeros(0, np.int64),
                    barycentric=np.concatenate(barys) if barys else np.zeros((0, 3)),
                    mask=mask.reshape(H, W))


def _checked_only(mesh: Mesh, only):
    """``only`` (triangles to rasterise) checked: None or a bool array per triangle."""
    if only is None:
        return None
    only = np.asarray(only)
    if only.dtype != bool or only.shape != (len(mesh.triangles),):
        raise ValueError(f"only must be a bool array of shape "
                         f"({len(mesh.triangles)},), got {only.dtype} {only.shape}")
    return only


def _raster_bands(mesh: Mesh, H: int, W: int, tile: int, only):
    """:func:`rasterize_uv` of a checked mesh, band of rows by band of rows.

    Each band holds about :data:`BLOCK_TEXELS` texels, so that a 4K or 8K layout
    is rasterised (and baked) in pieces of bounded memory.

    Yields
    ------
    stop : int
        The row after the band's last.
    key : (p,) int64
        ``row * W + col`` of each covered texel of the band, increasing.
    triangle : (p,) int64
    barycentric : (p, 3) float64
    """
    u0, v0 = tile_origin(tile)
    skip = triangle_tiles(mesh) != tile
    if only is not None:
        skip |= ~only
    # corners in pixel coordinates: x = column, y = row, texel centres at integers
    uv = mesh.uvs[mesh.triangle_uvs]                        # (t, 3, 2)
    x = (uv[:, :, 0] - u0) * W - 0.5
    y = (1.0 - (uv[:, :, 1] - v0)) * H - 0.5
    e1x, e1y = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0]
    e2x, e2y = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    det = e1x * e2y - e1y * e2x
    margin = 1e-6
    c0 = np.clip(np.ceil(x.min(axis=1) - margin), 0, W).astype(np.int64)
    c1 = np.clip(np.floor(x.max(axis=1) + margin), -1, W - 1).astype(np.int64)
    r0 = np.clip(np.ceil(y.min(axis=1) - margin), 0, H).astype(np.int64)
    r1 = np.clip(np.floor(y.max(axis=1) + margin), -1, H - 1).astype(np.int64)
    asked = np.flatnonzero((det != 0) & ~skip)      # with area in UV space, asked for
    # only the columns each row of a triangle can reach (a box holds 2-3 times more)
    spans = triangle_row_spans(x[asked], y[asked], (c0[asked], c1[asked], r0[asked],
                                                    r1[asked]), grow=_INSIDE_TOL)
    band = max(1, BLOCK_TEXELS // W)
    by_row, rows = stable_sort_order(spans.rows)
    bounds = np.searchsorted(rows, np.arange(0, H + band, band))
    for top, lo, hi in zip(range(0, H, band), bounds[:-1], bounds[1:]):
        if lo == hi:
            continue
        runs = np.sort(by_row[lo:hi])       # back in triangle order: the owner rule's
        keys, tris, barys, scores = [], [], [], []
        for sel in blocks_by_budget(spans.widths[runs], BLOCK_TEXELS):
            tri, row, col = spans.pixels_of(runs[sel])
            tri = asked[tri]
            dx, dy = col - x[tri, 0], row - y[tri, 0]
            inv = 1.0 / det[tri]
            l1 = (dx * e2y[tri] - dy * e2x[tri]) * inv
            l2 = (e1x[tri] * dy - e1y[tri] * dx) * inv
            l0 = 1.0 - l1 - l2
            score = np.minimum(np.minimum(l0, l1), l2)
            inside = score >= -_INSIDE_TOL
            keys.append((row[inside] - top) * W + col[inside])
            tris.append(tri[inside])
            barys.append(np.stack([l0[inside], l1[inside], l2[inside]], axis=1))
            scores.append(score[inside])
        key, tri = np.concatenate(keys), np.concatenate(tris)
        bary, score = np.concatenate(barys), np.concatenate(scores)
        # one owner per texel: the candidate deepest inside, then the lowest triangle
        # (candidates come in triangle order); scatter-reductions, no sort
        n = min(band, H - top) * W
        best = np.full(n, -np.inf)
        np.maximum.at(best, key, score)
        win = np.flatnonzero(score == best[key])
        owner = np.full(n, len(key), dtype=np.int64)
        np.minimum.at(owner, key[win], win)
        own = owner[owner < len(key)]                      # row-major texel order
        bary = bary[own]
        np.maximum(bary, 0.0, out=bary)
        bary /= bary.sum(axis=1, keepdims=True)
        yield min(top + band, H), key[own] + top * W, tri[own], bary


def sample_image(image, uvs) -> np.ndarray:
    """Bilinear samples of an image at texture coordinates (OBJ convention).

    Texel ``(row, col)`` is centred at ``u = (col + 0.5) / W``,
    ``v = 1 - (row + 0.5) / H``; coordinates beyond the outer texel centres take the
    border texels (clamp, no wrap).

    Parameters
    ----------
    image : (H, W, C) or (H, W) uint8
    uvs : (k, 2) float

    Returns
    -------
    (k, C) float64
        In [0, 255], not rounded (C = 1 for a 2-D image).

    Examples
    --------
    >>> img = np.array([[[0], [100]], [[200], [255]]], dtype=np.uint8)  # 2 x 2 grey
    >>> sample_image(img, [[0.25, 0.75], [0.5, 0.5], [-1, 9]]).ravel().tolist()
    [0.0, 138.75, 0.0]
    """
    image = as_image(image, "image")
    uvs = np.asarray(uvs, dtype=np.float64)
    if uvs.ndim != 2 or uvs.shape[1] != 2 or not np.all(np.isfinite(uvs)):
        raise ValueError(f"uvs must be a finite array of shape (k, 2), got {uvs.shape}")
    return _bilinear(image, uvs)


def _bilinear(image: np.ndarray, uvs: np.ndarray) -> np.ndarray:
    H, W, C = image.shape
    x = np.clip(uvs[:, 0] * W - 0.5, 0.0, W - 1.0)
    y = np.clip((1.0 - uvs[:, 1]) * H - 0.5, 0.0, H - 1.0)
    x0 = np.minimum(x.astype(np.int64), W - 1)
    y0 = np.minimum(y.astype(np.int64), H - 1)
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    flat = image.reshape(H * W, C)
    top = flat[y0 * W + x0] * (1.0 - fx) + flat[y0 * W + x1] * fx
    bottom = flat[y1 * W + x0] * (1.0 - fx) + flat[y1 * W + x1] * fx
    return top * (1.0 - fy) + bottom * fy


@dataclass(frozen=True, eq=False)
class BakeResult:
    """A texture baked into one tile of a template's UV layout.

    Attributes
    ----------
    image : (H, W, 3) uint8
        RGB texture of the tile.
    coverage : (H, W) bool
        Texels whose colour comes from the scan: inside the layout, the closest
        scan point within ``max_distance`` and no other part of the template nearer
        to that scan point (see :func:`bake_texture`).
    padded : (H, W) bool
        Uncovered texels within ``padding`` pixels of a covered one; they hold the
        colour of the nearest covered texel.  All other uncovered texels hold the
        mean colour of the covered ones.
    layout : (H, W) bool
        Texels inside the tile's UV triangles (:attr:`UVRaster.mask`).
    filled_fraction : float
        ``coverage.sum() / layout.sum()``: the share of the tile's laid-out texels
        that the scan textured (0.0 for an empty layout).
    tile : int
        The UDIM tile (1001: the unit square).
    """

    image: np.ndarray
    coverage: np.ndarray
    padded: np.ndarray
    layout: np.ndarray
    filled_fraction: float
    tile: int = FIRST_TILE


def _checked_bake_args(template, scan, scan_image, size, padding, tree, max_distance):
    """The arguments of a bake checked once: (template, scan, rgb, (H, W), padding,
    tree, max_distance)."""
    template = checked_uv_mesh(template, "template")
    scan = checked_uv_mesh(scan, "scan")
    rgb = _rgb(as_image(scan_image, "scan_image"))
    hw = _size(size)
    if (isinstance(padding, (bool, np.bool_)) or not isinstance(padding, (int, np.integer))
            or padding < 0):
        raise ValueError(f"padding must be a non-negative int, got {padding!r}")
    max_distance = (0.05 * template.scale() if max_distance is None
                    else _non_negative(max_distance, "max_distance"))
    if tree is None:
        tree = ClosestPointTree(scan.vertices, scan.triangles)
    elif (tree.triangles.shape != scan.triangles.shape
          or tree.vertices.shape != scan.vertices.shape):
        raise ValueError("tree was not built on scan (vertex or triangle counts differ)")
    return template, scan, rgb, hw, int(padding), tree, max_distance


def scan_visibility(template: Mesh, tree) -> np.ndarray:
    """How much each template vertex is the template's own closest surface to the scan.

    For a vertex at distance ``d`` from its closest scan point ``q``, the ratio
    ``(e + h) / (d + h)``, where ``e`` is the distance from ``q`` to the nearest
    point of the whole template and ``h`` a hair (1e-9 of the template's size).  It
    is 1 where the vertex itself is what lies nearest to ``q`` (the skin the scanner
    saw) and near 0 where another part of the template lies much nearer (teeth
    behind the lips, the back of an eyeball, the inside of the mouth: the scanner
    saw that other part, not this one).

    Parameters
    ----------
    template : Mesh
        The fitted template.
    tree : facewrap.geometry.ClosestPointTree
        Built on the scan.

    Returns
    -------
    (n,) float64
        In [0, 1] (up to rounding).

    Examples
    --------
    >>> from facewrap.geometry import ClosestPointTree
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]])
    >>> behind = Mesh(quad.vertices - [0, 0, 0.5], [[0, 1, 2, 3]])
    >>> both = Mesh(np.vstack([quad.vertices + [0, 0, 0.1], behind.vertices]),
    ...             [[0, 1, 2, 3], [4, 5, 6, 7]])
    >>> vis = scan_visibility(both, ClosestPointTree(quad.vertices, quad.triangles))
    >>> np.round(vis, 2).tolist()
    [1.0, 1.0, 1.0, 1.0, 0.2, 0.2, 0.2, 0.2]
    """
    hair = 1e-9 * template.scale()
    own = tree.query(template.vertices)
    mine = ClosestPointTree(template.vertices, template.triangles)
    nearest = mine.query(own.points).distances
    return np.minimum((nearest + hair) / (own.distances + hair), 1.0)


def _beyond_border(tree, points: np.ndarray, cp, hair: float) -> np.ndarray:
    """Points whose closest scan point is where the scan stops, not under them.

    Past a hole or the scan's edge the closest point sits on the border, off to
    the side (the offset lies mostly in the surface's plane) rather than straight
    under the point along the normal; the scan says nothing about such points.
    Points within ``hair`` of the scan are on it, whatever rounding says.
    """
    out = tree.boundary_triangles[cp.triangles] & (cp.distances > hair)
    k = np.flatnonzero(out)         # (the normals of these few only)
    offset = np.abs(np.einsum("kd,kd->k", points[k] - cp.points[k],
                              tree.normals_at(cp.triangles[k], cp.barycentric[k])))
    out[k] = offset < _COS_45 * cp.distances[k]
    return out


_COS_45 = float(np.cos(np.pi / 4))

#: Texels count as seen by the scanner where the interpolated
#: :func:`scan_visibility` is at least this.
SEEN = 0.5


def bake_texture(template: Mesh, scan: Mesh, scan_image, size=1024, padding: int = 8,
                 tree=None, max_distance: float | None = None, *,
                 tile: int = FIRST_TILE, only=None, visibility=None,
                 advance=None) -> BakeResult:
    """Re-bake a scan's texture into one tile of a (fitted) template's UV layout.

    For each texel of the tile's layout (:func:`rasterize_uv`) the point with the
    texel's barycentric coordinates on the template's 3-D triangle is mapped to the
    closest point on the scan, then to the scan's UV there (:func:`scan_uvs_at`), and
    the scan image is sampled bilinearly (:func:`sample_image`).  A texel is not
    covered when its closest scan point is farther than ``max_distance``, or lies
    on the scan's border off to the side (past the edge of a crop or a hole), or when
    the template's :func:`scan_visibility`, interpolated there, is below 0.5:
    another part of the template lies nearer to the scan there, and the scanner saw
    that part, not this one (teeth behind the lips, the back of an eyeball, the
    inside of the mouth).  The texels of triangles unseen at all three corners are
    not looked up on the scan at all.

    Padding across seams: uncovered texels within ``padding`` pixels (Euclidean) of a
    covered texel take the colour of the nearest covered texel
    (``scipy.ndimage.distance_transform_edt``), so mip-maps and bilinear filtering do
    not bleed background into UV islands; the remaining texels take the mean colour
    of the covered ones (black when nothing is covered).

    Parameters
    ----------
    template : Mesh
        Fitted template with texture coordinates (its UV layout is baked).
    scan : Mesh
        Scan with texture coordinates into ``scan_image``.
    scan_image : (h, w, 3) or (h, w, 4) uint8
        The scan's texture (alpha ignored; (h, w) grey accepted).
    size : int or (H, W) int
        Output size; an int means square.
    padding : int
        Dilation radius in pixels, >= 0.
    tree : facewrap.geometry.ClosestPointTree, optional
        A tree already built on ``scan.vertices`` / ``scan.triangles``; built here
        otherwise.
    max_distance : float, optional
        Largest template-to-scan distance that still counts as covered; default 5 %
        of the template's bounding-box diagonal.
    tile : int
        The UDIM tile to bake (:mod:`facewrap.texture.udim`);
        :func:`facewrap.texture.tiles.bake_tiles` bakes every used tile.
    only : (t,) bool, optional
        Bake these triangles of ``template.triangles`` only (those of one texture
        set, :func:`facewrap.texture.tiles.texture_sets`); the others are not laid out.
    visibility : (n,) float, optional
        :func:`scan_visibility` of ``template`` on ``tree``; computed here otherwise.
    advance : callable, optional
        Called as the bake goes, with the share of the image's rows each band
        finished (they add up to 1): a progress bar's ``advance``.

    Returns
    -------
    BakeResult
        The image, which texels the scan covered and which were padded.

    Examples
    --------
    >>> quad = Mesh([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.]], [[0, 1, 2, 3]],
    ...             uvs=[[0, 0], [1, 0], [1, 1], [0, 1.]], face_uvs=[[0, 1, 2, 3]])
    >>> img = np.arange(48, dtype=np.uint8).reshape(4, 4, 3)
    >>> res = bake_texture(quad, quad, img, size=4)
    >>> bool((res.image == img).all()), res.filled_fraction
    (True, 1.0)
    """
    tile_origin(tile)   # a tile that does not exist is refused before any work
    template, scan, rgb, (H, W), padding, tree, max_distance = _checked_bake_args(
        template, scan, scan_image, size, padding, tree, max_distance)
    if visibility is None:
        visibility = scan_visibility(template, tree)
    else:
        visibility = np.asarray(visibility, dtype=np.float64)
        if visibility.shape != (template.n_vertices,):
            raise ValueError(f"visibility must have shape ({template.n_vertices},), got "
                             f"{visibility.shape}")
    image = np.zeros((H, W, 3), dtype=np.uint8)
    coverage = np.zeros(H * W, dtype=bool)
    layout = np.zeros(H * W, dtype=bool)
    flat = image.reshape(-1, 3)
    # band by band of texel rows: a 4K or 8K layout in pieces of bounded memory
    done = 0
    for stop, key, tri, bary in _raster_bands(template, H, W, tile,
                                              _checked_only(template, only)):
        layout[key] = True
        corner_ids = template.triangles[tri]                                # (p, 3)
        seen = np.einsum("pc,pc->p", bary, visibility[corner_ids]) >= SEEN
        points = np.einsum("pc,pcd->pd", bary[seen], template.vertices[corner_ids[seen]])
        cp = tree.query(points)
        hit = (cp.distances <= max_distance) & ~_beyond_border(tree, points, cp,
                                                               1e-9 * template.scale())
        near = key[seen][hit]
        uv = trusted_scan_uvs(scan, cp.triangles[hit], cp.barycentric[hit])
        flat[near] = to_uint8(_bilinear(rgb, uv))
        coverage[near] = True
        if advance is not None:
            advance((stop - done) / H)
            done = stop
    if advance is not None and done < H:
        advance((H - done) / H)
    coverage = coverage.reshape(H, W)
    image, padded = pad_texture(image, coverage, padding)
    n_layout = int(layout.sum())
    return BakeResult(image=image, coverage=coverage, padded=padded,
                      layout=layout.reshape(H, W),
                      filled_fraction=float(coverage.sum() / n_layout) if n_layout else 0.0,
                      tile=int(tile))


def pad_texture(image: np.ndarray, coverage: np.ndarray, padding: int):
    """Fill a baked image's uncovered texels, so that filtering shows no seams.

    Uncovered texels within ``padding`` pixels (Euclidean) of a covered texel take
    the colour of a nearest covered texel (``scipy.ndimage.distance_transform_edt``);
    the others take the mean colour of the covered ones.

    Parameters
    ----------
    image : (H, W, C) uint8
    coverage : (H, W) bool
        Texels holding baked colours.
    padding : int
        Radius in pixels, >= 0.

    Returns
    -------
    image : (H, W, C) uint8
        A new image (the input itself when nothing or everything is covered).
    padded : (H, W) bool
        The texels given a nearest covered colour.

    Examples
    --------
    >>> image = np.zeros((1, 5, 3), np.uint8)
    >>> image[0, 0] = 200
    >>> out, padded = pad_texture(image, np.array([[1, 0, 0, 0, 1]], bool), 1)
    >>> out[0, :, 0].tolist(), padded.astype(int).tolist()
    ([200, 200, 100, 0, 0], [[0, 1, 0, 1, 0]])
    """
    padded = np.zeros_like(coverage)
    if not coverage.any():
        return image, padded
    if coverage.all():
        return image, padded
    # deferred: scipy.ndimage takes ~0.2 s to import and only baking pads a texture
    from scipy import ndimage
    out = image.copy()
    out[~coverage] = to_uint8(image[coverage].mean(axis=0))
    # texels within `padding` of a covered one, and that covered one, lie in the
    # covered texels' box grown by `padding`: the distance transform runs there only
    # (an eye's image covers a corner of its tile)
    rows, cols = np.flatnonzero(coverage.any(axis=1)), np.flatnonzero(coverage.any(axis=0))
    box = (slice(max(rows[0] - padding, 0), rows[-1] + padding + 1),
           slice(max(cols[0] - padding, 0), cols[-1] + padding + 1))
    dist, (ri, ci) = ndimage.distance_transform_edt(~coverage[box], return_indices=True)
    near = ~coverage[box] & (dist <= padding)
    padded[box] = near
    out[box][near] = image[box][ri[near], ci[near]]
    return out, padded


def interpolate_images(a, b, t: float) -> np.ndarray:
    """Blend two images: ``round((1 - t) a + t b)`` (SPEC §1.5, for textures).

    Parameters
    ----------
    a, b : (H, W) or (H, W, C) uint8
        Same shape.
    t : float
        In [0, 1]; ``t = 0`` gives ``a``, ``t = 1`` gives ``b`` exactly.

    Returns
    -------
    uint8 array, shape of ``a``

    Examples
    --------
    >>> a, b = np.zeros((1, 2, 3), np.uint8), np.full((1, 2, 3), 255, np.uint8)
    >>> interpolate_images(a, b, 0.5)[0, 0].tolist()
    [128, 128, 128]
    """
    a, b = np.asarray(a), np.asarray(b)
    for name, im in (("a", a), ("b", b)):
        if im.dtype != np.uint8 or im.ndim not in (2, 3):
            raise ValueError(f"{name} must be a uint8 image (H, W) or (H, W, C), got "
                             f"{im.dtype} {im.shape}")
    if a.shape != b.shape:
        raise ValueError(f"a and b must have the same shape, got {a.shape} and {b.shape}")
    t = float(t)
    if not 0.0 <= t <= 1.0:
        raise ValueError(f"t must lie in [0, 1], got {t}")
    return to_uint8((1.0 - t) * a.astype(np.float64) + t * b.astype(np.float64))
