"""Landmark detection: the 68 iBUG points on a scan or a template, no user input.

:func:`detect_landmarks` draws the mesh with the report's software rasteriser
(:mod:`.views`), searches every direction for a frontal face (:mod:`.search`),
detects the 68 points in a frontal and two turned views with dlib's model
(:mod:`.backend`, the optional extra ``facewrap[landmarks]``), lifts them onto the
surface and fuses the views with a confidence per point (:mod:`.fuse`).
:func:`mesh_texture` finds the image a mesh file refers to.
"""

from facewrap.lazy import lazy_exports

#: public name -> the module that defines it, imported on first use (a wrap that is
#: given its landmarks never loads the renderer)
_PUBLIC = {
    "EXTRA_HINT": "facewrap.detection.backend",
    "DetectedLandmarks": "facewrap.detection.detect",
    "detect_landmarks": "facewrap.detection.detect",
    "DetectionSettings": "facewrap.detection.settings",
    "mesh_texture": "facewrap.detection.texture",
}
lazy_exports(__name__, _PUBLIC)

__all__ = ["detect_landmarks", "DetectedLandmarks", "DetectionSettings", "mesh_texture",
           "EXTRA_HINT"]
