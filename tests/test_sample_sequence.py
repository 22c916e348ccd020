"""facewrap.sample.sequence: expression ramps of scans."""

import numpy as np
import pytest

from facewrap.sample import make_sequence, make_template


@pytest.fixture(scope="module")
def tpl():
    return make_template()


def test_sequence_ramps_the_expression(tpl):
    seq = make_sequence(tpl, frames=4, peak={"jaw_open": 1.0, "blink": 0.6},
                        resolution=30, texture_size=8, seed=3)
    assert len(seq) == 4
    np.testing.assert_allclose([s.weights["jaw_open"] for s in seq], [0, 1 / 3, 2 / 3, 1])
    np.testing.assert_allclose(seq[-1].weights["blink"], 0.6)
    assert len({s.mesh.n_vertices for s in seq}) > 1            # own topology per frame
    assert all(np.array_equal(s.transform, seq[0].transform) for s in seq)
    lm = tpl.landmarks.vertex
    gaps = [np.linalg.norm(s.ground_truth[lm[62]] - s.ground_truth[lm[66]]) for s in seq]
    assert np.all(np.diff(gaps) > 0)
    with pytest.raises(ValueError, match="peak"):
        make_sequence(tpl, frames=3, weights={"smile": 1.0})
    with pytest.raises(ValueError, match="frames"):
        make_sequence(tpl, frames=1)
