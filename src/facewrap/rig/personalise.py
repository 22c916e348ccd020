"""A template's blendshapes made into one person's: same topology, their face.

The wrap of a person's neutral scan gives the template's topology in the shape of
their face.  Each template shape is then carried onto it:

- ``"deformation"`` (default): deformation transfer (Sumner and Popović 2004, SPEC
  §3) from the template's neutral to the person's, triangle to triangle.  Each
  template triangle's deformation from neutral to shape is applied to the person's
  triangle and the positions are solved for in the least-squares sense; with the
  same topology on both sides the system is factored once and every shape costs
  one back-substitution.  A smile is carried as the same stretch and turn of each
  patch of skin, whatever that patch's size and slope on this face.
- ``"delta"``: the template's displacement added as it is (rotated and scaled into
  the person's frame).  Right for a model built as neutral plus displacements, and
  the baseline the benchmark measures the transfer against.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from facewrap.geometry.checks import as_shape_dict, as_vertex_ids
from facewrap.geometry.similarity import Similarity
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import Options, expect_instance, validate
from facewrap.rig.stabilise import least_moving
from facewrap.transfer import Correspondence, DeformationTransfer

__all__ = ["PERSONALISE_METHODS", "PersonalisedShapes", "personalise_shapes"]

#: how template shapes are carried onto a person's neutral
PERSONALISE_METHODS = ("deformation", "delta")


@dataclass(frozen=True)
class PersonalisedShapes:
    """Shapes in a person's frame and face.

    Attributes
    ----------
    shapes : dict of str to (n, 3) float64
        Shape name → vertex positions (absolute), in the person's neutral frame.
    method : str
        One of :data:`PERSONALISE_METHODS`.
    timings : dict
        Seconds: ``factor`` (the transfer's system, once) and ``shapes`` (all of them).
    """

    shapes: dict
    method: str
    timings: dict = field(default_factory=dict)


@dataclass(frozen=True)
class _Method:
    method: str = "deformation"
    constraints = {"method": Options(*PERSONALISE_METHODS)}

    def __post_init__(self):
        validate(self)


def _same_topology(template: Mesh, anchors) -> Correspondence:
    """Triangle ``j`` of the template to triangle ``j`` of the person's neutral."""
    t = np.arange(len(template.triangles), dtype=np.int64)
    anchors = np.asarray(anchors, dtype=np.int64)
    n = template.n_vertices
    return Correspondence(t, t.copy(), n, len(t), n, len(t), np.c_[anchors, anchors],
                          template.vertices.copy(), "source",
                          {"kind": "same topology"})


def personalise_shapes(template: Mesh, shapes: dict, person: Mesh, similarity: Similarity,
                       *, method: str = "deformation", anchors=None) -> PersonalisedShapes:
    """Carry ``shapes`` of ``template`` onto ``person`` (the template wrapped onto them).

    Parameters
    ----------
    template : Mesh
        The template's neutral, in its own frame.
    shapes : dict of str to (n, 3) float
        Its shapes (positions, the template's topology and frame).
    person : Mesh
        The template wrapped onto the person's neutral scan (same topology, the
        scan's frame).
    similarity : Similarity
        The template → scan alignment of that wrap (``WrapResult.transform``): the
        shapes are carried in the scan's frame and units.
    method : {"deformation", "delta"}
        See the module's description.
    anchors : (k,) int, optional
        Vertices whose mean motion the transferred shapes keep (deformation
        transfer fixes positions only up to a translation): ICT-FaceKit's
        skull-rigid vertices, say.  Default: the tenth of the vertices that move
        least over all the shapes (the skull's, in a face rig).

    Returns
    -------
    PersonalisedShapes

    Examples
    --------
    A person who is the template scaled and moved gets its shapes scaled and moved:

    >>> from facewrap.sample import make_template
    >>> tpl = make_template(20)
    >>> face, _ = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    >>> open_ = face.vertices + [0.0, 0.0, 1.0] * (face.vertices[:, 1:2] < 0)
    >>> s = Similarity(np.eye(3), np.array([5.0, 0, 0]), 2.0)
    >>> out = personalise_shapes(face, {"open": open_}, face.with_vertices(
    ...     s.apply(face.vertices)), s)
    >>> bool(np.allclose(out.shapes["open"], s.apply(open_), atol=1e-6))
    True
    """
    _Method(method)
    check_mesh(template, "template")
    check_mesh(person, "person")
    if person.n_vertices != template.n_vertices:
        raise ValueError(f"person must be the template wrapped onto them ({template.n_vertices} "
                         f"vertices), got {person.n_vertices} vertices")
    shapes = as_shape_dict(shapes, template.n_vertices, "shapes")
    expect_instance(similarity, Similarity, "similarity")
    t0 = time.perf_counter()
    names = list(shapes)
    aligned = similarity.apply(template.vertices)
    poses = np.stack([similarity.apply(shapes[k]) for k in names]) if names \
        else np.zeros((0, template.n_vertices, 3))
    if method == "delta":
        out = person.vertices[None] + (poses - aligned[None])
        return PersonalisedShapes(dict(zip(names, out)), method,
                                  {"factor": 0.0, "shapes": time.perf_counter() - t0})
    anchors = (least_moving(poses, aligned) if anchors is None
               else as_vertex_ids(anchors, template.n_vertices, "anchors"))
    source = template.with_vertices(aligned)
    # one anchor vertex fixes the solve's translation; the anchors' mean then sets it
    transfer = DeformationTransfer(anchor=int(anchors[0]), fix_flips=False).fit(
        source, person, _same_topology(template, anchors))
    t1 = time.perf_counter()
    out = transfer.transfer(poses) if names else poses
    # the anchors' mean moves as the template's does: the same face-sized shapes, in
    # the same frame
    drift = ((out[:, anchors] - person.vertices[anchors]).mean(axis=1)
             - (poses[:, anchors] - aligned[anchors]).mean(axis=1))
    out = out - drift[:, None, :]
    return PersonalisedShapes(dict(zip(names, out)), method,
                              {"factor": t1 - t0, "shapes": time.perf_counter() - t1})
