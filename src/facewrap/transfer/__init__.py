"""Deformation transfer (SPEC §3) and landmark-guided avatar blendshapes (SPEC §4).

Data flows one way: reference meshes + markers → :func:`find_correspondence`
(deform one mesh onto the other, match triangles; save it once per pair) →
:class:`DeformationTransfer` (factor once) → one back-substitution per pose.
:class:`AvatarTransfer` does the same for a blendshape set and an avatar, adding
the landmark-motion term with per-part frames and scales.

Gradients (:mod:`.gradients`)
    :func:`gradient_operator`, :class:`GradientOperator`, :func:`fourth_vertices`,
    :func:`deformation_gradients`
Correspondence (:mod:`.correspondence`)
    :func:`find_correspondence`, :class:`Correspondence`,
    :class:`CorrespondenceSettings`, :class:`CorrespondenceStage`,
    :data:`SUMNER_SCHEDULE`, :func:`match_triangles`
Transfer (:mod:`.transfer`)
    :class:`DeformationTransfer` (unfolds the triangles it would flip, see
    ``fix_flips``), :func:`flipped_triangles`
Partner ambiguity (:mod:`.ambiguity`)
    :func:`partner_ambiguity` (where the result depends on the correspondence),
    :func:`ambiguity_summary` (where more markers would help)
Avatar blendshapes (:mod:`.avatar`)
    :class:`AvatarTransfer`, :class:`FacePart`, :data:`IBUG51_PARTS`,
    :func:`read_parts`, :data:`ONIZUKA_SCHEDULE`
"""

from .gradients import (GradientOperator, deformation_gradients, fourth_vertices,
                        gradient_operator)
from .correspondence import (SUMNER_SCHEDULE, Correspondence, CorrespondenceSettings,
                             CorrespondenceStage, find_correspondence, match_triangles)
from .transfer import DeformationTransfer, flipped_triangles
from .ambiguity import ambiguity_summary, partner_ambiguity
from .avatar import (IBUG51_PARTS, ONIZUKA_SCHEDULE, AvatarTransfer, FacePart,
                     read_parts)

__all__ = [
    "GradientOperator", "gradient_operator", "fourth_vertices", "deformation_gradients",
    "Correspondence", "CorrespondenceSettings", "CorrespondenceStage",
    "SUMNER_SCHEDULE", "find_correspondence", "match_triangles",
    "DeformationTransfer", "flipped_triangles", "partner_ambiguity", "ambiguity_summary",
    "AvatarTransfer", "FacePart", "IBUG51_PARTS", "ONIZUKA_SCHEDULE", "read_parts",
]
