"""Template profiles: what a template says about itself, so a wrap needs no id lists.

A profile names, by vertex id, a template's landmarks, the vertices meant to be
fitted to a scan, and the vertices that move rigidly with the skull.  Two layouts
are read:

* **ICT-FaceKit's** ``vertex_indices.json`` as published: ``idx_to_landmark_verts``
  (68 iBUG-68 landmarks), ``idx_to_fitting_verts``, ``idx_to_rigid_verts``;
* **facewrap's own** (any template can ship one, ``<template>.profile.json`` beside
  it)::

      {"format": "facewrap.template_profile", "version": 1,
       "landmarks": [1225, 1888, ...],            # or [{"name": .., "vertex": ..}]
       "fitting_vertices": [...], "rigid_vertices": [...]}

  every key but ``format`` and ``version`` optional.

A list of exactly 68 unnamed landmarks is taken to be in iBUG-68 order (ICT's, and
what face-landmark tools write) and named so, which lets it pair by name with a
named scan set.  :func:`find_template_profile` looks for a profile beside a template.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import read_json
from facewrap.landmarks import IBUG68_NAMES, Landmarks

__all__ = ["TemplateProfile", "read_template_profile", "find_template_profile",
           "PROFILE_FORMAT"]

PROFILE_FORMAT = "facewrap.template_profile"

#: ICT-FaceKit's keys → profile fields
_ICT_KEYS = {"idx_to_landmark_verts": "landmarks", "idx_to_fitting_verts": "fitting",
             "idx_to_rigid_verts": "rigid"}
_OWN_KEYS = {"landmarks": "landmarks", "fitting_vertices": "fitting",
             "rigid_vertices": "rigid"}


@dataclass(frozen=True)
class TemplateProfile:
    """A template's landmarks and vertex sets (see the module docstring).

    Attributes
    ----------
    path : str
        The file it was read from.
    landmarks : Landmarks or None
        Vertex landmarks (named iBUG-68 when there are 68 unnamed ones).
    fitting : (k,) int64 or None
        Vertices meant to be fitted to a scan.
    rigid : (r,) int64 or None
        Vertices that move with the skull.
    """
    path: str
    landmarks: Landmarks | None = None
    fitting: np.ndarray | None = None
    rigid: np.ndarray | None = None

    def check(self, n_vertices: int) -> None:
        """Raise :class:`InputError` naming the file when an id is not a vertex of a
        template with ``n_vertices`` vertices (a profile for another mesh)."""
        sets = {"landmark": None if self.landmarks is None else self.landmarks.vertex,
                "fitting vertex": self.fitting, "rigid vertex": self.rigid}
        for what, ids in sets.items():
            if ids is not None and len(ids) and int(ids.max()) >= n_vertices:
                raise InputError(f"{what} id {int(ids.max())} is not a vertex of the "
                                 f"template ({n_vertices} vertices): a profile for "
                                 "another mesh?", self.path)

    def summary(self) -> str:
        """One line: what the profile gives."""
        parts = [f"{len(self.landmarks)} landmarks" if self.landmarks is not None else "",
                 f"{len(self.fitting)} fitting vertices" if self.fitting is not None
                 else "",
                 f"{len(self.rigid)} rigid vertices" if self.rigid is not None else ""]
        return ", ".join(p for p in parts if p) or "nothing"


def _ids(value, key: str, path) -> np.ndarray:
    """A JSON list of vertex ids as int64, checked."""
    if not isinstance(value, list) or not all(
            isinstance(v, int) and not isinstance(v, bool) for v in value):
        raise InputError(f"{key!r} must be a list of vertex ids (integers)", path)
    ids = np.asarray(value, dtype=np.int64).reshape(-1)
    if len(ids) and ids.min() < 0:
        raise InputError(f"{key!r} holds a negative vertex id ({int(ids.min())})", path)
    return ids


def _landmarks(value, path) -> Landmarks:
    """Landmarks from a list of ids or of ``{"name", "vertex"}`` records."""
    if isinstance(value, list) and value and all(isinstance(v, dict) for v in value):
        try:
            names = [str(v["name"]) for v in value]
            ids = _ids([v["vertex"] for v in value], "landmarks", path)
        except KeyError as exc:
            raise InputError(f"each landmark record needs {exc.args[0]!r}", path) from None
        if len(set(names)) != len(names):
            raise InputError("landmark names repeat", path)
        return Landmarks.from_vertices(ids, names=names)
    ids = _ids(value, "landmarks", path)
    names = list(IBUG68_NAMES) if len(ids) == len(IBUG68_NAMES) else None
    return Landmarks.from_vertices(ids, names=names)


def read_template_profile(path) -> TemplateProfile:
    """Read a template profile (ICT's ``vertex_indices.json`` or facewrap's own).

    Raises
    ------
    InputError
        Naming the file: not JSON, neither layout, ids that are not vertex ids.

    Examples
    --------
    >>> import json, tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> p = os.path.join(d, "head.profile.json")
    >>> _ = open(p, "w").write(json.dumps({"format": PROFILE_FORMAT, "version": 1,
    ...     "landmarks": [{"name": "nose_tip", "vertex": 3}], "fitting_vertices": [0, 3]}))
    >>> prof = read_template_profile(p)
    >>> prof.landmarks.names, prof.fitting.tolist(), prof.rigid is None
    (('nose_tip',), [0, 3], True)
    """
    data = read_json(path)
    if not isinstance(data, dict):
        raise InputError("a template profile must be a JSON object", path)
    if data.get("format") == PROFILE_FORMAT:
        if data.get("version") != 1:
            raise InputError(f"template profile version {data.get('version')!r} is not "
                             "supported (1 is)", path)
        keys = _OWN_KEYS
    elif any(k in data for k in _ICT_KEYS):
        keys = _ICT_KEYS
    else:
        raise InputError(f"not a template profile: needs \"format\": "
                         f"\"{PROFILE_FORMAT}\" or ICT-FaceKit's "
                         f"{', '.join(_ICT_KEYS)}", path)
    fields = {}
    for key, name in keys.items():
        if key in data:
            fields[name] = (_landmarks(data[key], path) if name == "landmarks"
                            else np.unique(_ids(data[key], key, path)))
    return TemplateProfile(str(path), **fields)


def find_template_profile(template_path) -> Path | None:
    """The profile beside a template, if any: ``<template>.profile.json`` (e.g.
    ``head.obj.profile.json`` or ``head.profile.json``), else an ICT-FaceKit
    ``vertex_indices.json`` in the same folder.

    Returns
    -------
    Path or None
    """
    t = Path(template_path)
    for candidate in (t.with_name(t.name + ".profile.json"),
                      t.with_name(t.stem + ".profile.json"),
                      t.with_name("vertex_indices.json")):
        if candidate.is_file():
            return candidate
    return None
