"""Landmark detection: the 68 iBUG points on a scan or a template, no user input.

:func:`detect_landmarks` draws the mesh with the report's software rasteriser
(:mod:`.views`), searches every direction for a frontal face (:mod:`.search`),
detects the 68 points in a frontal and two turned views with dlib's model
(:mod:`.backend`, the optional extra ``facewrap[landmarks]``), lifts them onto the
surface and fuses the views with a confidence per point (:mod:`.fuse`).
:func:`mesh_texture` finds the image a mesh file refers to.
"""

from facewrap.detection.backend import EXTRA_HINT
from facewrap.detection.detect import DetectedLandmarks, detect_landmarks
from facewrap.detection.settings import DetectionSettings
from facewrap.detection.texture import mesh_texture

__all__ = ["detect_landmarks", "DetectedLandmarks", "DetectionSettings", "mesh_texture",
           "EXTRA_HINT"]
