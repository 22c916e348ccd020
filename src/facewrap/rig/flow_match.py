"""Surface correspondences from optical flow between two textured meshes.

Geometry alone cannot see skin slide along smooth skin (the forehead under a brow
raise, the cheeks under a smile): a closest-point fit leaves each vertex wherever
the surface is, not where its skin went.  The texture can.  :func:`flow_matches`
draws the fitted template (with its texture) and the scan (with its own) from the
same orthographic cameras (:func:`face_cameras`), as albedo only (no light: the
two surfaces differ in shape, a light would shade them differently), computes the
dense optical flow from the template's picture to the scan's (OpenCV's DIS, or
Farnebäck) and lifts every matched pixel: its template point (triangle +
barycentric, from the z-buffer) goes to the scan point the flow lands on.

Each match has a confidence, the product of

- forward-backward consistency (the flow from the scan back lands where it
  started: occlusions, texture-less regions and silhouettes fail it),
- texture gradient strength (flow on a flat albedo is a guess),
- view angle (both surfaces seen face-on, not grazing),

and a match is kept only when its pixel and its landing pixel both show the
surface away from the silhouette, and the two surface points are near in 3-D.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from facewrap.detection.views import Camera, RenderedView, SceneArrays, rotation_about
from facewrap.geometry.normals import trusted_vertex_normals
from facewrap.mesh import Mesh
from facewrap.parallel import thread_map
from facewrap.params import Interval, Options, validate
from facewrap.report.raster import Raster, trusted_rasterize

__all__ = ["TexturedSurface", "FlowMatches", "MatchRules", "face_cameras", "render_albedo",
           "dense_flow", "flow_matches", "prefiltered", "ScanViews", "FLOW_METHODS"]

#: the optical flow algorithms of :func:`dense_flow`
FLOW_METHODS = ("dis", "farneback")
_LUMA = np.array([0.299, 0.587, 0.114], dtype=np.float32)
_BORDER = 3              # pixels of the silhouette's rim that no match may touch
_DIS_PATCH_STRIDE = 4    # pixels between DIS's patches (its medium preset: 3)


@dataclass(frozen=True, eq=False)
class TexturedSurface:
    """A triangle mesh with its albedo, as the flow draws it.

    Attributes
    ----------
    V : (n, 3) float64
    T : (t, 3) int64
    corner_uvs : (t, 3, 2) float64
        Texture coordinates of each triangle corner.
    image : (H, W, 3) or (H, W) uint8 or float32
        The albedo (OBJ convention: row 0 at ``v = 1``), in [0, 255].
    triangles : (s,) int64 or None
        The triangles that may be drawn (the skin of a template), None: all.
    """
    V: np.ndarray
    T: np.ndarray
    corner_uvs: np.ndarray
    image: np.ndarray
    triangles: np.ndarray | None = None

    @classmethod
    def of(cls, mesh: Mesh, image, vertices=None, triangles=None) -> "TexturedSurface":
        """``mesh`` (with texture coordinates) drawn with ``image``, at ``vertices``
        (n, 3) when given (a fitted template's positions)."""
        if mesh.uvs is None or mesh.triangle_uvs is None:
            raise ValueError("a textured surface needs texture coordinates")
        V = mesh.vertices if vertices is None else np.asarray(vertices, dtype=np.float64)
        return cls(V, mesh.triangles, np.asarray(mesh.uvs)[mesh.triangle_uvs],
                   np.asarray(image), None if triangles is None
                   else np.asarray(triangles, dtype=np.int64))


def _gray(image) -> np.ndarray:
    """(H, W) float32 grey levels (Rec. 601 luma) of an (H, W) or (H, W, 3) image,
    channel by channel: no float copy of a whole colour texture (a 2048² one took
    longer to convert than to blur)."""
    image = np.asarray(image)
    if image.ndim == 2:
        return image.astype(np.float32, copy=False)
    gray = np.multiply(image[..., 0], _LUMA[0], dtype=np.float32)
    for c in (1, 2):
        gray += np.multiply(image[..., c], _LUMA[c], dtype=np.float32)
    return gray


def _blur(gray: np.ndarray, sigma: float) -> np.ndarray:
    """(H, W) float32 ``gray`` blurred by a Gaussian of ``sigma`` pixels, cut at four
    sigmas, mirrored at the edges: scipy's ``gaussian_filter``, by OpenCV's
    separable filter when it is there (a tenth of the time; the same to 1e-4 grey
    levels)."""
    radius = int(4.0 * sigma + 0.5)
    try:
        import cv2    # the flow's optional extra
    except ImportError:
        from scipy.ndimage import gaussian_filter
        return gaussian_filter(gray, sigma)
    return cv2.GaussianBlur(gray, (2 * radius + 1, 2 * radius + 1), sigma,
                            borderType=cv2.BORDER_REFLECT)


def prefiltered(surface: TexturedSurface, pixel_size: float) -> TexturedSurface:
    """``surface`` with its image in grey and blurred to the detail a picture of
    pixels ``pixel_size`` (mesh units) can show.

    A picture samples the texture once per pixel; texture detail finer than a
    pixel aliases, differently in two meshes whose triangles differ, and the flow
    would match the aliasing.  The image is blurred by a Gaussian of half the
    texels a pixel covers (texels per mesh unit from the UV and surface areas).
    """
    gray = _gray(surface.image)
    H, W = gray.shape
    T = surface.T if surface.triangles is None else surface.T[surface.triangles]
    uv = surface.corner_uvs if surface.triangles is None else \
        surface.corner_uvs[surface.triangles]
    e1, e2 = uv[:, 1] - uv[:, 0], uv[:, 2] - uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]) * W * H
    P = surface.V[T]
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    texels_per_unit = np.sqrt(uv_area.sum() / max(float(area.sum()), 1e-300))
    sigma = 0.5 * texels_per_unit * pixel_size
    if sigma > 0.3:
        gray = _blur(gray, sigma)
    return TexturedSurface(surface.V, surface.T, surface.corner_uvs,
                           np.clip(gray, 0, 255), surface.triangles)


