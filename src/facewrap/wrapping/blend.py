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
from scipy.sparse import csgraph

from facewrap.geometry import edges_of_polygons, uniform_laplacian
from facewrap.mesh import Mesh
from facewrap.solve.fixed import FixedSystem

__all__ = ["extension_operator", "SmoothExtension", "smooth_extension"]


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


class SmoothExtension:
    """Smooth extensions of displacements over one mesh, as often as needed.

    Known vertices keep their displacement; the others solve ``Lᵒʳᵈᵉʳ d = 0`` with
    the known ones fixed (:class:`facewrap.solve.fixed.FixedSystem`).  Order 1 is
    harmonic (continuous), order 2 biharmonic (also smooth across the border of the
    known region).  Vertices in pieces with no known vertex keep a zero
    displacement: they are held at zero rather than solved for, so a template's
    parts (eyeballs, teeth: half the vertices of ICT's head) do not enter the
    factorisation of every extension of its skin.  The operator and its pieces are
    made once, for every extension (a fold guard or an unfolding extends again and
    again over one mesh).

    Parameters
    ----------
    mesh : Mesh
    order : {1, 2}

    Examples
    --------
    >>> from facewrap.mesh import Mesh
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0], [5, 0, 0], [6, 0, 0.]])
    >>> extend = SmoothExtension(Mesh(V, [[0, 1, 2], [3, 4, 4]]), order=1)
    >>> d = np.array([[0, 0, 0], [0, 0, 0], [3, 0, 0.], [9, 9, 9], [9, 9, 9]])
    >>> extend(d, [True, False, True, False, False]).round(6).tolist()
    [[0.0, 0.0, 0.0], [1.5, -0.0, -0.0], [3.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    """

    def __init__(self, mesh: Mesh, order: int = 2):
        self.operator = extension_operator(mesh, order)
        self._pieces = None         # the operator's connected pieces, on first need

    def __call__(self, displacement, known) -> np.ndarray:
        """Extend ``displacement`` (n, 3), given at ``known`` (n,) bool, to every
        vertex; returns (n, 3) float64."""
        d = np.array(displacement, dtype=np.float64)
        known = np.asarray(known, dtype=bool)
        unknown = ~known
        if not unknown.any():
            return d
        d[unknown] = 0.0
        if not known.any():
            return d
        if self._pieces is None:
            self._pieces = csgraph.connected_components(self.operator, directed=False)[1]
        reached = np.zeros(int(self._pieces.max()) + 1, dtype=bool)
        reached[self._pieces[known]] = True
        held = known | ~reached[self._pieces]       # known, or zero for want of any
        # a tiny ridge keeps the solve well-posed whatever the operator
        system = FixedSystem(self.operator, held, solves="few", ridge=1e-10)
        return system.solve(None, d[held])


def smooth_extension(mesh: Mesh, displacement, known, order: int = 2) -> np.ndarray:
    """Extend displacements from ``known`` vertices smoothly over the mesh: one
    :class:`SmoothExtension` (make one to extend several times over a mesh).

    Parameters
    ----------
    mesh : Mesh
    displacement : (n, 3) float
        Values at known vertices (others ignored).
    known : (n,) bool
    order : {1, 2}

    Returns
    -------
    (n, 3) float64
    """
    return SmoothExtension(mesh, order)(displacement, known)
