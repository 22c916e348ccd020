"""Textures: UV transfer between meshes and baking a scan's colours into the template's UVs."""
