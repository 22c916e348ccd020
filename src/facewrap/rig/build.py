"""``build_rig``: a person's neutral scan in, their rig out (wrap, then personalise)."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.rig.personalise import personalise_shapes
from facewrap.wrapping import WrapResult, WrapSettings, wrap

__all__ = ["Rig", "build_rig"]


@dataclass(frozen=True)
class Rig:
    """A person's rig in the template's topology.

    Attributes
    ----------
    neutral : Mesh
        The template wrapped onto the person's neutral scan (the scan's frame).
    shapes : dict of str to (n, 3) float64
        The template's shapes made the person's (absolute positions).
    wrap : WrapResult
        The neutral's wrap (metrics, roles, alignment).
    method : str
        How the shapes were carried (:data:`~facewrap.rig.PERSONALISE_METHODS`).
    timings : dict
        Seconds: ``wrap``, ``shapes`` and ``total``.
    """

    neutral: Mesh
    shapes: dict
    wrap: WrapResult
    method: str
    timings: dict = field(default_factory=dict)

    def shape_mesh(self, name: str) -> Mesh:
        """Shape ``name`` as a mesh in the template's exact topology."""
        return self.neutral.with_vertices(self.shapes[name])

    def write_gltf(self, path, *, scale: float = 1.0, textures=None) -> None:
        """The neutral with every shape as a named morph target (``.glb``/``.gltf``);
        see :func:`facewrap.io.gltf.write_gltf_morphs`."""
        from facewrap.io.gltf import write_gltf_morphs
        write_gltf_morphs(path, self.neutral, self.shapes, scale=scale, name="rig",
                          textures=textures)


def build_rig(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
              scan_landmarks: Landmarks, blendshapes: dict, *,
              settings: WrapSettings | None = None, method: str = "deformation",
              anchors=None, **wrap_options) -> Rig:
    """Wrap ``template`` onto a person's neutral ``scan`` and make its shapes theirs.

    Parameters
    ----------
    template : Mesh
        The template's neutral.
    scan : Mesh
        The person's neutral scan.
    template_landmarks, scan_landmarks : Landmarks
        As for :func:`~facewrap.wrapping.wrap`.
    blendshapes : dict of str to (n, 3) float
        The template's shapes (positions in its topology): the hybrid model fits
        with them, and each is carried onto the person.
    settings : WrapSettings, optional
        Default: the hybrid model.
    method : {"deformation", "delta"}
        See :func:`~facewrap.rig.personalise_shapes`.
    anchors : (k,) int, optional
        See :func:`~facewrap.rig.personalise_shapes`.
    **wrap_options
        Passed to :func:`~facewrap.wrapping.wrap` (``exclude``, ``fit_mask``, ...).

    Returns
    -------
    Rig

    Examples
    --------
    >>> from facewrap.sample import make_scan, make_template
    >>> tpl = make_template(24)
    >>> scan = make_scan(tpl, weights={})                  # a neutral scan
    >>> rig = build_rig(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
    ...                 tpl.blendshapes)
    >>> sorted(rig.shapes) == sorted(tpl.blendshapes), rig.neutral.n_vertices
    (True, 1164)
    """
    t0 = time.perf_counter()
    settings = settings or WrapSettings(model="hybrid")
    result = wrap(template, scan, template_landmarks, scan_landmarks, settings,
                  blendshapes=blendshapes, **wrap_options)
    t1 = time.perf_counter()
    shapes = personalise_shapes(template, blendshapes, result.mesh, result.transform,
                                method=method, anchors=anchors)
    t2 = time.perf_counter()
    return Rig(result.mesh, shapes.shapes, result, method,
               {"wrap": t1 - t0, "shapes": t2 - t1, "total": t2 - t0})
