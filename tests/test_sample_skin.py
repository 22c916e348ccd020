"""facewrap.sample.skin: the procedural texture of a scan looks like a face."""

import numpy as np
import pytest

from facewrap.sample import make_scan, make_template
from facewrap.sample.layout import EYE_S, EYE_T, MOUTH_T, uv_from_st


@pytest.fixture(scope="module")
def tpl():
    return make_template()


def test_texture_looks_like_a_face(tpl):
    open_eyes = make_scan(tpl, weights={}, resolution=30, texture_size=256)
    shut = make_scan(tpl, weights={"blink": 1.0}, resolution=30, texture_size=256)
    tex = open_eyes.texture.astype(float)

    def at(s, t):
        u, v = uv_from_st(np.array(s), np.array(t))
        return tex[int((1 - v) * 256), int(u * 256)]
    skin, lip = at(60.0, -20.0), at(0.0, MOUTH_T + 4.0)
    brow, white = at(-33.0, 19.5), at(EYE_S + 8.0, EYE_T + 1.5)
    assert lip[0] - lip[1] > skin[0] - skin[1] + 20            # lips redder than skin
    assert brow.sum() < 0.7 * skin.sum()                         # brows darker
    assert white.min() > 200                                     # eye white
    # the socket's shadow around the eye (a face detector finds eyes by it): the
    # lids under and above the opening darker than the cheek
    under, lid = at(EYE_S, EYE_T - 6.0), at(EYE_S, EYE_T + 8.0)
    assert under.sum() < 0.85 * skin.sum() and lid.sum() < 0.92 * skin.sum()
    # in shadow beyond the landmarks' jaw line (8 mm past it), lit inside (8 mm in)
    for inside, outside in (((0.0, -90.0), (0.0, -106.0)), ((66.0, -20.0), (82.0, -20.0))):
        assert at(*outside).sum() < 0.6 * at(*inside).sum()
    a = np.array(open_eyes.texture, float)
    b = np.array(shut.texture, float)
    assert np.abs(a - b).max() > 50 and np.median(np.abs(a - b)) == 0