@dataclass(frozen=True, eq=False)
class FlowMatches:
    """Template surface points and the scan points the flow matched them to.

    Attributes
    ----------
    triangle : (k,) int64
        Template triangle of each match (into the template's ``T``).
    barycentric : (k, 3) float64
        Its coordinates in that triangle.
    targets : (k, 3) float64
        The scan point it goes to.
    confidence : (k,) float64 in (0, 1]
    view : (k,) int64
        The camera that found it.
    rejected : dict of str to int
        Pixels dropped per reason (``consistency``, ``gradient``, ``angle``,
        ``visibility``, ``distance``).
    """
    triangle: np.ndarray
    barycentric: np.ndarray
    targets: np.ndarray
    confidence: np.ndarray
    view: np.ndarray
    rejected: dict

    def __len__(self) -> int:
        return len(self.triangle)

    def sources(self, V, T) -> np.ndarray:
        """(k, 3) float64: the template points at positions ``V`` (n, 3)."""
        return np.einsum("kj,kjd->kd", self.barycentric, np.asarray(V)[np.asarray(T)[
            self.triangle]])


@dataclass(frozen=True)
class MatchRules:
    """What a flow match must pass (see :func:`flow_matches`); checked when made.

    The one home of these rules: :class:`~facewrap.rig.TextureFlowSettings`
    derives from this class, so a refinement's settings are its match rules too.

    Attributes
    ----------
    method : {"dis", "farneback"}
        The optical flow (OpenCV's DIS or Farnebäck).
    consistency : float
        Largest forward-backward disagreement of a match, pixels.
    min_gradient : float
        Smallest albedo gradient (grey levels per pixel, smoothed) where a match
        counts; the confidence grows to 1 at four times it.
    max_angle : float
        Largest angle between a surface normal and the camera's direction, degrees.
    max_distance : float
        Largest distance between a match's two points, fraction of the template's
        size (the ``size`` of :func:`flow_matches`: by default the bounding-box
        diagonal of the part it draws).
    step : int
        Every ``step``-th pixel in each direction is matched (neighbouring pixels'
        flow is nearly the same: more of them only cost).
    """
    method: str = "dis"
    consistency: float = 0.7
    min_gradient: float = 2.0
    max_angle: float = 65.0
    max_distance: float = 0.02
    step: int = 2
    constraints = {"method": Options(*FLOW_METHODS),
                   "consistency": Interval(float, 0, None, closed="neither"),
                   # a confidence is the gradient over four times this: not zero
                   "min_gradient": Interval(float, 0, None, closed="neither"),
                   "max_angle": Interval(float, 0, 90, closed="neither"),
                   "max_distance": Interval(float, 0, 1, closed="right"),
                   "step": Interval(int, 1, 16)}

    def __post_init__(self):
        validate(self)


