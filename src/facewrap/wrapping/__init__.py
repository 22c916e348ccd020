"""Wrapping: fit a template onto a scan, keeping the template's topology (SPEC §1–§2).

The stages, in the order data flows through them:

* :mod:`.align` — landmark similarity (Umeyama) and trimmed rigid ICP;
* :mod:`.models` — how the template may move (rigid, blendshape, affine, graph,
  hybrid);
* :mod:`.icp` — the non-rigid ICP engine that fits a model, its schedule and terms;
* :mod:`.warp` — the landmark RBF warp and the landmark pull;
* :mod:`.projection` — projection onto the scan along normals;
* :mod:`.stages` — :func:`wrap`, the staged pipeline over all of the above;
* :mod:`.track` — 4D sequences, each frame warm-started from the previous one.
"""

from facewrap.wrapping.stages import WrapResult, WrapSettings, wrap

from facewrap.wrapping.stages import MODELS
from facewrap.wrapping.track import track, write_track_outputs

__all__ = ["wrap", "WrapSettings", "WrapResult",
    "MODELS", "track", "write_track_outputs",
]
