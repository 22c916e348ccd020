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
    (the one flip test), :func:`adjacent_triangle_pairs`, :func:`facing_apart`,
    :func:`new_creases` (the one crease test), :func:`triangle_normals`, :func:`triangle_quality`,
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

from facewrap.lazy import lazy_exports

#: public name -> the module that defines it, imported on first use (a command that
#: needs the connectivity does not load the closest-point trees)
_PUBLIC = {
    "ClosestPoints": "facewrap.geometry.closest",
    "ClosestPointTree": "facewrap.geometry.closest",
    "RayHits": "facewrap.geometry.closest",
    "closest_points": "facewrap.geometry.closest",
    "face_areas": "facewrap.geometry.normals",
    "face_normals": "facewrap.geometry.normals",
    "vertex_normals": "facewrap.geometry.normals",
    "boundary_edges": "facewrap.geometry.adjacency",
    "boundary_loops": "facewrap.geometry.adjacency",
    "boundary_vertices": "facewrap.geometry.adjacency",
    "connected_components": "facewrap.geometry.adjacency",
    "edges": "facewrap.geometry.adjacency",
    "edges_of_polygons": "facewrap.geometry.adjacency",
    "triangle_adjacency": "facewrap.geometry.adjacency",
    "vertex_adjacency": "facewrap.geometry.adjacency",
    "cotangent_laplacian": "facewrap.geometry.laplacian",
    "mass_matrix": "facewrap.geometry.laplacian",
    "uniform_laplacian": "facewrap.geometry.laplacian",
    "NormalisedFrame": "facewrap.geometry.frames",
    "Matches": "facewrap.geometry.matching",
    "closest_compatible_points": "facewrap.geometry.matching",
    "compatible": "facewrap.geometry.matching",
    "TriangleQuality": "facewrap.geometry.quality",
    "adjacent_triangle_pairs": "facewrap.geometry.quality",
    "facing_apart": "facewrap.geometry.quality",
    "new_creases": "facewrap.geometry.quality",
    "flipped_triangles": "facewrap.geometry.quality",
    "folded_in": "facewrap.geometry.quality",
    "triangle_normals": "facewrap.geometry.quality",
    "triangle_quality": "facewrap.geometry.quality",
    "triangle_to_vertex": "facewrap.geometry.quality",
    "turned": "facewrap.geometry.quality",
    "turned_from": "facewrap.geometry.quality",
    "turned_triangles": "facewrap.geometry.quality",
    "Similarity": "facewrap.geometry.similarity",
    "similarity_transform": "facewrap.geometry.similarity",
    "farthest_point_sampling": "facewrap.geometry.sampling",
    "poisson_disk_vertices": "facewrap.geometry.sampling",
    "sample_surface": "facewrap.geometry.sampling",
    "outside_views": "facewrap.geometry.visibility",
    "sphere_directions": "facewrap.geometry.visibility",
}
lazy_exports(__name__, _PUBLIC)

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
    "folded_in", "adjacent_triangle_pairs", "facing_apart", "new_creases",
    "TriangleQuality", "triangle_quality",
    "triangle_to_vertex",
    # what an outside camera sees
    "outside_views", "sphere_directions",
    # sampling
    "sample_surface", "farthest_point_sampling", "poisson_disk_vertices",
]
