"""Pictures: the rasteriser, cameras, colour maps, shading and figures."""


import numpy as np
import pytest

from facewrap.report import (apply_colormap, blendshape_sheet, colorbar, colormap,
                             frame_from_axes, heatmap_figure, nice_ticks, rasterize,
                             render_mesh, render_views, robust_clim, side_by_side,
                             view_rotation)

WHITE = [255, 255, 255]


def inside_oracle(xy, T, W, H):
    """Brute force: pixel centres inside any triangle (either orientation)."""
    cx, cy = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    P = np.stack([cx.ravel(), cy.ravel()], 1)
    covered = np.zeros(len(P), bool)
    for a, b, c in xy[np.asarray(T)]:
        def edge(p, q):
            return (q[0] - p[0]) * (P[:, 1] - p[1]) - (q[1] - p[1]) * (P[:, 0] - p[0])
        e = np.stack([edge(a, b), edge(b, c), edge(c, a)], 1)
        covered |= (e >= -1e-9).all(1) | (e <= 1e-9).all(1)
    return covered.reshape(H, W)


def luminance(rgb):
    return np.asarray(rgb, float) @ [0.2126, 0.7152, 0.0722]


# -- z-buffer --------------------------------------------------------------------------------

def test_known_triangle_covers_the_expected_pixels():
    xy = np.array([[1.2, 0.7], [13.9, 3.1], [4.4, 11.6]])
    for T in ([[0, 1, 2]], [[0, 2, 1]]):                   # both orientations drawn
        r = rasterize(xy, np.zeros(3), T, (16, 12))
        assert np.array_equal(r.mask, inside_oracle(xy, T, 16, 12))
        assert np.allclose(r.barycentric.sum(1), 1) and (r.barycentric >= 0).all()
    # barycentric coordinates reproduce the pixel centres
    px = np.stack([r.pixels % 16 + 0.5, r.pixels // 16 + 0.5], 1)
    assert np.allclose(r.barycentric @ xy[[0, 2, 1]], px, atol=1e-4)


def test_nearer_triangle_wins_whatever_the_order():
    xy = np.array([[0, 0], [10, 0], [0, 10], [0, 0], [10, 0], [0, 10.]])
    for depth in ([1, 1, 1, 0, 0, 0], [0, 0, 0, 1, 1, 1]):
        r = rasterize(xy, depth, [[0, 1, 2], [3, 4, 5]], (10, 10))
        near = 1 if depth[0] == 1 else 0
        assert set(np.unique(r.triangle[r.mask])) == {near}
    # exact tie: the lower triangle index
    r = rasterize(xy, np.zeros(6), [[3, 4, 5], [0, 1, 2]], (10, 10))
    assert set(np.unique(r.triangle[r.mask])) == {0}


def test_shared_edges_leave_no_crack():
    rng = np.random.default_rng(3)
    n = 9
    s = np.linspace(0, 40, n)
    X, Y = np.meshgrid(s, s)
    xy = np.stack([X.ravel(), Y.ravel()], 1)
    xy[(xy > 0).all(1) & (xy < 40).all(1)] += rng.uniform(-1.5, 1.5, (49, 2))
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)).ravel()
    T = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    r = rasterize(xy, rng.uniform(0, 1, len(xy)), T, (40, 40))
    assert r.mask.all()


def test_rasterize_validates():
    with pytest.raises(ValueError, match="xy"):
        rasterize(np.zeros((3, 3)), np.zeros(3), [[0, 1, 2]], (4, 4))
    with pytest.raises(ValueError, match="size"):
        rasterize(np.zeros((3, 2)), np.zeros(3), [[0, 1, 2]], (0, 4))


# -- cameras and orientation ------------------------------------------------------------------

def test_view_rotations_are_rotations_and_views_point_right():
    for v in ("front", "side", "three_quarter", (20.0, -30.0)):
        R = view_rotation(v)
        assert np.allclose(R @ R.T, np.eye(3)) and np.linalg.det(R) == pytest.approx(1)
    assert np.allclose(view_rotation("front"), np.eye(3))
    assert np.allclose(view_rotation("top") @ [0, 1, 0], [0, 0.017452, 0.999848], atol=1e-5)
    with pytest.raises(ValueError, match="view"):
        view_rotation("diagonal")
    F = frame_from_axes(up=(0, 0, 1), front=(1, 0, 0))
    assert np.allclose(F @ [1, 0, 0], [0, 0, 1]) and np.allclose(F @ [0, 0, 1], [0, 1, 0])
    with pytest.raises(ValueError, match="parallel"):
        frame_from_axes(up=(0, 0, 1), front=(0, 0, 2))


