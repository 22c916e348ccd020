"""facewrap.report.render: shading, transparency, determinism, arguments."""

import numpy as np
import pytest

from facewrap.report import render_mesh


WHITE = [255, 255, 255]


def luminance(rgb):
    return np.asarray(rgb, float) @ [0.2126, 0.7152, 0.0722]


def pointer():
    """A triangle pointing up (+y) and lying toward +x, in the z = 0 plane."""
    return np.array([[0, 0, 0], [4, 0, 0], [0, 8, 0.]]), np.array([[0, 1, 2]])


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
