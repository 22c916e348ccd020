"""facewrap: wrap a template head onto raw face scans, transfer deformations, and
make blendshapes for any avatar.

The public API, grouped (``docs/architecture.md`` shows how data flows between the
packages; each package's own ``__init__`` lists the rest of its API):

* the mesh model and files: :class:`Mesh`, :func:`read_mesh`, :func:`write_mesh`
* landmarks: :class:`Landmarks`, :func:`read_landmarks`, :func:`read_markers`,
  :func:`pair_landmarks`, :data:`IBUG68_NAMES`
* wrapping a template onto a scan (:mod:`facewrap.wrapping`): :func:`wrap`,
  :class:`WrapSettings`, :class:`WrapResult`, :func:`track`
* deformation transfer (:mod:`facewrap.transfer`): :func:`find_correspondence`,
  :class:`DeformationTransfer`
* avatar blendshapes (:mod:`facewrap.avatar`): :class:`AvatarTransfer`
* jobs from files to files (:mod:`facewrap.jobs`): :class:`WrapJob`,
  :func:`run_wrap_job`, :class:`TransferJob`, :func:`run_transfer_job`,
  :func:`load_job`; batches: :mod:`facewrap.batch`
* geometry, solvers, textures, measures, pictures: :mod:`facewrap.geometry`,
  :mod:`facewrap.solve`, :mod:`facewrap.texture`, :mod:`facewrap.evaluate`,
  :mod:`facewrap.report`; the built-in sample :mod:`facewrap.sample`; real data sets
  :mod:`facewrap.datasets`
"""

from importlib import import_module

from facewrap.version import __version__

#: public name -> the module that defines it.  Imported on first use (PEP 562), so
#: ``import facewrap.io`` or ``facewrap --help`` does not pay for the engines.
_PUBLIC = {
    "InputError": "facewrap.errors",
    "Mesh": "facewrap.mesh",
    "Landmarks": "facewrap.landmarks", "IBUG68_NAMES": "facewrap.landmarks",
    "pair_landmarks": "facewrap.landmarks",
    "read_mesh": "facewrap.io", "write_mesh": "facewrap.io",
    "read_landmarks": "facewrap.io.landmarks", "read_markers": "facewrap.io.landmarks",
    "wrap": "facewrap.wrapping", "WrapSettings": "facewrap.wrapping",
    "WrapResult": "facewrap.wrapping", "track": "facewrap.wrapping",
    "find_correspondence": "facewrap.transfer", "DeformationTransfer": "facewrap.transfer",
    "AvatarTransfer": "facewrap.avatar",
    "WrapJob": "facewrap.jobs", "run_wrap_job": "facewrap.jobs",
    "TransferJob": "facewrap.jobs", "run_transfer_job": "facewrap.jobs",
    "load_job": "facewrap.jobs",
}


def __getattr__(name: str):
    if name in _PUBLIC:
        value = getattr(import_module(_PUBLIC[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'facewrap' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + list(_PUBLIC))


__all__ = [
    "__version__", "InputError",
    "Mesh", "read_mesh", "write_mesh",
    "Landmarks", "IBUG68_NAMES", "pair_landmarks", "read_landmarks", "read_markers",
    "wrap", "WrapSettings", "WrapResult", "track",
    "find_correspondence", "DeformationTransfer",
    "AvatarTransfer",
    "WrapJob", "run_wrap_job", "TransferJob", "run_transfer_job", "load_job",
]

