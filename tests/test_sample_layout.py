"""facewrap.sample.layout: the parameter domain and where the features lie in it."""

import numpy as np

from facewrap.sample.layout import (LANDMARK_NAMES, MOUTH_HALF_WIDTH, MOUTH_T, S_MAX, S_MIN,
                                    T_MAX, T_MIN, in_slit, landmark_layout, slit_half_height,
                                    st_from_uv, uv_from_st)


def test_uv_and_st_are_inverse_maps_of_the_domain_onto_the_unit_square():
    s = np.array([S_MIN, 0.0, S_MAX])
    t = np.array([T_MIN, 0.0, T_MAX])
    uv = uv_from_st(s, t)
    assert uv[0].tolist() == [0.0, 0.0] and uv[2].tolist() == [1.0, 1.0]
    s2, t2 = st_from_uv(uv)
    np.testing.assert_allclose(s2, s, atol=1e-12)
    np.testing.assert_allclose(t2, t, atol=1e-12)


def test_the_mouth_slit_is_a_lens_around_the_mouth_line():
    s = np.linspace(-MOUTH_HALF_WIDTH, MOUTH_HALF_WIDTH, 11)[1:-1]
    h = slit_half_height(s)
    assert np.all(h > 0) and slit_half_height(np.array([MOUTH_HALF_WIDTH + 1.0]))[0] == 0
    assert in_slit(s, np.full_like(s, MOUTH_T)).all()
    assert not in_slit(s, MOUTH_T + 1.01 * h).any()
    assert not in_slit(np.array([MOUTH_HALF_WIDTH + 1.0]), np.array([MOUTH_T])).any()


def test_landmark_layout_has_one_point_per_name_inside_the_domain():
    pts, kind = landmark_layout()
    assert pts.shape == (len(LANDMARK_NAMES), 2) and kind.shape == (len(LANDMARK_NAMES),)
    assert (S_MIN < pts[:, 0]).all() and (pts[:, 0] < S_MAX).all()
    assert (T_MIN < pts[:, 1]).all() and (pts[:, 1] < T_MAX).all()
    assert set(kind.tolist()) <= {0, 1, 2, 3, 4, 5}
