"""Detected landmarks in a wrap: the confident ones paired with the template's, and
what the report says about them."""

from __future__ import annotations

import numpy as np

from facewrap.landmarks import IBUG68_NAMES, Landmarks

__all__ = ["confident_landmarks", "detection_report", "detected_landmark_settings",
           "DETECTED_LANDMARK_SCALE"]

#: Weight of detected landmarks in a wrap, relative to clicked ones: the inverse
#: ratio of their variances, (0.5 mm / 3 mm)^2 -- a careful click is about half a
#: millimetre off, a confident detected point about three (``bench_detection``).
#: Light enough that the scan surface, not the detector's offsets, places the face;
#: not zero, so they still guard the fit against gross failure (as the landmarks a
#: sequence carries over from frame to frame do, ``track.PROPAGATED_LANDMARKS``).
#: On ICT-FaceKit ground-truth scans of four held-out identities and expressions
#: (hybrid model): 0.88-1.33 mm mean error at full weight, 0.41-0.73 at this one,
#: against 0.34-0.50 from the true landmarks.
DETECTED_LANDMARK_SCALE = 0.03


def confident_landmarks(template: Landmarks, found) -> tuple[Landmarks, Landmarks]:
    """The template landmarks and the detected scan landmarks a wrap pairs by name.

    Low-confidence points are left out (a jaw contour the scan does not hold would
    pull the fit off).  An unnamed template set of 68 is read as iBUG-68 order (the
    order of ICT-FaceKit's landmark vertices and of 68-point files).

    Parameters
    ----------
    template : Landmarks
    found : DetectedLandmarks

    Returns
    -------
    (Landmarks, Landmarks)
        Template and scan landmarks, both named.

    Raises
    ------
    ValueError
        When the template's landmarks cannot be paired with iBUG-68 points, or fewer
        than four confident points are left.

    Examples
    --------
    >>> from types import SimpleNamespace
    >>> tl = Landmarks.from_vertices(np.arange(68))
    >>> low = np.zeros(68, bool); low[:17] = True                      # the jaw
    >>> found = SimpleNamespace(landmarks=Landmarks.from_points(np.eye(68, 3), IBUG68_NAMES),
    ...                         low_confidence=low)
    >>> t, s = confident_landmarks(tl, found)
    >>> len(t), len(s), s.names[0]
    (68, 51, 'brow_r_0')
    """
    if template.names is None:
        if len(template) != 68:
            raise ValueError(f"template landmarks: {len(template)} unnamed landmarks "
                             "cannot pair with the 68 detected iBUG points; give 68 in "
                             "iBUG order, named ones, or --scan-landmarks")
        template = Landmarks(template.vertex, template.triangle, template.barycentric,
                             template.points, IBUG68_NAMES)
    keep = np.flatnonzero(~np.asarray(found.low_confidence))
    common = set(template.names) & {found.landmarks.names[i] for i in keep}
    if len(common) < 4:
        raise ValueError(f"scan landmarks: only {len(common)} confidently detected "
                         "landmark(s) pair with the template's; give --scan-landmarks")
    return template, found.landmarks.subset(keep)


def detected_landmark_settings(settings):
    """``settings`` for a wrap whose scan landmarks were detected.

    The landmark weight of every ICP stage is scaled by
    :data:`DETECTED_LANDMARK_SCALE` (on top of ``settings.landmark_scale``), and the
    landmark pull is off: pulling the fit to within a fraction of a millimetre of
    points that are millimetres off would bend the face toward them.

    Parameters
    ----------
    settings : WrapSettings

    Returns
    -------
    WrapSettings
        A copy; ``settings`` is not changed.

    Examples
    --------
    >>> from facewrap.wrapping import WrapSettings
    >>> s = detected_landmark_settings(WrapSettings(landmark_scale=2.0))
    >>> round(s.landmark_scale, 6), s.landmark_pull
    (0.06, False)
    """
    from dataclasses import replace
    return replace(settings, landmark_scale=settings.landmark_scale * DETECTED_LANDMARK_SCALE,
                   landmark_pull=False)


def detection_report(found) -> dict:
    """The report JSON's account of one detection (confidences, flags, views, time)."""
    names = found.landmarks.names
    return {"confidence": dict(zip(names, np.round(found.confidence, 4).tolist())),
            "low_confidence": [names[i] for i in np.flatnonzero(found.low_confidence)],
            "views": found.views, "eye_distance": found.eye_distance,
            "timings": found.timings}
