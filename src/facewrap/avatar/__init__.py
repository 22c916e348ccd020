"""Landmark-guided avatar blendshapes (Onizuka et al. 2019, SPEC §4).

A source blendshape set (a neutral and its expressions) is carried onto an avatar
of another topology by deformation transfer (:mod:`facewrap.transfer`) plus a
landmark-motion term: the avatar's landmarks move as the source's do, measured in
per-part frames and scales so that a small mouth still closes.

Key shapes (:mod:`.shapes`)
    :class:`AvatarTransfer`, :class:`AvatarSettings`, :data:`ONIZUKA_SCHEDULE`
Face parts (:mod:`.parts`)
    :class:`FacePart`, :data:`IBUG51_PARTS`, :func:`read_parts`, :func:`part_frame`,
    :func:`part_motions`
"""

from facewrap.avatar.parts import (IBUG51_PARTS, FacePart, check_parts, part_frame,
                                   part_motions, read_parts)
from facewrap.avatar.shapes import ONIZUKA_SCHEDULE, AvatarSettings, AvatarTransfer

__all__ = ["AvatarTransfer", "AvatarSettings", "ONIZUKA_SCHEDULE", "FacePart",
           "IBUG51_PARTS", "read_parts", "check_parts", "part_frame", "part_motions"]
