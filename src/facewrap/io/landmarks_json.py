"""facewrap's own landmark JSON: any landmark kind, names, and what detection adds.

The format (see :mod:`facewrap.io.landmarks` for every other one)::

    {"format": "facewrap.landmarks", "version": 1,
     "source": "detected",                                 (optional)
     "landmarks": [
       {"name": "nose_tip", "vertex": 20},
       {"name": "mouth_left", "triangle": 511, "barycentric": [0.2, 0.3, 0.5],
        "confidence": 0.93, "low_confidence": false},       (both optional)
       {"name": "pupil_r", "point": [31.2, 10.5, 88.0]}],
     "views": [{"direction": [0, 0, 1], "yaw": 0, ...}]}     (optional)

Files without the optional keys (every file written before them) read as before.
"""

from __future__ import annotations

import json

import numpy as np

from facewrap.errors import InputError
from facewrap.io.atomic import atomic_write
from facewrap.io.files import read_format_items, read_json
from facewrap.landmarks import Landmarks, barycentric_problem

__all__ = ["read_landmarks_json", "write_landmarks_json", "read_landmark_details"]

#: Largest index a file may hold (int64); larger ones are errors, not overflows.
_MAX_INDEX = 2**63 - 1


def read_landmarks_json(path) -> Landmarks:
    """Read the facewrap landmark JSON format (see the module docstring)."""
    items = read_format_items(path, "facewrap.landmarks", "landmarks", "landmark")
    k = len(items)
    vertex, triangle = np.full(k, -1), np.full(k, -1)
    bary, points = np.zeros((k, 3)), np.full((k, 3), np.nan)
    names = []
    for i, it in enumerate(items):
        where = f"landmark {i}"
        if not isinstance(it, dict):
            raise InputError(f"{where} must be an object", path)
        names.append(it.get("name", str(i)))
        keys = [key for key in ("vertex", "triangle", "point") if key in it]
        if len(keys) != 1:
            raise InputError(f"{where} needs exactly one of 'vertex', 'triangle' "
                             "(+ 'barycentric') or 'point'", path)
        try:
            if keys[0] == "vertex":
                vertex[i] = _nonneg_int(it["vertex"])
            elif keys[0] == "triangle":
                triangle[i] = _nonneg_int(it["triangle"])
                bary[i] = _barycentric(it.get("barycentric"))
            else:
                points[i] = _three_numbers(it["point"], "point")
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: {exc}", path) from None
    if not any(isinstance(it, dict) and "name" in it for it in items):
        names = None   # names are optional: without any, the set pairs by order
    try:
        return Landmarks(vertex, triangle, bary, points, names)
    except ValueError as exc:
        raise InputError(str(exc), path) from None


def _three_numbers(value, key: str) -> np.ndarray:
    """A JSON ``[x, y, z]`` of finite numbers (``true`` is not the number 1)."""
    if (not isinstance(value, list) or len(value) != 3
            or any(isinstance(x, bool) or not isinstance(x, (int, float)) for x in value)):
        raise ValueError(f"'{key}' must be 3 finite numbers")
    out = np.asarray(value, dtype=np.float64)
    if not np.isfinite(out).all():
        raise ValueError(f"'{key}' must be 3 finite numbers")
    return out


def _barycentric(value) -> np.ndarray:
    """Coordinates of a point inside its triangle: each in [0, 1], summing to 1.

    Others put the point off the surface, or (1e300) overflow the alignment into
    an unnamed numerical failure; rounding in a written file is allowed for.
    """
    b = _three_numbers(value, "barycentric")
    if barycentric_problem(b):   # the one rule, Landmarks' own
        raise ValueError("'barycentric' must be 3 numbers in [0, 1] that sum to 1, "
                         f"got {value}")
    return b


def _nonneg_int(x) -> int:
    if isinstance(x, bool) or not isinstance(x, int) or x < 0:
        raise ValueError(f"index must be a non-negative integer, got {x!r}")
    if x > _MAX_INDEX:
        raise ValueError(f"index {str(x)[:30]} is too large")
    return x