def face_cameras(V, normals, count: int, size: int) -> list[Camera]:
    """``count`` orthographic cameras around the surface ``V`` (k, 3) whose vertex
    normals are ``normals`` (k, 3): one along their mean (the face's front), the
    others turned 30 degrees about two axes across it, every one framing all of
    ``V`` in ``size`` x ``size`` pixels.

    Returns
    -------
    list of Camera
    """
    V = np.asarray(V, dtype=np.float64)
    front = np.asarray(normals, dtype=np.float64).sum(axis=0)
    front /= max(np.linalg.norm(front), 1e-300)
    centre = V.mean(axis=0)
    # across the front: the surface's widest direction, then the third axis
    X = V - centre
    X = X - np.outer(X @ front, front)
    across = np.linalg.svd(X, full_matrices=False)[2][0]
    other = np.cross(front, across)
    turns = [np.eye(3)] + [rotation_about(axis, sign * 30.0)
                           for axis in (other, across) for sign in (1.0, -1.0)]
    cameras = []
    for turn in turns[:count]:
        z = turn @ front
        x = turn @ across
        R = np.stack([x, np.cross(z, x), z])
        C = (V - centre) @ R.T
        extent = float(np.max(np.abs(C[:, :2]))) * 2.0
        cameras.append(Camera(R, centre, 1.05 * extent / size, (size, size)))
    return cameras


def render_albedo(surface: TexturedSurface, camera: Camera) -> tuple[np.ndarray, Raster]:
    """The surface's grey albedo seen by ``camera`` (no light) and its raster.

    Returns
    -------
    gray : (H, W) float32
        Grey levels in [0, 255]; 0 on the background.
    raster : Raster
        Triangle (into the surface's ``T``) and barycentric coordinates per pixel.
    """
    w, h = camera.size
    C = (surface.V - camera.center) @ camera.rotation.T
    x = C[:, 0] / camera.pixel_size + w / 2 - 0.5
    y = h / 2 - C[:, 1] / camera.pixel_size - 0.5
    T = surface.T if surface.triangles is None else surface.T[surface.triangles]
    raster = trusted_rasterize(x, y, -C[:, 2], T, w, h)
    if surface.triangles is not None:
        full = np.where(raster.triangle >= 0,
                        surface.triangles[np.maximum(raster.triangle, 0)], -1)
        raster = Raster(full, raster.pixels, raster.barycentric)
    gray = np.zeros(h * w, dtype=np.float32)
    if len(raster.pixels):
        tri = raster.triangle.reshape(-1)[raster.pixels]
        uv = np.einsum("pj,pjd->pd", raster.barycentric.astype(np.float64),
                       surface.corner_uvs[tri])
        image = _gray(surface.image)
        H, W = image.shape
        # texel (row, col) is centred at u = (col + 0.5) / W, v = 1 - (row + 0.5) / H
        gray[raster.pixels] = _sample(image, np.column_stack([uv[:, 0] * W - 0.5,
                                                              (1.0 - uv[:, 1]) * H - 0.5]))
    return gray.reshape(h, w), raster


def dense_flow(a, b, method: str = "dis") -> np.ndarray:
    """Dense optical flow from grey picture ``a`` to ``b`` (both (H, W) float or
    uint8, [0, 255]): ``a[y, x]`` shows what ``b`` shows at ``(x, y) + flow[y, x]``.

    Returns
    -------
    (H, W, 2) float32
        ``(dx, dy)`` in pixels.
    """
    import cv2    # the optional extra facewrap[flow], loaded on use

    a8 = np.clip(np.rint(a), 0, 255).astype(np.uint8)
    b8 = np.clip(np.rint(b), 0, 255).astype(np.uint8)
    if method == "dis":
        dis = cv2.DISOpticalFlow_create(cv2.DISOPTICAL_FLOW_PRESET_MEDIUM)
        # patches every 4 pixels, not the preset's 3: 36 instead of 50 ms of CPU a
        # 640² flow, and the refinement's errors on bench_texture_flow's six
        # expressions the same to 0.003 mm
        dis.setPatchStride(_DIS_PATCH_STRIDE)
        return dis.calc(a8, b8, None)
    if method == "farneback":
        return cv2.calcOpticalFlowFarneback(a8, b8, None, 0.5, 5, 15, 5, 7, 1.5, 0)
    raise ValueError(f"flow method must be one of {', '.join(FLOW_METHODS)}; got {method!r}")


