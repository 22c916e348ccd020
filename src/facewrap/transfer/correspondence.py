"""Triangle correspondence between two meshes of different topology (SPEC §3.2).

This module owns the step that makes deformation transfer possible: which
triangles of the source correspond to which triangles of the target.
:func:`find_correspondence`

1. checks the markers (:mod:`.constraints`) and aligns the moving mesh on them;
2. deforms one mesh (the *moving* one, normally the source) toward the other (the
   *fixed* one) with the markers as hard constraints (:mod:`.marker_deformation`);
3. matches triangles both ways (:mod:`.triangle_matching`); the union is the
   many-to-many :class:`Correspondence`.

Lengths are measured in units of the fixed mesh's bounding-box diagonal (after a
similarity alignment on the markers), so the weights mean the same for meshes in
millimetres or metres.  A :class:`Correspondence` saves to and loads from ``.npz``
so it is computed once per source/target pair.
"""

from __future__ import annotations

import json
import os
import time
import zipfile
from dataclasses import dataclass, field

import numpy as np

from facewrap.errors import InputError
from facewrap.geometry.frames import NormalisedFrame
from facewrap.geometry.similarity import Similarity, similarity_transform
from facewrap.io.atomic import atomic_write
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import Instances, Interval, NoneAllowed, Options, expect_instance, validate
from facewrap.transfer.constraints import check_markers
from facewrap.transfer.marker_deformation import (SUMNER_SCHEDULE, CorrespondenceStage,
                                                  deform_toward)
from facewrap.transfer.triangle_matching import match_triangles

__all__ = ["CorrespondenceSettings", "Correspondence", "find_correspondence"]


@dataclass(frozen=True)
class CorrespondenceSettings:
    """How :func:`find_correspondence` works.

    Attributes
    ----------
    schedule : tuple of CorrespondenceStage
        Deformation steps, in order.
    deform : {"source", "target"}
        Which mesh is deformed toward the other (Sumner deforms the source;
        Onizuka et al. deform the avatar, i.e. the target).
    align : {"similarity", "rigid", "none"}
        Pre-alignment of the moving mesh on the markers before deforming.
    neighbours : int
        Candidates examined (nearest first) when looking for a compatible
        triangle or a valid closest vertex.
    max_distance : float or None
        Triangle pairs whose centroids are farther apart than this (fraction of the
        fixed mesh's bounding-box diagonal) are not matched.
    """

    schedule: tuple = SUMNER_SCHEDULE
    deform: str = "source"
    align: str = "similarity"
    neighbours: int = 16
    max_distance: float | None = None

    constraints = {
        "schedule": Instances(CorrespondenceStage),
        "deform": Options("source", "target"),
        "align": Options("similarity", "rigid", "none"),
        "neighbours": Interval(int, 1, None),
        "max_distance": (NoneAllowed(), Interval(float, 0, None, closed="neither")),
    }

    def __post_init__(self):
        validate(self)


_FORMAT = "facewrap.correspondence"
_VERSION = 1


