"""facewrap: wrap a template head onto raw face scans, transfer deformations, and
make blendshapes for any avatar.

The public API, grouped (see ``docs/architecture.md`` for how data flows):

* mesh model and files: :class:`Mesh`, :func:`read_mesh`, :func:`write_mesh`
* landmarks: :class:`Landmarks`, :func:`read_landmarks`, :func:`pair_landmarks`
* built-in sample: :mod:`facewrap.sample`; real data sets: :mod:`facewrap.datasets`
* geometry queries: :mod:`facewrap.geometry`
* wrapping a template onto a scan: :func:`wrap`, :class:`WrapSettings`
* textures and sequences: :mod:`facewrap.texture.bake`, :mod:`facewrap.animation`
"""

from facewrap.version import __version__

from facewrap.errors import InputError
from facewrap.mesh import Mesh
from facewrap.landmarks import IBUG68_NAMES, Landmarks, pair_landmarks
from facewrap.io import read_mesh, write_mesh
from facewrap.io.landmarks import read_landmarks, read_markers
from facewrap.wrapping import WrapResult, WrapSettings, wrap

__all__ = [
    "__version__", "InputError",
    "Mesh", "read_mesh", "write_mesh",
    "Landmarks", "IBUG68_NAMES", "pair_landmarks", "read_landmarks", "read_markers",
    "wrap", "WrapSettings", "WrapResult",
]
