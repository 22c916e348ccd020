"""Wrapping: fit a template onto a scan, keeping the template's topology (SPEC §1–§2).

The modules, in the order data flows through them:

* :mod:`.settings` — :class:`WrapSettings` and its table of allowed values;
* :mod:`.align` — trimmed rigid ICP (the landmark similarity is
  :mod:`facewrap.geometry.similarity`);
* :mod:`.models` — how the template may move (rigid, rbf, affine, graph,
  blendshape, hybrid): one module each and the registry of them;
* :mod:`.icp` — the non-rigid ICP engine, its schedule and energy terms;
* :mod:`.model_fit` — the coarse pre-fit and ICP fit of a wrap;
* :mod:`.warp` — the landmark RBF warp and the landmark pull;
* :mod:`.roles` — which template vertices the scan pulls and which follow (parts,
  cavities, the user's exclusions and pins);
* :mod:`.projection` — projection onto the scan along normals;
* :mod:`.stages` — :func:`wrap`, the named stages over all of the above;
* :mod:`.track` — 4D sequences, each frame warm-started from the previous one.
"""

from facewrap.lazy import lazy_exports

#: public name -> the module that defines it, imported on first use
_PUBLIC = {
    "Stage": "facewrap.wrapping.icp.schedule",
    "MODEL_REGISTRY": "facewrap.wrapping.models",
    "default_schedule": "facewrap.wrapping.models",
    "DEFAULT_GRAPH_CACHE": "facewrap.wrapping.models.graph",
    "GraphCache": "facewrap.wrapping.models.graph",
    "VERTEX_ROLES": "facewrap.wrapping.roles",
    "find_hidden_surface": "facewrap.wrapping.roles",
    "role_ranges": "facewrap.wrapping.roles",
    "MODELS": "facewrap.wrapping.settings",
    "WrapSettings": "facewrap.wrapping.settings",
    "WrapResult": "facewrap.wrapping.stages",
    "fit_metrics": "facewrap.wrapping.stages",
    "wrap": "facewrap.wrapping.stages",
    "track": "facewrap.wrapping.track",
    "write_track_outputs": "facewrap.wrapping.track",
}
lazy_exports(__name__, _PUBLIC)

__all__ = ["wrap", "WrapSettings", "WrapResult", "MODELS", "MODEL_REGISTRY",
           "track", "write_track_outputs", "Stage", "default_schedule", "fit_metrics",
           "GraphCache", "DEFAULT_GRAPH_CACHE", "VERTEX_ROLES", "find_hidden_surface",
           "role_ranges"]