def _gradient(gray: np.ndarray) -> np.ndarray:
    """(H, W) float32: length of the albedo's gradient, lightly smoothed (grey
    levels per pixel)."""
    from scipy.ndimage import sobel

    g = _blur(gray.astype(np.float32), 1.0)
    return np.hypot(sobel(g, axis=1), sobel(g, axis=0)) / 8.0


def _sample(field: np.ndarray, xy: np.ndarray) -> np.ndarray:
    """Bilinear samples of an (H, W, ...) field at (k, 2) pixel positions."""
    H, W = field.shape[:2]
    x = np.clip(xy[:, 0], 0.0, W - 1.0)
    y = np.clip(xy[:, 1], 0.0, H - 1.0)
    x0 = np.minimum(x.astype(np.int64), W - 2)
    y0 = np.minimum(y.astype(np.int64), H - 2)
    fx, fy = x - x0, y - y0
    # four gathers from the flat field: one index array, not four pairs of them
    flat = field.reshape(H * W, *field.shape[2:])
    i = y0 * W + x0
    if field.ndim == 3:
        fx, fy = fx[:, None], fy[:, None]
    top = flat.take(i, axis=0) * (1 - fx) + flat.take(i + 1, axis=0) * fx
    bottom = flat.take(i + W, axis=0) * (1 - fx) + flat.take(i + W + 1, axis=0) * fx
    return top * (1 - fy) + bottom * fy


