"""facewrap.report.figures: ticks, colour bars, heatmaps, sheets."""

import numpy as np
import pytest

from facewrap.report import (blendshape_sheet, colorbar, heatmap_figure, nice_ticks, render_views,
                             robust_clim, side_by_side)


def test_nice_ticks_and_robust_clim():
    assert nice_ticks(0, 1.9).tolist() == [0.0, 0.5, 1.0, 1.5]
    assert nice_ticks(0.013, 0.048).tolist() == pytest.approx([0.02, 0.03, 0.04])
    assert robust_clim(np.r_[np.linspace(0, 2, 1000), 500.0]) == (0.0, 2.0)
    assert robust_clim([-0.3, 0.05]) == (-0.3, 0.3)
    assert robust_clim([np.nan]) == (0.0, 1.0)


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
