"""facewrap.texture.bake: UV rasterisation, image sampling and baking (SPEC §1.4)."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

import facewrap.texture.bake
from facewrap.geometry import ClosestPointTree
from facewrap.mesh import Mesh
from facewrap.texture import (bake_texture, interpolate_images, load_image, rasterize_uv,
                              sample_image)

from texture_cases import checkerboard, gradient_image, texel_centres, uv_plane


@pytest.mark.parametrize("size", [64, (48, 80), 50])
@pytest.mark.parametrize("jitter", [0.0, 0.35])
def test_full_square_layout_covers_every_texel_exactly_once(size, jitter):
    mesh = uv_plane(7, jitter=jitter)            # 7 does not divide the sizes: edges cut texels
    r = rasterize_uv(mesh, size)
    H, W = (size, size) if np.ndim(size) == 0 else size
    assert r.mask.shape == (H, W) and r.mask.all()
    assert len(r) == H * W
    assert len(np.unique(r.pixels[:, 0] * W + r.pixels[:, 1])) == H * W
    # barycentric coordinates rebuild each texel centre's UV in its owning triangle
    uv = np.einsum("pc,pcd->pd", r.barycentric, mesh.uvs[mesh.triangle_uvs[r.triangles]])
    np.testing.assert_allclose(uv, texel_centres(H, W)[r.pixels[:, 0], r.pixels[:, 1]],
                               atol=1e-12)
    assert r.barycentric.min() >= 0
    np.testing.assert_allclose(r.barycentric.sum(axis=1), 1)


def test_partial_layout_coverage_matches_area_and_a_brute_force_oracle():
    # a disc-like island (jittered grid squeezed into a circle) in part of UV space
    def squeeze(xy):
        d = xy - 0.5
        r = np.abs(d).max(axis=1, keepdims=True)
        n = np.linalg.norm(d, axis=1, keepdims=True)
        return 0.45 + 0.4 * np.divide(d * r, n, out=np.zeros_like(d), where=n > 0)

    mesh = uv_plane(6, uv=squeeze)
    S = 96
    r = rasterize_uv(mesh, S)
    uvt = mesh.uvs[mesh.triangle_uvs]                    # (t, 3, 2)
    a, b, c = uvt[:, 0], uvt[:, 1], uvt[:, 2]
    area = 0.5 * np.abs((b - a)[:, 0] * (c - a)[:, 1] - (b - a)[:, 1] * (c - a)[:, 0])
    assert abs(len(r) - area.sum() * S * S) < 4 * S     # within a perimeter's worth
    # oracle: texel centre inside some triangle (sign tests, no tolerance games)
    q = texel_centres(S, S).reshape(-1, 1, 2)

    def cross(o, p, x):
        return (p - o)[..., 0] * (x - o)[..., 1] - (p - o)[..., 1] * (x - o)[..., 0]

    s = np.stack([cross(a, b, q), cross(b, c, q), cross(c, a, q)], -1)   # (S*S, t, 3)
    strict = ((s > 1e-12).all(-1) | (s < -1e-12).all(-1)).any(-1).reshape(S, S)
    loose = ((s >= -1e-9).all(-1) | (s <= 1e-9).all(-1)).any(-1).reshape(S, S)
    assert np.all(r.mask[strict]) and not np.any(r.mask & ~loose)
    # each owner really contains its texel centre
    inside = (s[r.pixels[:, 0] * S + r.pixels[:, 1], r.triangles] * np.sign(
        area_signed := cross(a, b, c))[r.triangles, None] >= -1e-9).all(-1)
    assert inside.all() and np.all(area_signed != 0)


def test_rasterize_ignores_uvs_outside_the_unit_square_and_checks_size():
    mesh = uv_plane(2, uv=lambda xy: xy + 2.0)
    r = rasterize_uv(mesh, 16)
    assert len(r) == 0 and not r.mask.any()
    for bad in (0, -3, 2.5, (4, 0), (1, 2, 3), True):
        with pytest.raises(ValueError, match="size"):
            rasterize_uv(mesh, bad)


@pytest.mark.parametrize("image", [checkerboard(128), gradient_image(128, 4)])
def test_bake_mesh_onto_itself_reproduces_the_image(image):
    mesh = uv_plane(9, jitter=0.3)
    image_ro = image.copy()
    image_ro.setflags(write=False)
    res = bake_texture(mesh, mesh, image_ro, size=128)
    assert res.image.shape == (128, 128, 3) and res.image.dtype == np.uint8
    assert res.coverage.all() and res.filled_fraction == 1.0
    err = np.abs(res.image.astype(int) - image[..., :3].astype(int))
    assert err[res.coverage].mean() < 2
    np.testing.assert_array_equal(image_ro, image)


def test_bake_resamples_a_smooth_image_at_another_size():
    mesh = uv_plane(5)
    img = gradient_image(200)
    res = bake_texture(mesh, mesh, img, size=64)
    # the gradient is linear, so the bilinear sample equals the analytic value
    uv = texel_centres(64, 64)
    expected = np.stack([uv[..., 0] * 200 - 0.5, (1 - uv[..., 1]) * 200 - 0.5], -1)
    expected = np.clip(expected, 0, 199) * 255 / 199
    err = np.abs(res.image[..., :2].astype(float) - expected)
    assert err.max() <= 1.0 and err.mean() < 0.5


def test_bake_refuses_an_image_too_large_to_hold_before_allocating_it():
    """``size=10**6`` failed as a bare MemoryError at allocation (a terabyte image)."""
    mesh = uv_plane(2)
    for bad in (10 ** 6, (64, 10 ** 5), 16385):
        with pytest.raises(ValueError, match="at most 16384 pixels a side"):
            bake_texture(mesh, mesh, gradient_image(8), size=bad)


def test_bake_between_rotated_layouts_rotates_the_image():
    S = 96
    scan = uv_plane(6)                                              # uv = (x, y)
    template = uv_plane(5, uv=lambda xy: np.stack([1 - xy[:, 1], xy[:, 0]], 1))  # 90 deg
    img = checkerboard(S, cell=12)
    img[:10, :30] = [255, 255, 0]                               # break the symmetry
    res = bake_texture(template, scan, img, size=S)
    assert res.coverage.all()
    err = np.abs(res.image.astype(int) - np.rot90(img).astype(int))
    assert err.mean() < 2
    assert np.abs(res.image.astype(int) - img.astype(int)).mean() > 20


def test_padding_fills_exactly_the_texels_within_padding_pixels():
    S, pad = 64, 5
    scan = uv_plane(4)
    template = uv_plane(4, uv=lambda xy: 0.25 + 0.5 * xy)   # island = texels 16..47
    img = gradient_image(S)
    res = bake_texture(template, scan, img, size=S, padding=pad)
    cov = np.zeros((S, S), bool)
    cov[16:48, 16:48] = True
    np.testing.assert_array_equal(res.coverage, cov)
    np.testing.assert_array_equal(res.layout, cov)
    # oracle: Euclidean distance from each texel to the nearest covered texel
    d, nearest = cKDTree(np.argwhere(cov)).query(np.argwhere(np.ones((S, S))))
    d = d.reshape(S, S)
    np.testing.assert_array_equal(res.padded, ~cov & (d <= pad))
    assert res.padded.sum() > 0 and (~cov & ~res.padded).sum() > 0
    # straight out from an edge: the colour of the edge texel
    np.testing.assert_array_equal(res.image[20, 16 - pad:16], np.repeat(
        res.image[20, 16:17], pad, axis=0))
    np.testing.assert_array_equal(res.image[47 + pad, 30], res.image[47, 30])
    # beyond the padding: mean colour of the covered texels
    mean = np.rint(res.image[cov].mean(axis=0))
    np.testing.assert_array_equal(res.image[~cov & ~res.padded],
                                  np.broadcast_to(mean, ((~cov & ~res.padded).sum(), 3)))
    assert res.filled_fraction == 1.0
    res0 = bake_texture(template, scan, img, size=S, padding=0)
    assert not res0.padded.any()


def test_far_texels_are_not_covered():
    scan = uv_plane(4)
    lifted = uv_plane(4)
    lifted = lifted.with_vertices(lifted.vertices + [0, 0, 0.08])   # 0.08 above the scan
    for max_distance, covered in ((0.1, True), (0.05, False)):
        res = bake_texture(lifted, scan, gradient_image(32), size=16,
                           max_distance=max_distance, padding=0)
        assert res.coverage.all() if covered else not res.coverage.any()
    # default: 5 % of the template's diagonal (sqrt(2) * 0.05 ~ 0.071 < 0.08)
    assert not bake_texture(lifted, scan, gradient_image(32), size=16).coverage.any()


def test_texels_past_the_scans_border_are_not_covered_however_near():
    scan = uv_plane(4)
    template = uv_plane(8, scale=(2.0, 1.0))     # x in [0, 2]: right half is off the scan
    u = texel_centres(40, 40)[..., 0]
    for max_distance in (0.1, None):
        res = bake_texture(template, scan, gradient_image(32), size=40,
                           max_distance=max_distance, padding=0)
        np.testing.assert_array_equal(res.coverage, 2 * u - 1 <= 0)
        assert res.filled_fraction == pytest.approx(res.coverage.mean())


def test_bake_checks_its_arguments():
    mesh = uv_plane(2)
    img = gradient_image(8)
    with pytest.raises(ValueError, match="uint8"):
        bake_texture(mesh, mesh, img.astype(float))
    with pytest.raises(ValueError, match="padding"):
        bake_texture(mesh, mesh, img, size=8, padding=-1)
    with pytest.raises(ValueError, match="template has no texture"):
        bake_texture(Mesh(mesh.vertices, mesh.faces_array()), mesh, img)
    other = uv_plane(3)
    with pytest.raises(ValueError, match="tree"):
        bake_texture(mesh, mesh, img, size=8,
                     tree=ClosestPointTree(other.vertices, other.triangles))


def test_sample_image_is_bilinear_and_clamps():
    img = np.array([[[0], [100]], [[200], [40]]], np.uint8)
    got = sample_image(img, [[0.25, 0.75], [0.75, 0.75], [0.25, 0.25], [0.5, 0.75],
                             [5.0, -5.0]]).ravel()
    np.testing.assert_allclose(got, [0, 100, 200, 50, 40])


def test_interpolate_images():
    a = np.zeros((3, 4, 3), np.uint8)
    b = np.full((3, 4, 3), 201, np.uint8)
    np.testing.assert_array_equal(interpolate_images(a, b, 0), a)
    np.testing.assert_array_equal(interpolate_images(a, b, 1), b)
    assert interpolate_images(a, b, 0.5).dtype == np.uint8
    assert np.all(interpolate_images(a, b, 0.5) == 100) or \
        np.all(interpolate_images(a, b, 0.5) == 101)
    with pytest.raises(ValueError, match="same shape"):
        interpolate_images(a, b[:2], 0.5)
    with pytest.raises(ValueError, match="t must"):
        interpolate_images(a, b, 1.5)


def test_rasterize_and_bake_in_small_chunks_give_the_same_results(monkeypatch):
    mesh = uv_plane(5, jitter=0.3)
    scan = uv_plane(9, jitter=0.2, seed=4)
    img = gradient_image(32)
    whole = rasterize_uv(mesh, 40)
    baked = bake_texture(mesh, scan, img, size=(40, 36), padding=3)
    # 7 texels a block: every band a row, every block a few runs
    monkeypatch.setattr(facewrap.texture.bake, "BLOCK_TEXELS", 7)
    parts = rasterize_uv(mesh, 40)
    np.testing.assert_array_equal(parts.pixels, whole.pixels)
    np.testing.assert_array_equal(parts.triangles, whole.triangles)
    np.testing.assert_allclose(parts.barycentric, whole.barycentric, atol=1e-15)
    shares = []
    banded = bake_texture(mesh, scan, img, size=(40, 36), padding=3, advance=shares.append)
    assert len(shares) == 40 and sum(shares) == pytest.approx(1.0)   # a row a band
    for name in ("image", "coverage", "padded", "layout"):
        np.testing.assert_array_equal(getattr(banded, name), getattr(baked, name))
    assert banded.filled_fraction == baked.filled_fraction > 0.9


@pytest.mark.shared_data
def test_bake_real_textured_scan_onto_itself(data_dir):
    from facewrap.io.obj import read_obj
    scan = read_obj(data_dir / "scans" / "james" / "james.obj")     # UV seams, holes
    image = load_image(data_dir / "scans" / "james" / "james.jpg")
    assert image.shape == (1600, 2400, 3)
    res = bake_texture(scan, scan, image, size=256)
    assert res.filled_fraction > 0.99
    r = rasterize_uv(scan, 256)
    np.testing.assert_array_equal(r.mask, res.layout)
    expected = sample_image(image, texel_centres(256, 256)[r.pixels[:, 0], r.pixels[:, 1]])
    got = res.image[r.pixels[:, 0], r.pixels[:, 1]].astype(float)
    covered = res.coverage[r.pixels[:, 0], r.pixels[:, 1]]
    assert np.abs(got - expected)[covered].mean() < 2


def _box_raster(mesh, S, tile):
    """Reference rasteriser: every texel of each triangle's box tested, the owner the
    deepest inside, then the lowest triangle (what rasterize_uv must find, by any
    enumeration)."""
    from facewrap.texture.udim import tile_origin, triangle_tiles
    u0, v0 = tile_origin(tile)
    uv = mesh.uvs[mesh.triangle_uvs]
    X, Y = (uv[:, :, 0] - u0) * S - 0.5, (1.0 - (uv[:, :, 1] - v0)) * S - 0.5
    best = {}
    for t in np.flatnonzero(triangle_tiles(mesh) == tile):
        (x0, x1, x2), (y0, y1, y2) = X[t], Y[t]
        det = (x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0)
        if det == 0:
            continue
        cols = np.arange(max(np.ceil(X[t].min() - 1e-6), 0), min(np.floor(X[t].max() + 1e-6),
                                                                   S - 1) + 1)
        rows = np.arange(max(np.ceil(Y[t].min() - 1e-6), 0), min(np.floor(Y[t].max() + 1e-6),
                                                                   S - 1) + 1)
        col, row = np.meshgrid(cols, rows)
        dx, dy = col - x0, row - y0
        l1 = (dx * (y2 - y0) - dy * (x2 - x0)) / det
        l2 = ((x1 - x0) * dy - (y1 - y0) * dx) / det
        score = np.minimum(np.minimum(1 - l1 - l2, l1), l2)
        for r, c, sc in zip(row[score >= -1e-7], col[score >= -1e-7], score[score >= -1e-7]):
            key = (int(r), int(c))
            if key not in best or sc > best[key][0]:
                best[key] = (sc, t)
    return best


def test_rasterize_finds_the_owners_a_box_by_box_test_finds():
    # a soup of overlapping triangles, needles and slivers among them, over two tiles
    rng = np.random.default_rng(3)
    n = 60
    uvs = rng.uniform(0.02, 0.98, (3 * n, 2))
    uvs[: 3 * n // 2: 3, 0] += 1.0                      # some triangles in tile 1002
    k = np.arange(0, 30, 3)                             # needles: third corner on the line
    uvs[k + 2] = uvs[k] + 0.37 * (uvs[k + 1] - uvs[k]) + [0, 1e-4]
    V = np.column_stack([uvs, np.zeros(3 * n)])
    F = np.arange(3 * n).reshape(n, 3)
    mesh = Mesh(V, F, uvs=uvs, face_uvs=F)
    from facewrap.texture.udim import triangle_tiles
    for tile in np.unique(triangle_tiles(mesh)):
        r = rasterize_uv(mesh, 48, int(tile))
        got = {(int(a), int(b)): int(t) for (a, b), t in zip(r.pixels, r.triangles)}
        want = {key: int(t) for key, (_, t) in _box_raster(mesh, 48, int(tile)).items()}
        assert len(got) > 100 and got == want


def test_padding_takes_a_nearest_covered_colour_with_islands_at_the_borders():
    from facewrap.texture.bake import pad_texture
    rng = np.random.default_rng(5)
    S, pad = 40, 4
    image = rng.integers(0, 256, (S, S, 3), dtype=np.uint8)
    for cover in (np.zeros((S, S), bool), rng.uniform(size=(S, S)) < 0.02):
        cover[0, 3] = cover[S - 1, S - 2] = cover[17, 0] = True     # islands on the edges
        cover[20:23, 20:22] = True
        out, padded = pad_texture(image, cover, pad)
        d, _ = cKDTree(np.argwhere(cover)).query(np.argwhere(np.ones((S, S))))
        np.testing.assert_array_equal(padded, ~cover & (d.reshape(S, S) <= pad))
        np.testing.assert_array_equal(out[cover], image[cover])
        # each padded texel: the colour of a covered texel at the least distance
        covered = np.argwhere(cover)
        for r, c in np.argwhere(padded):
            dist = np.hypot(*(covered - [r, c]).T)
            nearest = covered[np.isclose(dist, dist.min())]
            assert any((out[r, c] == image[a, b]).all() for a, b in nearest)
        rest = ~cover & ~padded
        assert rest.any() and (out[rest] == np.rint(image[cover].mean(axis=0))).all()
