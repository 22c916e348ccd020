"""Image files: reading any format Pillow reads as RGB, writing PNG atomically.

Images are ``uint8`` arrays ``(H, W)`` (grey), ``(H, W, 3)`` (RGB) or ``(H, W, 4)``
(RGBA), row 0 at the top of the picture.
"""

from __future__ import annotations

import contextlib
import io
import os

import numpy as np

from facewrap.errors import InputError
from facewrap.io.atomic import atomic_write
from facewrap.io.files import not_a_file

__all__ = ["as_image", "to_uint8", "png_bytes", "save_png", "load_image", "check_image"]


def as_image(image, name: str) -> np.ndarray:
    """An image argument checked: uint8, 1 to 4 channels, not empty.

    Parameters
    ----------
    image : (H, W) or (H, W, C) uint8
        A 2-D array is taken as one grey channel.
    name : str
        The argument's name, for the error message.

    Returns
    -------
    (H, W, C) uint8
        C in (1, 3, 4); a view of ``image`` where possible.

    Raises
    ------
    ValueError
        When the dtype or the shape is wrong.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8:
        raise ValueError(f"{name} must be a uint8 image, got dtype {image.dtype}")
    if image.ndim == 2:
        image = image[:, :, None]
    if image.ndim != 3 or image.shape[2] not in (1, 3, 4):
        raise ValueError(f"{name} must have shape (H, W), (H, W, 3) or (H, W, 4), "
                         f"got {image.shape}")
    if image.shape[0] == 0 or image.shape[1] == 0:
        raise ValueError(f"{name} is empty, shape {image.shape}")
    return image


def to_uint8(values: np.ndarray) -> np.ndarray:
    """Pixel values rounded to the nearest integer and clipped to [0, 255], any shape.

    Examples
    --------
    >>> to_uint8(np.array([-3.0, 127.5, 300.0])).tolist()
    [0, 128, 255]
    """
    return np.clip(np.rint(values), 0, 255).astype(np.uint8)


def png_bytes(image) -> bytes:
    """An image encoded as PNG (for files, or to embed in a glTF).

    Parameters
    ----------
    image : (H, W), (H, W, 3) or (H, W, 4) uint8

    Examples
    --------
    >>> png_bytes(np.zeros((2, 2, 3), np.uint8))[:4]
    b'\\x89PNG'
    """
    # deferred: only image files need Pillow (start-up of every other command)
    from PIL import Image
    image = as_image(image, "image")
    if image.shape[2] == 1:
        image = image[:, :, 0]
    buf = io.BytesIO()
    # zlib's fastest level: Pillow's default (6) took 5x the time (0.37 against
    # 0.07 s) for a file 4 % smaller on a baked 1024^2 skin texture
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", compress_level=1)
    return buf.getvalue()


def save_png(path, image) -> None:
    """Write an image as PNG, atomically (complete file or none).

    Parameters
    ----------
    path : str or os.PathLike
        Destination; its folder is created when missing.
    image : (H, W), (H, W, 3) or (H, W, 4) uint8
        Grey, RGB or RGBA; row 0 is the top of the picture.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.png"
    >>> save_png(p, np.full((2, 3, 3), 7, np.uint8))
    >>> load_image(p).shape
    (2, 3, 3)
    """
    data = png_bytes(image)
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_write(path, "wb") as fh:
        fh.write(data)


def load_image(path) -> np.ndarray:
    """Read an image file (any format Pillow reads) as RGB.

    Grey and palette images are expanded to RGB, alpha is dropped, 16-bit grey is
    scaled to 8 bits, 32-bit float grey in [0, 1] to [0, 255] (levels above 1 are
    taken as 8-bit levels; NaN as 0).  No EXIF orientation is applied (textures are stored as laid
    out in UV space).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    (H, W, 3) uint8

    Raises
    ------
    InputError
        Naming the file, when it is missing, unreadable, not an image or corrupt.
    """
    # deferred: only image files need Pillow (start-up of every other command)
    from PIL import Image
    with _image_errors(path):
        with Image.open(path) as img:
            img.load()
            if img.mode in ("I", "I;16", "I;16B", "I;16L", "I;16N"):
                grey = np.asarray(img).astype(np.float64)
                grey = grey / 257.0 if grey.max(initial=0) > 255 else grey
            elif img.mode == "F":    # 32-bit float grey: levels in [0, 1], as renderers
                grey = np.nan_to_num(np.asarray(img, dtype=np.float64))   # write them
                grey = grey * 255.0 if grey.max(initial=0) <= 1.0 else grey
            else:
                return np.asarray(img.convert("RGB"), dtype=np.uint8).copy()
    return np.repeat(to_uint8(grey)[:, :, None], 3, axis=2)


def check_image(path) -> tuple[int, int]:
    """``(width, height)`` of an image file that decodes whole.

    For images that are only passed on (a report's pictures): a truncated or
    broken file is refused before any work instead of showing as a broken picture.

    Raises
    ------
    InputError
        Naming the file, as :func:`load_image` does.
    """
    from PIL import Image
    with _image_errors(path):
        with Image.open(path) as img:
            img.load()   # decodes every pixel: a truncated file fails here
            return img.size


@contextlib.contextmanager
def _image_errors(path):
    """Pillow's failures on ``path`` as one :class:`InputError` naming it."""
    from PIL import Image
    if os.path.lexists(path) and not os.path.isfile(path):
        # Pillow would open a fifo and wait for a writer forever (or read
        # /dev/zero to the memory limit): say what it is before opening it
        raise not_a_file(path)
    try:
        yield
    except FileNotFoundError:
        raise InputError("image file not found", path) from None
    except IsADirectoryError:
        raise InputError("is a folder, not an image file", path) from None
    except (OSError, ValueError, SyntaxError, Image.DecompressionBombError) as exc:
        raise InputError(f"cannot read image ({type(exc).__name__}: {exc})",
                         path) from None
