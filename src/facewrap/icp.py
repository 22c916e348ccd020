"""The one registration engine: correspondences → deformation solve → repeat.

(SPEC §2.1.)  Work in progress: the schedule types are defined here first.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["Stage"]


@dataclass
class Stage:
    """One stage of the non-rigid ICP schedule (stiff to loose).

    Attributes
    ----------
    iterations : int
        Maximum ICP iterations (correspondences + one damped Gauss–Newton step).
    stiffness : float
        Weight of the model's smoothness regulariser (graph eq. 7, affine
        stiffness), relative to the data term.
    landmark_weight : float
        Weight of the landmark term relative to the data term.
    blend_weight : float
        Tikhonov weight on blend weights (eq. 5).
    """
    iterations: int = 10
    stiffness: float = 1.0
    landmark_weight: float = 1.0
    blend_weight: float = 0.01