def pointer():
    """A triangle pointing up (+y) and lying toward +x, in the z = 0 plane."""
    return np.array([[0, 0, 0], [4, 0, 0], [0, 8, 0.]]), np.array([[0, 1, 2]])


def test_front_view_has_y_up_and_x_right():
    V, T = pointer()
    img = render_mesh((V, T), size=(40, 40), supersample=1)
    covered = (img != 255).any(2)
    rows, cols = np.nonzero(covered)
    # the tip (0, 8) is at the top left; the wide end at the bottom
    top = rows.min()
    assert cols[rows == top].mean() < 20 and covered[rows.max()].sum() > covered[top].sum()
    assert covered[:, :20].sum() > covered[:, 20:].sum()


def test_side_view_sees_the_face_toward_the_left():
    # a nose sticking out toward +z on a plane: from the side it points left
    V = np.array([[0, -5, 0], [0, 5, 0], [0, 0, 8.], [0.1, 0, 0]])
    T = [[0, 1, 2], [0, 1, 3]]
    img = render_mesh((V, T), view="side", size=(40, 40), supersample=1)
    cols = np.nonzero((img != 255).any(2))[1]
    assert cols.min() < 8 and cols.max() > 30   # spans width: tip at left, base right
    covered = (img != 255).any(2)
    tip_rows = np.nonzero(covered[:, cols.min()])[0]
    assert abs(tip_rows.mean() - 19.5) < 3


# -- colours ------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["viridis", "inferno", "magma", "greys"])
def test_sequential_colormaps_are_monotone_in_lightness(name):
    L = luminance(colormap(name, 256))
    assert np.all(np.diff(L) > 0)
    assert np.allclose(colormap(name + "_r"), colormap(name)[::-1])


def test_apply_colormap_clips_and_greys_nan():
    c = apply_colormap([-1.0, 0.0, 0.5, 1.0, 7.0, np.nan], "viridis", (0, 1),
                       nan_color=(0.5, 0.5, 0.5))
    lut = colormap("viridis")
    assert np.allclose(c[0], lut[0]) and np.allclose(c[4], lut[-1])
    assert np.allclose(c[5], 0.5)
    with pytest.raises(ValueError, match="cmap"):
        colormap("jet")


def test_heatmap_colours_are_monotone_in_value():
    # a flat strip facing the camera, value = x: rendered lightness grows with x
    n = 41
    x = np.linspace(0, 10, n)
    V = np.concatenate([np.stack([x, np.zeros(n), np.zeros(n)], 1),
                        np.stack([x, np.ones(n), np.zeros(n)], 1)])
    i = np.arange(n - 1)
    T = np.concatenate([np.stack([i, i + 1, i + n + 1], 1), np.stack([i, i + n + 1, i + n], 1)])
    img = render_mesh((V, T), scalars=V[:, 0], size=(200, 40), supersample=1,
                      background=None)
    row = img[20]
    seen = row[:, 3] == 255
    L = luminance(row[seen, :3])
    assert seen.sum() > 150
    assert np.all(np.diff(L) >= -0.5) and L[-1] - L[0] > 100


def test_nice_ticks_and_robust_clim():
    assert nice_ticks(0, 1.9).tolist() == [0.0, 0.5, 1.0, 1.5]
    assert nice_ticks(0.013, 0.048).tolist() == pytest.approx([0.02, 0.03, 0.04])
    assert robust_clim(np.r_[np.linspace(0, 2, 1000), 500.0]) == (0.0, 2.0)
    assert robust_clim([-0.3, 0.05]) == (-0.3, 0.3)
    assert robust_clim([np.nan]) == (0.0, 1.0)


# -- shading and images --------------------------------------------------------------

