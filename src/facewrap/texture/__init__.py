"""Textures: UV transfer between meshes and baking a scan's colours into the template's UVs."""

from facewrap.texture.bake import bake_texture, interpolate_images, load_image, save_png

__all__ = [
    "bake_texture", "interpolate_images", "load_image", "save_png",
]