def write_landmarks_json(path, landmarks: Landmarks, *, confidence=None,
                         low_confidence=None, views=None, source: str | None = None
                         ) -> None:
    """Write any landmark set in the facewrap JSON format (names kept).

    Detected landmarks add, optionally, a ``"confidence"`` (in [0, 1]) and a
    ``"low_confidence"`` flag per landmark, and top-level ``"views"`` (a list of
    objects: the views they were detected in) and ``"source"`` (what made them);
    :func:`read_landmarks_json` reads such files as any other, and
    :func:`read_landmark_details` returns the additions.

    Parameters
    ----------
    path : path
    landmarks : Landmarks
    confidence : (k,) float in [0, 1], optional
    low_confidence : (k,) bool, optional
    views : list of dict, optional
        JSON-serialisable.
    source : str, optional
        E.g. ``"detected"``.

    Examples
    --------
    >>> import tempfile, os
    >>> lm = Landmarks.from_vertices([3, 1], names=["a", "b"])
    >>> path = os.path.join(tempfile.mkdtemp(), "lm.json")
    >>> write_landmarks_json(path, lm, confidence=[0.9, 0.2], low_confidence=[False, True])
    >>> read_landmarks_json(path).vertex.tolist(), read_landmark_details(path)["confidence"].tolist()
    ([3, 1], [0.9, 0.2])
    """
    k = len(landmarks)
    conf = None if confidence is None else np.asarray(confidence, dtype=np.float64)
    low = None if low_confidence is None else np.asarray(low_confidence, dtype=bool)
    for name, a in (("confidence", conf), ("low_confidence", low)):
        if a is not None and a.shape != (k,):
            raise ValueError(f"{name} must have one value per landmark ({k}), got "
                             f"shape {a.shape}")
    if conf is not None and not np.all((conf >= 0) & (conf <= 1)):
        raise ValueError("confidence must lie in [0, 1]")
    items = []
    for i in range(k):
        # an unnamed set stays unnamed (read back, it pairs by order again)
        it = {} if landmarks.names is None else {"name": landmarks.names[i]}
        if landmarks.vertex[i] >= 0:
            it["vertex"] = int(landmarks.vertex[i])
        elif landmarks.triangle[i] >= 0:
            it["triangle"] = int(landmarks.triangle[i])
            it["barycentric"] = landmarks.barycentric[i].tolist()
        else:
            it["point"] = landmarks.points[i].tolist()
        if conf is not None:
            it["confidence"] = round(float(conf[i]), 4)
        if low is not None:
            it["low_confidence"] = bool(low[i])
        items.append(it)
    doc = {"format": "facewrap.landmarks", "version": 1}
    if source is not None:
        doc["source"] = str(source)
    doc["landmarks"] = items
    if views is not None:
        doc["views"] = list(views)
    with atomic_write(path, "w") as fh:
        json.dump(doc, fh, indent=1)


def read_landmark_details(path) -> dict:
    """What a facewrap landmark JSON adds to the landmarks (all optional).

    Returns
    -------
    dict
        ``confidence`` ((k,) float64 or None), ``low_confidence`` ((k,) bool or
        None), ``views`` (list), ``source`` (str or None).  A file without them
        (an older one) gives None, None, [], None.

    Raises
    ------
    InputError
        A confidence that is not a number in [0, 1], a flag that is not true or
        false, ``views`` that is not a list; or what :func:`read_landmarks_json`
        raises.
    """
    items = read_format_items(path, "facewrap.landmarks", "landmarks", "landmark")
    doc = read_json(path)
    out = {"confidence": None, "low_confidence": None,
           "views": doc.get("views", []), "source": doc.get("source")}
    if not isinstance(out["views"], list):
        raise InputError("'views' must be a list", path)
    if any(isinstance(it, dict) and "confidence" in it for it in items):
        conf = np.full(len(items), np.nan)
        for i, it in enumerate(items):
            c = it.get("confidence") if isinstance(it, dict) else None
            if isinstance(c, bool) or not isinstance(c, (int, float)) or not 0 <= c <= 1:
                raise InputError(f"landmark {i}: 'confidence' must be a number in "
                                 f"[0, 1], got {c!r}", path)
            conf[i] = c
        out["confidence"] = conf
    if any(isinstance(it, dict) and "low_confidence" in it for it in items):
        flags = [it.get("low_confidence") if isinstance(it, dict) else None for it in items]
        bad = next((i for i, f in enumerate(flags) if not isinstance(f, bool)), None)
        if bad is not None:
            raise InputError(f"landmark {bad}: 'low_confidence' must be true or false",
                             path)
        out["low_confidence"] = np.array(flags, dtype=bool)
    return out
