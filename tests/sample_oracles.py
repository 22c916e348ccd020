"""Oracles for the tests of facewrap.sample, independent of the code under test."""

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def boundary_loops(T):
    """Number of boundary loops: components of the graph of edges used once."""
    e = np.sort(np.concatenate([T[:, [0, 1]], T[:, [1, 2]], T[:, [2, 0]]]), axis=1)
    edges, count = np.unique(e, axis=0, return_counts=True)
    assert count.max() <= 2, "non-manifold edge"
    b = edges[count == 1]
    if len(b) == 0:
        return 0
    verts, idx = np.unique(b, return_inverse=True)
    idx = idx.reshape(-1, 2)
    A = coo_matrix((np.ones(len(b)), (idx[:, 0], idx[:, 1])), shape=(len(verts),) * 2)
    return connected_components(A, directed=False)[0]
