"""Settings of landmark detection and their table of allowed values."""

from __future__ import annotations

from dataclasses import dataclass

from facewrap.params import Interval, validate

__all__ = ["DetectionSettings"]


@dataclass(frozen=True)
class DetectionSettings:
    """How :func:`~facewrap.detection.detect_landmarks` looks for the face.

    Attributes
    ----------
    search_size : int
        Pixels across the pictures of the whole mesh in which the face is searched
        (from up to 26 directions, each at four in-plane turns).
    refine_size : int
        Pixels across the pictures of the face once it is found.
    face_fraction : float
        Share of a refined picture's width the face (its 68 points) spans.
    yaw : float
        Degrees: the refined views look at the face from the front, this far to
        either side (0: none to the sides) ...
    pitch : float
        ... and this far from above and below (0: none).
    agreement : float
        Two views agree on a point when their lifts lie within this fraction of the
        distance between the eye centres (about 6 mm on an adult at 0.1).
    min_confidence : float
        Points whose confidence is below this are flagged low-confidence.
    """
    search_size: int = 320
    refine_size: int = 384
    face_fraction: float = 0.55
    yaw: float = 20.0
    pitch: float = 0.0
    agreement: float = 0.1
    min_confidence: float = 0.5

    constraints = {
        "search_size": Interval(int, 96, 2048),
        "refine_size": Interval(int, 96, 2048),
        "face_fraction": Interval(float, 0.2, 0.95),
        "yaw": Interval(float, 0.0, 45.0),
        "pitch": Interval(float, 0.0, 45.0),
        "agreement": Interval(float, 0.0, 1.0, closed="right"),
        "min_confidence": Interval(float, 0.0, 1.0),
    }

    def __post_init__(self):
        validate(self)
