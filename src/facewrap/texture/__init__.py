"""Textures: UV transfer between meshes and baking a scan's colours into the template's UVs.

Texture coordinates from the scan (:mod:`.uvs`)
    :func:`transfer_uvs`, :func:`scan_uvs_at`, :func:`cylindrical_uvs`
Baking into the template's layout (:mod:`.bake`)
    :func:`bake_texture`, :class:`BakeResult`, :func:`rasterize_uv`, :class:`UVRaster`,
    :func:`sample_image`, :func:`pad_texture`, :func:`interpolate_images`
Image files (:mod:`facewrap.io.images`, exported here too)
    :func:`load_image`, :func:`save_png`
"""

from facewrap.io.images import load_image, save_png
from facewrap.texture.bake import (BakeResult, UVRaster, bake_texture, interpolate_images,
                                   pad_texture, rasterize_uv, sample_image)
from facewrap.texture.uvs import cylindrical_uvs, scan_uvs_at, transfer_uvs

__all__ = [
    "transfer_uvs", "scan_uvs_at", "cylindrical_uvs",
    "bake_texture", "BakeResult", "rasterize_uv", "UVRaster", "sample_image",
    "pad_texture", "interpolate_images",
    "load_image", "save_png",
]
