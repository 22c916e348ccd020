"""Deformation models: how a template may move.

Each model is a small estimator (settings in ``__init__``, ``fit`` returns
``self``, fitted results end in ``_``).  :class:`RBFWarp` interpolates landmark
displacements (SPEC §1.2).
"""

from facewrap.wrapping.warp import RBFWarp, rbf_kernel

__all__ = ["RBFWarp", "rbf_kernel"]
