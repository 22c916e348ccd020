"""facewrap.transfer.triangle_matching: the two-phase nearest compatible triangle
search against a brute-force search."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from facewrap.transfer.triangle_matching import nearest_compatible_triangles


def _brute_nearest_compatible_triangles(qc, qn, c, nrm, k, max_distance):
    d = np.linalg.norm(qc[:, None] - c[None], axis=2)
    order = np.argsort(d, axis=1, kind="stable")[:, :k]
    out = np.full(len(qc), -1)
    for i in range(len(qc)):
        for j in order[i]:
            if d[i, j] > max_distance:
                break
            if nrm[j] @ qn[i] > 0:
                out[i] = j
                break
    return out


@pytest.mark.parametrize("max_distance", [np.inf, 0.25])
def test_nearest_compatible_equals_brute_force(max_distance):
    """Nearest-first, then k candidates only where the nearest is incompatible:
    the same as examining the k nearest for every query."""
    rng = np.random.default_rng(7)
    c = rng.uniform(size=(300, 3))
    nrm = rng.normal(size=(300, 3))
    qc = rng.uniform(size=(200, 3))
    qn = rng.normal(size=(200, 3))
    for k in (1, 4, 16):
        got = nearest_compatible_triangles(qc, qn, cKDTree(c), nrm, k, max_distance)
        want = _brute_nearest_compatible_triangles(qc, qn, c, nrm, k, max_distance)
        np.testing.assert_array_equal(got, want)
    # random normals: about half the nearest are incompatible, so both phases ran
    assert (want == -1).sum() < len(qc) // 2
