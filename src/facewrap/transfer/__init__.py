"""Deformation transfer between meshes of different topology (SPEC §3).

Data flows one way: reference meshes + markers → :func:`find_correspondence`
(deform one mesh onto the other, match triangles; save it once per pair) →
:class:`DeformationTransfer` (factor once) → one back-substitution per pose.
Avatar blendshapes (SPEC §4) build on this in :mod:`facewrap.avatar`.

Gradients (:mod:`.gradients`)
    :func:`gradient_operator`, :class:`GradientOperator`, :func:`fourth_vertices`,
    :func:`deformation_gradients`
Correspondence (:mod:`.correspondence`)
    :func:`find_correspondence`, :class:`Correspondence`,
    :class:`CorrespondenceSettings`, :class:`CorrespondenceStage`,
    :data:`SUMNER_SCHEDULE`, :func:`match_triangles`
Transfer (:mod:`.deformation`)
    :class:`DeformationTransfer` (unfolds the triangles it would flip, see
    ``fix_flips``), :func:`flipped_triangles`
Partner ambiguity (:mod:`.ambiguity`)
    :func:`partner_ambiguity` (where the result depends on the correspondence),
    :func:`ambiguity_summary` (where more markers would help)
"""

from facewrap.transfer.gradients import (GradientOperator, deformation_gradients, fourth_vertices,
                        gradient_operator)
from facewrap.transfer.correspondence import (SUMNER_SCHEDULE, Correspondence, CorrespondenceSettings,
                             CorrespondenceStage, find_correspondence, match_triangles)
from facewrap.transfer.deformation import DeformationTransfer, flipped_triangles
from facewrap.transfer.ambiguity import ambiguity_summary, partner_ambiguity

from facewrap.transfer.correspondence import check_markers
from facewrap.transfer.deformation import complete_pairs, pair_matrix, source_gradient_blocks
from facewrap.transfer.gradients import adjacent_triangle_pairs, triangle_smoothness_operator

__all__ = [
    "GradientOperator", "gradient_operator", "fourth_vertices", "deformation_gradients",
    "Correspondence", "CorrespondenceSettings", "CorrespondenceStage",
    "SUMNER_SCHEDULE", "find_correspondence", "match_triangles",
    "DeformationTransfer", "flipped_triangles", "partner_ambiguity", "ambiguity_summary",
    "check_markers", "complete_pairs", "pair_matrix", "source_gradient_blocks", "adjacent_triangle_pairs", "triangle_smoothness_operator",
]
