"""Pictures of meshes and results, rendered headlessly (no GPU, no display).

Rendering (:mod:`.render`): a vectorised numpy software rasteriser, deterministic
and free of system dependencies
    :func:`render_mesh`
Cameras (:mod:`.cameras`)
    :func:`view_rotation`, :func:`frame_from_axes`, :func:`fit_pixel_size`, :data:`VIEWS`
The z-buffer (:mod:`.raster`)
    :func:`rasterize`, :class:`Raster`
Colours (:mod:`.colors`)
    :func:`colormap`, :func:`apply_colormap`, :data:`COLORMAPS`
Figures (:mod:`.figures`): text, colour bars, grids
    :func:`heatmap_figure`, :func:`render_views`, :func:`side_by_side`,
    :func:`image_grid`, :func:`blendshape_sheet`, :func:`colorbar`,
    :func:`nice_ticks`, :func:`robust_clim`
Files
    :func:`save_png` (atomic PNG writer of :mod:`facewrap.texture.bake`)

Examples
--------
>>> from facewrap.sample import make_template
>>> tpl = make_template(24)
>>> img = heatmap_figure(tpl.mesh, tpl.mesh.vertices[:, 2], units="mm",
...                      title="depth", size=(120, 140))
>>> img.dtype.name, img.shape[2]
('uint8', 3)
"""

from facewrap.texture import save_png
from facewrap.report.figures import (blendshape_sheet, colorbar, heatmap_figure, image_grid,
                                     nice_ticks, render_views, robust_clim, side_by_side)
from facewrap.report.cameras import VIEWS, fit_pixel_size, frame_from_axes, view_rotation
from facewrap.report.colors import COLORMAPS, apply_colormap, colormap
from facewrap.report.raster import Raster, rasterize
from facewrap.report.render import render_mesh

from facewrap.report.html import write_html_report

__all__ = [
    # rendering
    "render_mesh", "rasterize", "Raster", "view_rotation", "frame_from_axes",
    "fit_pixel_size", "VIEWS",
    # colours
    "colormap", "apply_colormap", "COLORMAPS",
    # figures
    "heatmap_figure", "render_views", "side_by_side", "image_grid", "blendshape_sheet",
    "colorbar", "nice_ticks", "robust_clim",
    # files
    "save_png",
    "write_html_report",
]