@dataclass(frozen=True, eq=False)
class Correspondence:
    """Many-to-many triangle correspondence between a source and a target.

    Attributes
    ----------
    source_triangles, target_triangles : (k,) int64
        Pair ``j`` says source triangle ``source_triangles[j]`` corresponds to target
        triangle ``target_triangles[j]`` (indices into ``mesh.triangles``).  Sorted,
        without duplicates.
    n_source_vertices, n_source_triangles, n_target_vertices, n_target_triangles : int
        Sizes of the meshes it belongs to (checked when used).
    markers : (m, 2) int64
        The (source vertex, target vertex) pairs it was computed with.
    deformed : (n_moving, 3) float64
        The deformed moving mesh, in the fixed mesh's coordinates (for inspection).
    deformed_mesh : {"source", "target"}
        Which mesh ``deformed`` belongs to.
    stats : dict
        Timings and counts (closest-point validity, unmatched triangles).
    """

    source_triangles: np.ndarray
    target_triangles: np.ndarray
    n_source_vertices: int
    n_source_triangles: int
    n_target_vertices: int
    n_target_triangles: int
    markers: np.ndarray
    deformed: np.ndarray
    deformed_mesh: str = "source"
    stats: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.source_triangles)

    @property
    def unmatched_target(self) -> np.ndarray:
        """int64 target triangles without any source partner."""
        used = np.zeros(self.n_target_triangles, dtype=bool)
        used[self.target_triangles] = True
        return np.flatnonzero(~used)

    @property
    def unmatched_source(self) -> np.ndarray:
        """int64 source triangles without any target partner."""
        used = np.zeros(self.n_source_triangles, dtype=bool)
        used[self.source_triangles] = True
        return np.flatnonzero(~used)

    def check(self, source: Mesh | None = None, target: Mesh | None = None,
              path=None, *, markers=None) -> None:
        """Raise :class:`InputError` when the meshes or the marker pairs are not the
        ones it was made for.

        Parameters
        ----------
        source, target : Mesh, optional
        path : str, optional
            File to name in the message (the correspondence file).
        markers : (m, 2) int array_like, optional
            The (source, target) vertex pairs it must have been made with, in any
            order: a cache made with others would be reused in their place.
        """
        for name, mesh, nv, nt in (("source", source, self.n_source_vertices,
                                    self.n_source_triangles),
                                   ("target", target, self.n_target_vertices,
                                    self.n_target_triangles)):
            if mesh is None:
                continue
            if mesh.n_vertices != nv or len(mesh.triangles) != nt:
                raise InputError(f"correspondence was made for a {name} with {nv} "
                                 f"vertices and {nt} triangles, got "
                                 f"{mesh.n_vertices} and {len(mesh.triangles)}", path)
        if markers is not None:
            given = np.unique(np.asarray(markers, dtype=np.int64).reshape(-1, 2), axis=0)
            made = np.unique(self.markers.reshape(-1, 2), axis=0)
            if not np.array_equal(given, made):
                raise InputError(f"correspondence was made with other marker pairs "
                                 f"({len(made)}) than those given ({len(given)}): a cache "
                                 "of an earlier run; delete it to find a new one", path)

    def save(self, path) -> None:
        """Write to an ``.npz`` file (atomically)."""
        with atomic_write(path, "wb") as fh:
            np.savez_compressed(
                fh, format=np.array(_FORMAT), version=np.array(_VERSION),
                source_triangles=self.source_triangles,
                target_triangles=self.target_triangles,
                sizes=np.array([self.n_source_vertices, self.n_source_triangles,
                                self.n_target_vertices, self.n_target_triangles]),
                markers=self.markers, deformed=self.deformed,
                deformed_mesh=np.array(self.deformed_mesh),
                stats=np.array(json.dumps(self.stats)))

    @classmethod
    def load(cls, path) -> "Correspondence":
        """Read a file written by :meth:`save`.

        Raises
        ------
        InputError
            Missing file, not a facewrap correspondence, or inconsistent content.
        """
        if not os.path.isfile(path):
            raise InputError("no such file", path)
        with open(path, "rb") as fh:    # an .npz is a zip archive; anything else is not
            if fh.read(4) != b"PK\x03\x04":
                raise InputError("not a facewrap correspondence file (the .npz that "
                                 "`facewrap transfer --correspondence` writes)", path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if "format" not in z.files or str(z["format"]) != _FORMAT:
                    raise InputError("not a facewrap correspondence file", path)
                if int(z["version"]) > _VERSION:
                    raise InputError(f"correspondence version {int(z['version'])} is "
                                     "newer than this facewrap reads", path)
                d = {k: z[k] for k in z.files}
        except (OSError, ValueError, zipfile.BadZipFile, KeyError) as exc:
            if isinstance(exc, InputError):
                raise
            raise InputError(f"cannot read correspondence: {exc}", path) from None
        try:
            nsv, nst, ntv, ntt = (int(x) for x in d["sizes"])
            src = d["source_triangles"].astype(np.int64)
            tgt = d["target_triangles"].astype(np.int64)
            markers = d["markers"].astype(np.int64).reshape(-1, 2)
            deformed = d["deformed"].astype(np.float64)
            which = str(d["deformed_mesh"])
            stats = json.loads(str(d["stats"]))
        except (KeyError, ValueError, TypeError) as exc:
            raise InputError(f"incomplete correspondence file ({exc})", path) from None
        if (src.shape != tgt.shape or src.ndim != 1
                or (len(src) and (src.min() < 0 or src.max() >= nst
                                  or tgt.min() < 0 or tgt.max() >= ntt))):
            raise InputError("triangle pairs out of range", path)
        return cls(_ro(src), _ro(tgt), nsv, nst, ntv, ntt, _ro(markers), _ro(deformed),
                   which, stats)


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


def _fixed_frame(fixed: Mesh) -> NormalisedFrame:
    """The frame of the solve: the fixed mesh's bounding-box centre, its diagonal
    as the unit.

    The centre is the box's, not the centroid :meth:`NormalisedFrame.of` takes.  A
    translation changes the energy only by rounding, but rounding decides a few
    closest-point ties along the way: with the centroid, horse → camel gets one
    more triangle pair and one flip more or less per pose.  The box centre keeps the
    correspondences made so far (and saved files) bit for bit.
    """
    lo, hi = fixed.bounding_box()
    return NormalisedFrame((lo + hi) / 2, float(np.linalg.norm(hi - lo)) or 1.0)


def _align(moving: np.ndarray, fixed: np.ndarray, how: str) -> Similarity:
    if how == "none" or len(moving) < 3:
        return Similarity()
    return similarity_transform(moving, fixed, scale=(how == "similarity"))


def find_correspondence(source: Mesh, target: Mesh, markers,
                        settings: CorrespondenceSettings | None = None, *,
                        markers_path=None) -> Correspondence:
    """Compute the triangle correspondence of a source and a target mesh.

    Parameters
    ----------
    source, target : Mesh
        Reference meshes (any polygons; their fan triangulations are used).
    markers : (src, tgt) pair of (m,) int, or (m, 2) int
        Source vertex ↔ target vertex pairs, 0-based, at least one (three or more
        for the alignment).
    settings : CorrespondenceSettings, optional
    markers_path : str, optional
        Marker file, named in error messages.

    Returns
    -------
    Correspondence

    Raises
    ------
    InputError
        Marker ids out of range.
    TypeError, ValueError
        Not a Mesh, a mesh with a NaN or no faces, settings of another kind.
    """
    check_mesh(source, "source")
    check_mesh(target, "target")
    settings = expect_instance(settings, CorrespondenceSettings, "settings",
                               optional=True) or CorrespondenceSettings()
    src_ids, tgt_ids = check_markers(markers, source.n_vertices, target.n_vertices,
                                     markers_path)
    t0 = time.perf_counter()
    if settings.deform == "source":
        moving, fixed, m_ids, f_ids = source, target, src_ids, tgt_ids
    else:
        moving, fixed, m_ids, f_ids = target, source, tgt_ids, src_ids
    # one position per constrained moving vertex (mean when it is paired twice)
    uniq, inv = np.unique(m_ids, return_inverse=True)
    cnt = np.bincount(inv)
    goal = np.stack([np.bincount(inv, fixed.vertices[f_ids][:, d]) for d in range(3)],
                    axis=1) / cnt[:, None]
    align = _align(moving.vertices[m_ids], fixed.vertices[f_ids], settings.align)
    frame = _fixed_frame(fixed)
    Vm = frame.to_frame(align.apply(moving.vertices))
    Vf = frame.to_frame(fixed.vertices)
    deformed, stats = deform_toward(Vm, moving.triangles, Vf, fixed.triangles, uniq,
                                    frame.to_frame(goal), settings.schedule,
                                    settings.neighbours)
    t1 = time.perf_counter()
    max_d = np.inf if settings.max_distance is None else float(settings.max_distance)
    if settings.deform == "source":
        s_tri, t_tri = match_triangles(deformed, source.triangles, Vf, target.triangles,
                                       settings.neighbours, max_d)
    else:
        s_tri, t_tri = match_triangles(Vf, source.triangles, deformed, target.triangles,
                                       settings.neighbours, max_d)
    t2 = time.perf_counter()
    stats.update(deform_seconds=t1 - t0, match_seconds=t2 - t1, pairs=int(len(s_tri)))
    corr = Correspondence(
        _ro(s_tri), _ro(t_tri), source.n_vertices, len(source.triangles),
        target.n_vertices, len(target.triangles),
        _ro(np.stack([src_ids, tgt_ids], axis=1)), _ro(frame.from_frame(deformed)),
        settings.deform, stats)
    stats.update(unmatched_source=int(len(corr.unmatched_source)),
                 unmatched_target=int(len(corr.unmatched_target)))
    return corr
