"""facewrap.report.colors: colour maps, limits and NaN colour."""

import numpy as np
import pytest

from facewrap.report import apply_colormap, colormap, render_mesh


def luminance(rgb):
    return np.asarray(rgb, float) @ [0.2126, 0.7152, 0.0722]


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
