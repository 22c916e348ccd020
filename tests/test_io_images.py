"""facewrap.io.images: PNG writing and image reading, with clear errors."""

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.io.images import load_image, save_png

from texture_cases import gradient_image


def test_png_round_trip_and_image_errors(tmp_path):
    rgb = gradient_image(17)
    save_png(tmp_path / "sub" / "a.png", rgb)
    np.testing.assert_array_equal(load_image(tmp_path / "sub" / "a.png"), rgb)
    rgba = gradient_image(9, channels=4)
    save_png(tmp_path / "b.png", rgba)
    np.testing.assert_array_equal(load_image(tmp_path / "b.png"), rgba[..., :3])
    grey = rgb[..., 0]
    save_png(tmp_path / "g.png", grey)
    np.testing.assert_array_equal(load_image(tmp_path / "g.png"),
                                  np.repeat(grey[..., None], 3, axis=2))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b.png", "g.png", "sub"]
    with pytest.raises(InputError, match="missing.png"):
        load_image(tmp_path / "missing.png")
    (tmp_path / "bad.png").write_bytes(b"not an image at all")
    with pytest.raises(InputError, match="bad.png"):
        load_image(tmp_path / "bad.png")
    good = (tmp_path / "sub" / "a.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(good[: len(good) // 2])
    with pytest.raises(InputError, match="cut.png"):
        load_image(tmp_path / "cut.png")
    with pytest.raises(ValueError, match="uint8"):
        save_png(tmp_path / "f.png", rgb.astype(np.float32))


def test_check_image_decodes_the_whole_file(tmp_path):
    from facewrap.io.images import check_image, png_bytes
    rng = np.random.default_rng(1)
    data = png_bytes(rng.integers(0, 256, (40, 30, 3), dtype=np.uint8))
    p = tmp_path / "a.png"
    p.write_bytes(data)
    assert check_image(p) == (30, 40)
    p.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="a.png: cannot read image"):
        check_image(p)
    with pytest.raises(InputError, match="is a folder"):
        check_image(tmp_path)


def test_grey_images_of_every_depth_read_as_8_bit_levels(tmp_path):
    from PIL import Image
    ramp = np.linspace(0.0, 1.0, 64).reshape(8, 8)
    want = np.rint(ramp * 255)
    # 16-bit grey, 32-bit float grey in [0, 1] (a renderer's), 8-bit grey with alpha
    Image.fromarray(np.rint(ramp * 65535).astype(np.uint16)).save(tmp_path / "g16.png")
    Image.fromarray(ramp.astype(np.float32)).save(tmp_path / "f32.tif")
    Image.fromarray(np.stack([want.astype(np.uint8), np.full((8, 8), 9, np.uint8)], -1),
                    "LA").save(tmp_path / "la.png")
    for name in ("g16.png", "f32.tif", "la.png"):
        image = load_image(tmp_path / name)
        assert image.shape == (8, 8, 3) and image.dtype == np.uint8
        np.testing.assert_allclose(image[:, :, 1], want, atol=1, err_msg=name)
    # float levels past 1 are 8-bit levels already; NaN is black
    levels = np.full((2, 2), 200.0, np.float32)
    levels[0, 0] = np.nan
    Image.fromarray(levels).save(tmp_path / "f255.tif")
    assert load_image(tmp_path / "f255.tif")[:, :, 0].tolist() == [[0, 200], [200, 200]]
