"""Templates split at their seams, fitted as one surface.

A production head exported with its vertices split where the UVs (or hard
normals) are cut has two or more copies of every seam vertex: the same point,
unconnected.  Fitted as they are, the two sides of a seam are two pieces to the
deformation graph (its geodesics stop at the cut), to the smoothness terms, the
normals and the projection's blend, and the result cracks open along the seam
(the built-in sample split down the middle: 0.8 mm with the hybrid model, 3.2 mm
with the graph).  :func:`seam_weld` finds the copies — vertices equal bit for bit
in the template and in every blendshape, so the upper and lower lip of a closed
mouth, which part in an expression, stay apart — and :class:`SeamWeld` maps a
wrap's inputs onto the welded template and its result back onto the template's
own vertices, every copy where its vertex went.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from facewrap.geometry.adjacency import boundary_edges
from facewrap.geometry.arrays import unique_integers
from facewrap.geometry.duplicates import any_duplicate_positions, duplicate_rows
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh

__all__ = ["SeamWeld", "seam_weld"]


@dataclass(frozen=True, eq=False)
class SeamWeld:
    """A template with its seam copies merged.

    Attributes
    ----------
    mesh : Mesh
        The welded mesh: ``u`` vertices, the template's faces in order.
    keep : (u,) int64
        The template vertex each welded vertex is (the first copy).
    inverse : (n,) int64
        The welded vertex of each template vertex.
    """
    mesh: Mesh
    keep: np.ndarray
    inverse: np.ndarray

    @property
    def merged(self) -> int:
        """How many template vertices are copies of another."""
        return len(self.inverse) - len(self.keep)

    def vertex_set(self, chosen):
        """A set of template vertices (``(n,)`` bool or ids; None) as welded ones:
        a welded vertex belongs when any of its copies does."""
        if chosen is None:
            return None
        chosen = np.asarray(chosen)
        mask = np.zeros(len(self.inverse), dtype=bool)
        mask[chosen] = True          # a bool mask indexes itself, ids set theirs
        out = np.zeros(len(self.keep), dtype=bool)
        out[self.inverse[mask]] = True
        return out

    def landmarks(self, landmarks: Landmarks) -> Landmarks:
        """Template landmarks on the welded mesh (triangles keep their ids)."""
        v = np.asarray(landmarks.vertex)
        return Landmarks(np.where(v >= 0, self.inverse[np.maximum(v, 0)], -1),
                         landmarks.triangle, landmarks.barycentric, landmarks.points,
                         names=landmarks.names)

    def shapes(self, shapes: dict | None) -> dict | None:
        """Blendshapes on the welded vertices."""
        if shapes is None:
            return None
        return {k: np.asarray(v)[self.keep] for k, v in shapes.items()}

    def unweld(self, result, template: Mesh):
        """A wrap result of the welded mesh, on ``template``'s own vertices."""
        inv = self.inverse
        projection = result.projection
        if projection is not None:
            projection = replace(projection, **{
                f: getattr(projection, f)[inv] for f in
                ("vertices", "projected", "triangles", "barycentric", "method", "distances")})
        metrics = dict(result.metrics, seam_copies_welded=self.merged)
        return replace(result, mesh=template.with_vertices(result.mesh.vertices[inv]),
                       warped=result.warped[inv], projection=projection,
                       roles=None if result.roles is None else result.roles[inv],
                       metrics=metrics)


def seam_weld(template: Mesh, blendshapes: dict | None = None) -> SeamWeld | None:
    """The template's seam copies merged, or None when it has none.

    Parameters
    ----------
    template : Mesh
    blendshapes : dict name -> (n, 3) float, optional
        Copies must also agree in every shape.

    Returns
    -------
    SeamWeld or None

    Examples
    --------
    >>> V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 0], [0, 1, 0.]])
    >>> weld = seam_weld(Mesh(V, [[0, 1, 2], [4, 3, 5]]))   # two triangles, cut apart
    >>> weld.merged, weld.mesh.triangles.tolist()
    (2, [[0, 1, 2], [1, 3, 2]])
    """
    V = template.vertices
    if not any_duplicate_positions(V):
        return None
    rows = V if not blendshapes else np.hstack(
        [V] + [np.asarray(s, dtype=np.float64) for s in blendshapes.values()])
    first, inverse = duplicate_rows(rows)
    # copies whose faces carry other materials are parts that touch (ICT's eye
    # occlusion on the eyelids' rims, 122 of its 123 groups); copies that do not
    # run along a cut (two border edges between the same two points) touch at a
    # point (three of ICT's lashes at one tip): each stays itself.  Splitting
    # groups can leave a neighbour without its twin edge: until nothing changes.
    alone = np.zeros(len(V), dtype=bool)                     # copies kept apart
    while len(first) < len(V):
        weldable = (_one_material(template, inverse)                 # per copy group
                    & _along_cut_edges(template.triangles, inverse)
                    | (np.bincount(inverse) == 1))                   # (lone vertices)
        if weldable.all():
            break
        alone |= ~weldable[inverse]
        tag = np.where(alone, np.arange(len(V)), -1).astype(np.float64)
        first, inverse = duplicate_rows(np.column_stack([rows, tag]))
    if len(first) == len(V):
        return None
    # welded vertices in the template's order (the first copy's place)
    order = np.argsort(first, kind="stable")
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    keep, inverse = first[order], rank[inverse]
    # the template's own faces (polygons stay polygons: the fit's smoothing and
    # unfolding follow their edges) and texture coordinates, on the welded vertices
    offsets = template.face_offsets
    welded = Mesh(V[keep], (offsets, inverse[template.face_indices]),
                  uvs=template.uvs,
                  face_uvs=None if template.uvs is None else (offsets, template.face_uvs))
    return SeamWeld(welded, keep, inverse)


def _one_material(template: Mesh, groups: np.ndarray) -> np.ndarray:
    """(g,) bool: the copy groups (``groups`` (n,): each vertex's) all of whose
    faces carry one material (every group, for a template without materials)."""
    g = int(groups.max()) + 1
    if template.face_materials is None or len(template.materials) < 2:
        return np.ones(g, dtype=bool)
    corner_face = np.repeat(np.arange(template.n_faces), np.diff(template.face_offsets))
    material = template.face_materials[corner_face]
    lo = np.full(g, np.iinfo(np.int64).max)
    hi = np.full(g, np.iinfo(np.int64).min)
    np.minimum.at(lo, groups[template.face_indices], material)
    np.maximum.at(hi, groups[template.face_indices], material)
    return lo == hi


def _along_cut_edges(T: np.ndarray, groups: np.ndarray) -> np.ndarray:
    """(g,) bool: copy groups all of whose copies end a border edge that another
    border edge between the same two points twins (a cut through a surface)."""
    g = int(groups.max()) + 1
    B = boundary_edges(T)
    if not len(B):
        return np.zeros(g, dtype=bool)
    ends = np.sort(groups[B], axis=1)
    _, inverse, counts = unique_integers(ends[:, 0] * g + ends[:, 1], return_inverse=True,
                                         return_counts=True)
    on_cut = np.zeros(len(groups), dtype=bool)
    on_cut[B[counts[inverse] > 1].ravel()] = True
    every = np.ones(g, dtype=bool)
    np.logical_and.at(every, groups, on_cut)
    return every