def test_render_is_deterministic_and_png_bytes_repeat(tmp_path):
    from facewrap.report import save_png
    from facewrap.sample import make_template
    tpl = make_template(24)
    a = render_mesh(tpl.mesh, view="three_quarter", size=(120, 140))
    b = render_mesh(tpl.mesh, view="three_quarter", size=(120, 140))
    assert a.shape == (140, 120, 3) and a.dtype == np.uint8 and np.array_equal(a, b)
    save_png(tmp_path / "a.png", a)
    save_png(tmp_path / "b.png", b)
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()
    assert a[0, 0].tolist() == WHITE and (a != 255).any(2).mean() > 0.2


def test_transparent_background_and_antialiased_edges():
    V, T = pointer()
    img = render_mesh((V, T), size=(40, 40), background=None)
    assert img.shape == (40, 40, 4) and img[0, -1, 3] == 0
    alpha = img[:, :, 3]
    assert (alpha == 255).sum() > 50 and ((alpha > 0) & (alpha < 255)).sum() > 10
    hard = render_mesh((V, T), size=(40, 40), background=None, supersample=1)
    assert set(np.unique(hard[:, :, 3])) == {0, 255}


def test_lighting_darkens_surfaces_turned_away():
    # two facets of a roof: the one facing the key light (upper left) is brighter
    V = np.array([[-1, 0, 0], [0, 0, 1], [0, 1, 1], [-1, 1, 0], [1, 0, 0], [1, 1, 0.]])
    T = [[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]]
    img = render_mesh((V, T), size=(60, 30), smooth=False, supersample=1)
    left, right = luminance(img[15, 10]), luminance(img[15, 50])
    assert left > right + 10


def test_render_validates_arguments():
    V, T = pointer()
    with pytest.raises(ValueError, match="scalars"):
        render_mesh((V, T), scalars=[1.0, 2.0])
    with pytest.raises(ValueError, match="supersample"):
        render_mesh((V, T), supersample=0)
    with pytest.raises(ValueError, match="background"):
        render_mesh((V, T), background="chartreuse")
    with pytest.raises(ValueError, match="mesh"):
        render_mesh(V)


def test_per_triangle_scalars_and_vertex_colors():
    V, T = pointer()
    img = render_mesh((V, T), scalars=[np.nan], size=(20, 20), supersample=1,
                      nan_color=(1.0, 0.0, 0.0))
    covered = (img != 255).any(2)
    assert (img[covered][:, 0] > img[covered][:, 1]).all()
    img = render_mesh((V, T), colors=np.array([[0, 0, 255]] * 3, np.uint8), size=(20, 20))
    c = img[(img != 255).any(2)]
    assert (c[:, 2] >= c[:, 0]).all()


# -- figures ---------------------------------------------------------------------------

def test_colorbar_runs_from_high_at_top_to_low_at_bottom():
    img = colorbar("greys", (0, 1), height=200, units="mm", label="error")
    mid = img[70:130, 16, 0].astype(int)              # middle of the bar, top to bottom
    assert np.all(np.diff(mid) <= 0) and mid[0] - mid[-1] > 50   # greys: high at top
    with pytest.raises(ValueError, match="extend"):
        colorbar(extend="up")


def test_heatmap_side_by_side_and_sheet_shapes():
    from facewrap.sample import make_template
    tpl = make_template(24)
    V = tpl.mesh.vertices
    fig = heatmap_figure(tpl.mesh, V[:, 1] - V[:, 1].mean(), title="height", units="mm",
                         caption="a caption", size=(100, 120))
    assert fig.ndim == 3 and fig.shape[1] > 3 * 100 and fig.shape[0] > 120
    pics = render_views([tpl.mesh, tpl.mesh.with_vertices(V * 0.5)], "front",
                        size=(60, 70))
    # one scale for both: the half-size head covers about a quarter of the pixels
    cover = [(p != 255).any(2).mean() for p in pics]
    assert cover[1] == pytest.approx(cover[0] / 4, rel=0.15)
    row = side_by_side(pics, ["before", "after"], gap=5)
    assert row.shape[1] == 2 * 60 + 3 * 5
    shapes = {k: tpl.blendshapes[k] for k in ("jaw_open", "blink")}
    sheet = blendshape_sheet(tpl.mesh, shapes, columns=2, cell_size=(60, 70),
                             color_by_offset=True)
    assert sheet.shape[0] > 2 * 70
    with pytest.raises(ValueError, match="jaw"):
        blendshape_sheet(tpl.mesh, {"jaw": V[:10]})
    with pytest.raises(ValueError, match="labels"):
        side_by_side(pics, ["one"])
