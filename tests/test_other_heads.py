"""Heads of other makes than the benchmarks' (ICT's): what their shapes ask of the
roles and of the parts' following (``benchmarks/bench_other_heads.py`` measures
the whole wraps)."""

import numpy as np

from facewrap.wrapping.follow import follow_skin
from facewrap.wrapping.roles import PART


def _slit_patch():
    """A 5 × 5 skin patch cut along its middle row's inner edge (the lips of a
    closed mouth: two vertices at each point of the slit) and a part beneath."""
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    V = np.c_[g, np.zeros(25)]
    T = np.array([[i, i + 1, i + 6] for i in range(19) if i % 5 < 4]
                 + [[i, i + 6, i + 5] for i in range(19) if i % 5 < 4])
    copies = {11: 25, 12: 26, 13: 27}        # the lower lip's copies of the slit row
    lower = np.isin(T, [1, 2, 3, 6, 7, 8]).any(axis=1)     # triangles below row 2
    T[lower] = np.vectorize(lambda v: copies.get(v, v))(T[lower])
    V = np.vstack([V, V[[11, 12, 13]], [[2.0, 2.0, -0.5], [2.5, 2.0, -0.5]]])
    roles = np.zeros(len(V), np.int8)
    roles[28:] = PART
    return V, T, roles


def test_parts_follow_a_skin_with_two_vertices_at_one_point():
    """Teeth behind closed lips whose two rows of vertices share their positions:
    the parts follow (the warp's anchors at one point count once)."""
    V, T, roles = _slit_patch()
    fit = V + [0.0, 0.0, 3.0]
    fit[26] += [0.0, 0.0, 0.2]                 # the fit parted the lips a little
    out = follow_skin(T, V, fit, roles)
    assert np.all(np.abs(out[28:, 2] - 2.5) < 0.2)
