"""Landmark-guided avatar blendshapes (Onizuka et al. 2019, SPEC §4).

A source blendshape set (a neutral and its expressions) is carried onto an avatar
of another topology by deformation transfer (:mod:`facewrap.transfer`) plus a
landmark-motion term: the avatar's landmarks move as the source's do, measured in
per-part frames and scales so that a small mouth still closes.

:class:`AvatarTransfer`, :class:`FacePart`, :data:`IBUG51_PARTS`, :func:`read_parts`,
:data:`ONIZUKA_SCHEDULE`
"""

from facewrap.avatar.shapes import (IBUG51_PARTS, ONIZUKA_SCHEDULE, AvatarTransfer, FacePart,
                                    read_parts)

__all__ = ["AvatarTransfer", "FacePart", "IBUG51_PARTS", "ONIZUKA_SCHEDULE", "read_parts"]
