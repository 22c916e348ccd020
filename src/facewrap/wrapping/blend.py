"""Smooth extension of displacements over a template: the one blend of vertices
whose motion is not measured (unprojected ones, pinned regions, unfolding).

Known vertices keep their displacement; the others solve ``Lᵒʳᵈᵉʳ d = 0`` with
the uniform Laplacian of the template's polygon edges: harmonic (order 1:
continuous, never overshoots) or biharmonic (order 2: also smooth across the
border of the known region, so a gap follows the curvature around it).
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from facewrap.geometry import edges_of_polygons, uniform_laplacian
from facewrap.mesh import Mesh
from facewrap.solve.fixed import FixedSystem

__all__ = ["extension_operator", "smooth_extension"]


def extension_operator(mesh: Mesh, order: int = 2) -> sp.csr_matrix:
    """``Lᵒʳᵈᵉʳ`` of :func:`smooth_extension`: the uniform Laplacian of the polygon
    edges (quads are not biased by their diagonals), squared for order 2.

    Returns
    -------
    (n, n) scipy.sparse.csr_matrix
    """
    E = edges_of_polygons(mesh.face_offsets, mesh.face_indices)
    L = uniform_laplacian(E, mesh.n_vertices)
    return (L if order == 1 else (L @ L)).tocsr()


def smooth_extension(mesh: Mesh, displacement, known, order: int = 2, *,
                     operator=None) -> np.ndarray:
    """Extend displacements from ``known`` vertices smoothly over the mesh.

    Solves ``Lᵒʳᵈᵉʳ d = 0`` on the unknown vertices with the known ones fixed
    (:class:`facewrap.solve.fixed.FixedSystem`).  Order 1 is harmonic
    (continuous), order 2 biharmonic (also smooth across the border of the known
    region).  Vertices in pieces with no known vertex keep a zero displacement.

    Parameters
    ----------
    mesh : Mesh
    displacement : (n, 3) float
        Values at known vertices (others ignored).
    known : (n,) bool
    order : {1, 2}
    operator : (n, n) scipy.sparse matrix, optional
        :func:`extension_operator` of ``mesh`` and ``order``, when the caller
        extends several times over one mesh.

    Returns
    -------
    (n, 3) float64
    """
    d = np.array(displacement, dtype=np.float64)
    known = np.asarray(known, dtype=bool)
    unknown = ~known
    if not unknown.any():
        return d
    d[unknown] = 0.0
    if not known.any():
        return d
    K = extension_operator(mesh, order) if operator is None else operator
    # a tiny ridge keeps pieces without known vertices well-posed (they stay at 0)
    system = FixedSystem(K, known, solves="few", ridge=1e-10)
    return system.solve(None, d[known])