def _inner(mask: np.ndarray) -> np.ndarray:
    """Covered pixels at least :data:`_BORDER` pixels inside the silhouette."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, iterations=_BORDER)


@dataclass(frozen=True, eq=False)
class ScanViews:
    """A scan drawn once from every camera: what each round of flow matching
    compares a moved template with (the scan does not move).

    Attributes
    ----------
    cameras : list of Camera
    pictures : list of (H, W) float32
        Prefiltered grey albedo per camera.
    rasters : list of Raster
    inner : list of (H, W) bool
        Covered pixels away from the silhouette.
    scene : SceneArrays
        The scan's arrays (for lifting points onto it).
    """
    cameras: list
    pictures: list
    rasters: list
    inner: list
    scene: SceneArrays

    @property
    def pixel_size(self) -> float:
        """The cameras' mean pixel size, mesh units (what :func:`prefiltered` blurs
        to)."""
        return float(np.mean([cam.pixel_size for cam in self.cameras]))

    @classmethod
    def of(cls, scan: TexturedSurface, cameras) -> "ScanViews":
        pixel = float(np.mean([cam.pixel_size for cam in cameras]))
        scan = prefiltered(scan, pixel)
        drawn = thread_map(lambda cam: render_albedo(scan, cam), cameras)
        return cls(list(cameras), [d[0] for d in drawn], [d[1] for d in drawn],
                   [_inner(d[1].mask) for d in drawn], SceneArrays.of(scan.V, scan.T))


def _view_matches(template: TexturedSurface, views: ScanViews, k: int, rules: MatchRules,
                  normals: np.ndarray, max_distance: float):
    """Camera ``k``'s matches: (triangle, barycentric, targets, confidence, rejected),
    ``rejected`` its pixels dropped per reason; ``max_distance`` in mesh units."""
    rejected: dict = {}
    camera, b, rb, inner_b = views.cameras[k], views.pictures[k], views.rasters[k], \
        views.inner[k]
    a, ra = render_albedo(template, camera)
    forward = dense_flow(a, b, rules.method)
    backward = dense_flow(b, a, rules.method)
    h, w = a.shape
    rows, cols = np.mgrid[0:h:rules.step, 0:w:rules.step]
    inner_a = _inner(ra.mask)
    keep = inner_a[rows, cols]
    rows, cols = rows[keep], cols[keep]
    p = np.column_stack([cols, rows]).astype(np.float64)
    f = forward[rows, cols].astype(np.float64)
    q = p + f
    qi = np.rint(q).astype(np.int64)
    inside = (qi[:, 0] >= 0) & (qi[:, 0] < w) & (qi[:, 1] >= 0) & (qi[:, 1] < h)
    seen = inside.copy()
    seen[inside] = inner_b[qi[inside, 1], qi[inside, 0]]
    back = _sample(backward, q)
    error = np.linalg.norm(f + back, axis=1)
    gradient = _gradient(a)[rows, cols]
    tri = ra.triangle[rows, cols]
    bary = ra.barycentric[np.searchsorted(ra.pixels, rows * w + cols)].astype(np.float64)
    n = np.einsum("kj,kjd->kd", bary, normals[template.T[tri]])
    cos = n @ camera.direction / np.maximum(np.linalg.norm(n, axis=1), 1e-300)
    tests = {"visibility": seen, "consistency": error <= rules.consistency,
             "gradient": gradient >= rules.min_gradient,
             "angle": cos >= np.cos(np.radians(rules.max_angle))}
    ok = np.ones(len(p), dtype=bool)
    for reason, passed in tests.items():
        rejected[reason] = rejected.get(reason, 0) + int(np.count_nonzero(ok & ~passed))
        ok &= passed
    view = RenderedView(camera, np.zeros((h, w), dtype=np.uint8), rb)
    targets, hit = view.lift(views.scene, q[ok])
    sources = np.einsum("kj,kjd->kd", bary[ok], template.V[template.T[tri[ok]]])
    near = (hit >= 0) & (np.linalg.norm(targets - sources, axis=1) <= max_distance)
    rejected["distance"] = rejected.get("distance", 0) + int(np.count_nonzero(~near))
    # consistency, gradient and view angle each scale the trust in a match
    confidence = (np.exp(-(error[ok] / rules.consistency) ** 2)
                  * np.minimum(1.0, gradient[ok] / (4.0 * rules.min_gradient))
                  * cos[ok])[near]
    return tri[ok][near], bary[ok][near], targets[near], confidence, rejected


def flow_matches(template: TexturedSurface, scan: TexturedSurface | ScanViews,
                 cameras=None, rules: MatchRules | None = None, *,
                 prefilter: bool = True, size: float | None = None) -> FlowMatches:
    """Correspondences from the template's surface to the scan's, by optical flow
    in every camera (see the module's docstring).

    Parameters
    ----------
    template : TexturedSurface
        The fitted template with its texture (the neutral's, baked in its layout).
    scan : TexturedSurface or ScanViews
        The scan with its own texture, or already drawn from the cameras (rounds of
        matching draw it once).
    cameras : sequence of Camera
        Needed when ``scan`` is a surface; a ScanViews has its own.
    rules : MatchRules, optional
    prefilter : bool
        False: the template's image is already :func:`prefiltered` for these
        cameras (rounds of matching the same template blur its image once).
    size : float, optional
        What ``rules.max_distance`` is a fraction of, mesh units; default the
        bounding-box diagonal of the template's drawn vertices.

    Returns
    -------
    FlowMatches
    """
    rules = rules or MatchRules()
    views = scan if isinstance(scan, ScanViews) else ScanViews.of(scan, cameras)
    if prefilter:
        template = prefiltered(template, views.pixel_size)
    normals = trusted_vertex_normals(template.V, template.T, "angle")
    # the views are independent, and their flow, rasters and filters release the GIL
    if size is None:
        drawn = template.T if template.triangles is None else template.T[template.triangles]
        size = float(np.linalg.norm(np.ptp(template.V[np.unique(drawn)], axis=0)))
    reach = rules.max_distance * size
    parts = thread_map(lambda k: _view_matches(template, views, k, rules, normals, reach),
                       range(len(views.cameras)))
    rejected: dict = {}
    for p in parts:
        for reason, count in p[4].items():
            rejected[reason] = rejected.get(reason, 0) + count
    view = np.concatenate([np.full(len(p[0]), k, dtype=np.int64)
                           for k, p in enumerate(parts)])
    tri, bary, targets, confidence = (np.concatenate([p[i] for p in parts])
                                      for i in range(4))
    return FlowMatches(tri.astype(np.int64), bary.reshape(-1, 3),
                       targets.reshape(-1, 3), confidence, view, rejected)
