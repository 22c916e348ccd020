"""Heads of other makes than the benchmarks' (ICT's): what their shapes ask of the
roles and of the parts' following (``benchmarks/bench_other_heads.py`` measures
the whole wraps)."""

import numpy as np

from facewrap.wrapping.follow import follow_skin
from facewrap.wrapping.roles import PART, find_hidden_surface


def _grid_quads(rows, cols):
    """Triangles of a rows × cols grid of points, closed along the rows."""
    T = []
    for i in range(rows - 1):
        for j in range(cols):
            a, b = i * cols + j, i * cols + (j + 1) % cols
            T += [[a, b, b + cols], [a, b + cols, a + cols]]
    return np.array(T)


def _ball(centre, radius, rings=8, cols=16):
    """A closed UV sphere, outward: (V, T)."""
    polar = np.linspace(0, np.pi, rings + 2)[1:-1]
    a = np.linspace(0, 2 * np.pi, cols, endpoint=False)
    V = np.vstack([np.c_[np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.full(cols, np.cos(p))]
                   for p in polar] + [[[0, 0, 1]], [[0, 0, -1]]])
    n = rings * cols
    T = np.vstack([_grid_quads(rings, cols)[:, ::-1],
                   [[j, (j + 1) % cols, n] for j in range(cols)],
                   [[n - cols + (j + 1) % cols, n - cols + j, n + 1] for j in range(cols)]])
    return centre + radius * V, T


def _mask_with_socket(cols=32):
    """A face mask (a spherical cap facing +z, open at the back) whose hole at the
    front runs into a socket: a tube going back, open at its far end (a throat),
    the hole plugged by a closed part (an eyeball in its socket).
    Returns (V, T, socket vertex mask, plug vertex mask)."""
    tube_z = np.linspace(0.3, np.cos(np.radians(15)), 10)[:-1]      # back end first
    polar = np.radians(np.linspace(15, 80, 14))                      # the hole's ring first
    a = np.linspace(0, 2 * np.pi, cols, endpoint=False)
    r = np.sin(polar[0])
    tube = [np.c_[r * np.cos(a), r * np.sin(a), np.full(cols, z)] for z in tube_z]
    mask = [np.c_[np.sin(p) * np.cos(a), np.sin(p) * np.sin(a), np.full(cols, np.cos(p))]
            for p in polar]
    V = np.vstack(tube + mask)
    T = _grid_quads(len(tube) + len(mask), cols)
    rim = V[-cols:]
    n = np.cross(V[T[-1, 1]] - V[T[-1, 0]], V[T[-1, 2]] - V[T[-1, 0]])
    if n @ rim.mean(axis=0) < 0:          # the mask's normals point out of the sphere
        T = T[:, ::-1]
    socket = np.zeros(len(V), dtype=bool)
    socket[:len(tube) * cols] = True
    B, BT = _ball([0.0, 0.0, 0.85], 0.3)
    plug = np.r_[np.zeros(len(V), bool), np.ones(len(B), bool)]
    return (np.vstack([V, B]), np.vstack([T, BT + len(V)]),
            np.r_[socket, np.zeros(len(B), bool)], plug)


def test_socket_of_a_face_mask_is_not_seen_through_the_masks_open_back():
    """Cameras behind a face mask see into its socket through the open back and the
    throat: no scanner records that, so the socket's depths are a cavity, not fitted."""
    V, T, socket, plug = _mask_with_socket()
    hidden = find_hidden_surface(V, T)
    assert hidden.skin_pieces == 1 and hidden.part[plug].all()
    assert hidden.cavity[socket].mean() > 0.9
    face = ~socket & ~plug & (V[:, 2] < 0.95)        # all but the ring the plug covers
    assert not hidden.cavity[face].any()


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
