"""Test meshes and images shared by the tests of facewrap.texture and facewrap.io.images.

Planes with UV layouts (optionally jittered or squeezed), texel centres of an image
in the OBJ convention, and small synthetic images.
"""

import numpy as np

from facewrap.mesh import Mesh


def uv_plane(n, uv=lambda xy: xy, scale=(1.0, 1.0), jitter=0.0, seed=0):
    """Unit-square plane (z = 0) of n x n quads; UVs = uv(xy) per vertex."""
    g = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(g, g)
    xy = np.stack([X.ravel(), Y.ravel()], axis=1)
    if jitter:
        inner = (xy > 0).all(axis=1) & (xy < 1).all(axis=1)
        xy[inner] += np.random.default_rng(seed).uniform(-jitter, jitter,
                                                         (inner.sum(), 2)) / n
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    faces = np.stack([a, a + 1, a + n + 2, a + n + 1], axis=1)
    V = np.column_stack([xy * np.asarray(scale), np.zeros(len(xy))])
    return Mesh(V, faces, uvs=uv(xy), face_uvs=faces)


def texel_centres(H, W):
    r, c = np.mgrid[0:H, 0:W]
    return np.stack([(c + 0.5) / W, 1 - (r + 0.5) / H], axis=-1)  # (H, W, 2) uv


def gradient_image(S, channels=3):
    r, c = np.mgrid[0:S, 0:S]
    img = np.stack([c * 255 / (S - 1), r * 255 / (S - 1), (r + c) * 127.0 / (S - 1)], -1)
    img = np.rint(img).astype(np.uint8)
    if channels == 4:
        img = np.concatenate([img, np.full((S, S, 1), 9, np.uint8)], axis=2)
    return img


def checkerboard(S, cell=8):
    r, c = np.mgrid[0:S, 0:S]
    on = ((r // cell + c // cell) % 2).astype(bool)
    img = np.where(on[..., None], [230, 40, 90], [20, 200, 60]).astype(np.uint8)
    img[..., 2] = (np.arange(S) * 255 // (S - 1)).astype(np.uint8)[None, :]
    return img
