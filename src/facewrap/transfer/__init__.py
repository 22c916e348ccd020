"""Deformation transfer between meshes of different topology (SPEC §3).

Data flows one way: reference meshes + markers → :func:`find_correspondence`
(deform one mesh onto the other, match triangles; save it once per pair) →
:class:`DeformationTransfer` (factor once) → one back-substitution per pose, with
the poses that fold a triangle over re-solved locally (:class:`FlipRepair`).
Avatar blendshapes (SPEC §4) build on this in :mod:`facewrap.avatar`.

Gradients (:mod:`.gradients`)
    :func:`gradient_operator`, :class:`GradientOperator`, :func:`fourth_vertices`,
    :func:`deformation_gradients`, :func:`triangle_smoothness_operator`,
    :func:`adjacent_triangle_pairs`, :class:`FourthVertexElimination`
Markers and tether (:mod:`.constraints`)
    :func:`check_markers`, :func:`untethered_vertices`, :func:`tether_weights`,
    :data:`TETHER_WEIGHT`
Correspondence (:mod:`.correspondence`, :mod:`.marker_deformation`,
:mod:`.triangle_matching`)
    :func:`find_correspondence`, :class:`Correspondence`,
    :class:`CorrespondenceSettings`, :class:`CorrespondenceStage`,
    :data:`SUMNER_SCHEDULE`, :func:`deform_toward`, :func:`match_triangles`
Transfer (:mod:`.deformation`)
    :class:`DeformationTransfer`, :class:`TransferSettings`, :func:`pair_matrix`,
    :func:`complete_pairs`, :func:`source_gradient_blocks`, :func:`as_pose_stack`
Flip repair (:mod:`.flip_repair`)
    :class:`FlipRepair` (unfolds the triangles a transfer flips where the source
    does not), :func:`nearest_proper_maps`
Partner ambiguity (:mod:`.ambiguity`)
    :func:`partner_ambiguity` (where the result depends on the correspondence),
    :func:`ambiguity_summary` (where more markers would help)

Flipped triangles are counted by :func:`facewrap.geometry.flipped_triangles`.
"""

from facewrap.transfer.ambiguity import ambiguity_summary, partner_ambiguity
from facewrap.transfer.constraints import (TETHER_WEIGHT, check_markers, tether_weights,
                                           untethered_vertices)
from facewrap.transfer.correspondence import (Correspondence, CorrespondenceSettings,
                                              find_correspondence)
from facewrap.transfer.deformation import (DeformationTransfer, TransferSettings,
                                           as_pose_stack, complete_pairs, pair_matrix,
                                           source_gradient_blocks)
from facewrap.transfer.flip_repair import FlipRepair, nearest_proper_maps
from facewrap.transfer.gradients import (FourthVertexElimination, GradientOperator,
                                         adjacent_triangle_pairs, deformation_gradients,
                                         fourth_vertices, gradient_operator,
                                         triangle_smoothness_operator)
from facewrap.transfer.marker_deformation import (SUMNER_SCHEDULE, CorrespondenceStage,
                                                  deform_toward)
from facewrap.transfer.triangle_matching import match_triangles

__all__ = [
    # gradients
    "GradientOperator", "gradient_operator", "fourth_vertices", "deformation_gradients",
    "adjacent_triangle_pairs", "triangle_smoothness_operator", "FourthVertexElimination",
    # markers and tether
    "check_markers", "untethered_vertices", "tether_weights", "TETHER_WEIGHT",
    # correspondence
    "Correspondence", "CorrespondenceSettings", "CorrespondenceStage",
    "SUMNER_SCHEDULE", "find_correspondence", "deform_toward", "match_triangles",
    # transfer and flip repair
    "DeformationTransfer", "TransferSettings", "pair_matrix", "complete_pairs",
    "source_gradient_blocks", "as_pose_stack", "FlipRepair", "nearest_proper_maps",
    # partner ambiguity
    "partner_ambiguity", "ambiguity_summary",
]
