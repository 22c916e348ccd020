"""Geometry of triangle meshes: pure functions on arrays.

Everything here takes plain arrays, ``V : (n, 3) float64`` vertex positions and
``T : (t, 3) int64`` triangles (for a :class:`~facewrap.mesh.Mesh`, pass
``mesh.vertices`` and ``mesh.triangles``), never mutates them, and raises
``ValueError`` naming the argument for bad input.

Closest points and rays (:mod:`.closest`)
    :class:`ClosestPointTree` (build once, query many times), :func:`closest_points`,
    :class:`ClosestPoints`, :class:`RayHits`
Normals and areas (:mod:`.normals`)
    :func:`face_normals`, :func:`face_areas`, :func:`vertex_normals`
Connectivity (:mod:`.adjacency`)
    :func:`edges`, :func:`edges_of_polygons`, :func:`vertex_adjacency`,
    :func:`triangle_adjacency`, :func:`boundary_edges`, :func:`boundary_vertices`,
    :func:`boundary_loops`, :func:`connected_components`
Laplacians (:mod:`.laplacian`), positive semi-definite
    :func:`cotangent_laplacian`, :func:`uniform_laplacian`, :func:`mass_matrix`
Closest compatible points (:mod:`.matching`), the normalised frame (:mod:`.frames`)
    :func:`closest_compatible_points`, :func:`compatible`, :class:`Matches`,
    :class:`NormalisedFrame`
Similarity transforms (:mod:`.similarity`)
    :class:`Similarity`, :func:`similarity_transform` (Umeyama)
Triangle quality (:mod:`.quality`)
    :func:`turned`, :func:`turned_triangles`, :func:`flipped_triangles`, :func:`turned_from`,
    :func:`folded_in`
    (the one flip test), :func:`triangle_normals`, :func:`triangle_quality`,
    :class:`TriangleQuality`, :func:`triangle_to_vertex`
What an outside camera sees (:mod:`.visibility`)
    :func:`outside_views`, :func:`sphere_directions`
Sampling (:mod:`.sampling`)
    :func:`sample_surface`, :func:`farthest_point_sampling`,
    :func:`poisson_disk_vertices`

For code inside the package: argument checks at the door (:mod:`.checks`, e.g.
:func:`~.checks.as_mesh_arrays`, :func:`~.checks.mesh_arrays`) and trusted array
primitives behind it (:mod:`.arrays`; ``trusted_*`` kernels in :mod:`.normals`,
:func:`~.adjacency.adjacency_matrix`, :func:`~.adjacency.unique_edges`).
"""

from facewrap.geometry.closest import ClosestPoints, ClosestPointTree, RayHits, closest_points
from facewrap.geometry.normals import face_areas, face_normals, vertex_normals
from facewrap.geometry.adjacency import (
    boundary_edges, boundary_loops, boundary_vertices, connected_components, edges,
    edges_of_polygons, triangle_adjacency, vertex_adjacency,
)
from facewrap.geometry.laplacian import cotangent_laplacian, mass_matrix, uniform_laplacian
from facewrap.geometry.frames import NormalisedFrame
from facewrap.geometry.matching import Matches, closest_compatible_points, compatible
from facewrap.geometry.quality import (TriangleQuality, flipped_triangles, folded_in,
                                       triangle_normals,
                                       triangle_quality, triangle_to_vertex, turned,
                                       turned_from, turned_triangles)
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.geometry.sampling import (farthest_point_sampling, poisson_disk_vertices,
                                        sample_surface)
from facewrap.geometry.visibility import outside_views, sphere_directions

__all__ = [
    # closest points and rays
    "ClosestPointTree", "ClosestPoints", "RayHits", "closest_points",
    # normals and areas
    "face_normals", "face_areas", "vertex_normals",
    # connectivity
    "edges", "edges_of_polygons", "vertex_adjacency", "triangle_adjacency",
    "boundary_edges", "boundary_vertices", "boundary_loops", "connected_components",
    # Laplacians
    "cotangent_laplacian", "uniform_laplacian", "mass_matrix",
    # closest compatible points, the normalised frame
    "closest_compatible_points", "compatible", "Matches", "NormalisedFrame",
    # similarity transforms
    "Similarity", "similarity_transform",
    # triangle quality
    "turned", "turned_triangles", "turned_from", "triangle_normals", "flipped_triangles",
    "folded_in",
    "TriangleQuality", "triangle_quality",
    "triangle_to_vertex",
    # what an outside camera sees
    "outside_views", "sphere_directions",
    # sampling
    "sample_surface", "farthest_point_sampling", "poisson_disk_vertices",
]
