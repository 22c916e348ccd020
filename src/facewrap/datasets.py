"""Loaders for public face and deformation-transfer data sets, in their own layouts.

These read a user's copy of each data set as it is published, so they work the same
on ``../shared/data`` and on any other copy:

* :class:`ICTFaceKit` — the ICT-FaceKit ``FaceXModel`` folder (neutral OBJ, one OBJ
  per expression/identity shape, ``vertex_indices.json``); shapes load lazily.
* :func:`load_shape_folder` — a folder of OBJ shapes in one topology (blendshapes).
* :func:`load_pose_set` / :class:`PoseSet` — Sumner-style reference + poses, with
  :func:`load_sumner_pair` for the ``markers-*.yml`` / ``.cons`` descriptions.
* :func:`expand_ict_facekit` — runs the compact copy's ``expand.py`` into a cache
  folder (never into the project tree).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from facewrap.errors import InputError
from facewrap.io.cache import cache_dir as shared_cache_dir
from facewrap.io.cache import content_key, load_arrays, save_arrays
from facewrap.io.dispatch import read_mesh
from facewrap.io.files import folder_files, read_file_bytes
from facewrap.io.landmarks import read_markers
from facewrap.io.obj import read_obj, read_obj_vertices
from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh
from facewrap.parallel import thread_map

__all__ = ["ICTFaceKit", "ICT_PARTS", "load_shape_folder", "PoseSet", "load_pose_set",
           "load_sumner_pair", "expand_ict_facekit", "cache_dir"]

#: ICT-FaceKit parts as (first vertex, last vertex, first polygon, last polygon),
#: inclusive, from the data set's documentation.
ICT_PARTS: dict[str, tuple[int, int, int, int]] = {
    "face": (0, 9408, 0, 9229),
    "narrow_face": (0, 6705, 0, 6559),
    "head_and_neck": (9409, 11247, 9230, 11143),
    "mouth_socket": (11248, 13293, 11144, 13225),
    "eye_socket_left": (13294, 13677, 13226, 13629),
    "eye_socket_right": (13678, 14061, 13630, 14033),
    "gums_and_tongue": (14062, 17038, 14034, 17005),
    "teeth": (17039, 21450, 17006, 21495),
    "eyeball_left": (21451, 23020, 21496, 23093),
    "eyeball_right": (23021, 24590, 23094, 24691),
    "eye_extras": (24591, 26718, 24692, 26383),
}


def cache_dir(*parts: str) -> Path:
    """A folder for expanded/converted data, created on demand: inside the one cache
    folder (:func:`facewrap.io.cache.cache_dir`: ``$FACEWRAP_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/facewrap`` or ``~/.cache/facewrap``); with the cache turned
    off (``FACEWRAP_CACHE=0``), in the system's temporary folder."""
    root = shared_cache_dir()
    root = Path(root) if root is not None else Path(tempfile.gettempdir()) / "facewrap-data"
    path = root.joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


def expand_ict_facekit(compact_root, out_dir=None, names=None) -> Path:
    """Write the FaceXModel folder from the compact copy (its own ``expand.py``).

    Parameters
    ----------
    compact_root : path
        Folder holding ``expand.py``, ``shapes_vertex_lines.npz`` and ``FaceXModel/``.
    out_dir : path, optional
        Defaults to ``cache_dir("ict-facekit")``.
    names : list of str, optional
        Shapes to write (all when omitted).  Shapes already written are kept;
        each file appears complete (written beside, then renamed), so processes
        sharing the folder never read a half-written shape.

    Returns
    -------
    Path of the expanded FaceXModel folder.
    """
    compact_root = Path(compact_root)
    script = compact_root / "expand.py"
    if not script.is_file():
        raise InputError("expand.py not found (not a compact ICT-FaceKit copy)",
                         compact_root)
    out = Path(out_dir) if out_dir is not None else cache_dir("ict-facekit")
    # Several processes (test workers, benchmarks) may share the cache: files
    # appear only complete (written beside, then renamed), a finished folder
    # is never rewritten, and "finished" is a marker written last.
    marker = out / ".expanded-all"
    if marker.is_file():
        return out
    wanted = list(names) if names else None
    if wanted is not None:
        wanted = [n for n in wanted if not (out / f"{n}.obj").is_file()]
        if not wanted and (out / "generic_neutral_mesh.obj").is_file():
            return out
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=out.parent, prefix=f".{out.name}-") as tmp:
        subprocess.run([sys.executable, str(script), tmp, *(wanted or [])], check=True)
        for f in Path(tmp).iterdir():
            os.replace(f, out / f.name)
    if wanted is None:
        marker.write_text("complete\n")
    return out


class ICTFaceKit:
    """The ICT-FaceKit light face model, read from its FaceXModel folder.

    Parameters
    ----------
    folder : path
        A ``FaceXModel`` folder: ``generic_neutral_mesh.obj``, ``vertex_indices.json``
        and one OBJ per shape (``browDown_L.obj``..., ``identity000.obj``...).

    Attributes
    ----------
    neutral : Mesh
        26,719 vertices, quads + triangles, 28,911 UVs, 12 materials (cm).
    expression_names, identity_names : list of str
        Shapes whose OBJ is present in the folder.
    landmarks : Landmarks
        The 68 iBUG landmark vertices (``idx_to_landmark_verts``), named
        :data:`~facewrap.landmarks.IBUG68_NAMES`.
    """

    def __init__(self, folder):
        self.folder = Path(folder)
        neutral = self.folder / "generic_neutral_mesh.obj"
        index = self.folder / "vertex_indices.json"
        for f in (neutral, index):
            if not f.is_file():
                raise InputError("missing (not an ICT-FaceKit FaceXModel folder)", f)
        self.neutral: Mesh = read_obj(neutral)
        with open(index) as fh:
            self.indices: dict = json.load(fh)
        self.expression_names = [n for n in self.indices["expressions"]
                                 if (self.folder / f"{n}.obj").is_file()]
        self.identity_names = sorted(p.stem for p in self.folder.glob("identity*.obj"))
        self.landmarks = Landmarks.from_vertices(self.indices["idx_to_landmark_verts"],
                                                 names=IBUG68_NAMES)
        self._cache: dict[str, np.ndarray] = {}

    def shape(self, name: str) -> np.ndarray:
        """(n, 3) vertex positions of one shape (read once, then cached)."""
        if name not in self._cache:
            path = self.folder / f"{name}.obj"
            if not path.is_file():
                raise InputError("shape not found", path)
            v = read_obj_vertices(path, self.neutral.n_vertices)
            v.setflags(write=False)
            self._cache[name] = v
        return self._cache[name]

    def deltas(self, names) -> np.ndarray:
        """(k, n, 3) displacements of the named shapes from the neutral."""
        return np.stack([self.shape(n) - self.neutral.vertices for n in names])

    def part_vertices(self, part: str) -> np.ndarray:
        """int64 vertex ids of a part of :data:`ICT_PARTS`."""
        lo, hi, _, _ = ICT_PARTS[part]
        return np.arange(lo, hi + 1, dtype=np.int64)

    def part_mesh(self, part: str = "face", vertices=None) -> Mesh:
        """The polygons of one part as a mesh (its vertex ids start at the part's
        first vertex, so for ``"face"`` they equal the full model's ids).

        Parameters
        ----------
        vertices : (n, 3) float, optional
            Positions for the full model (a shape); the neutral by default.
        """
        _, _, f0, f1 = ICT_PARTS[part]
        mesh = self.neutral if vertices is None else self.neutral.with_vertices(vertices)
        sub, vmap = mesh.submesh(np.arange(f0, f1 + 1))
        lo = ICT_PARTS[part][0]
        if not np.array_equal(vmap, np.arange(lo, lo + sub.n_vertices)):
            raise RuntimeError(f"ICT part {part!r} is not a contiguous vertex range")
        return sub


#: layout of the "obj-vertices" (one file) and "shape-folder" (a folder's files,
#: stacked) cache entries (bump when it changes)
_SHAPE_CACHE_VERSION = 1


def _usable(v, n_vertices: int | None, count: int | None = None) -> bool:
    """Whether a cached array is what a parse would give: float64, finite, (n, 3) —
    or (count, n, 3) for a stacked folder."""
    shape = v.shape[1:] if count is not None else v.shape
    return (v.dtype == np.float64 and len(shape) == 2 and shape[1] == 3 and shape[0] > 0
            and (count is None or len(v) == count)
            and (n_vertices is None or shape[0] == n_vertices) and np.isfinite(v).all())


def _shape_vertices(path: Path, n_vertices: int | None, data: bytes, key: str
                    ) -> np.ndarray:
    """The ``v`` lines of one shape OBJ (``data``, its bytes; ``key``, their
    :func:`content_key`), parsed once per content.

    The parsed array is kept in :mod:`facewrap.io.cache` under the hash of the file's
    bytes (hashing runs several times faster than the parse): an edited file is a new
    key, never a stale answer.  An entry is used only when it holds what this parse
    would give (:func:`_usable`); any other is ignored and written again.
    """
    hit = load_arrays("obj-vertices", key, ["vertices"], version=_SHAPE_CACHE_VERSION)
    if hit is not None and _usable(hit["vertices"], n_vertices):
        return hit["vertices"]
    v = read_obj_vertices(path, n_vertices, data=data)
    save_arrays("obj-vertices", key, {"vertices": v}, version=_SHAPE_CACHE_VERSION)
    return v


#: a folder's files count as unchanged since they were hashed only while each
#: file's path, size, modification and change times, inode and device are as they
#: were then, and only when the newest of those times was this many seconds older
#: than the hashing (git's rule for "racily clean" files: a write within the
#: clock's granularity of the hashing could leave the times as they were)
STAT_SETTLED = 2.0


def _stat_key(files: list, count: int) -> tuple[str, float] | None:
    """The key of the files' stat records and the newest of their change and
    modification times (s), or None when a file cannot be looked at."""
    records, newest = [], 0
    try:
        for p in files:
            st = os.stat(p)
            records.append((os.path.abspath(p), st.st_size, st.st_mtime_ns,
                            st.st_ctime_ns, st.st_ino, st.st_dev))
            newest = max(newest, st.st_mtime_ns, st.st_ctime_ns)
    except OSError:
        return None
    return content_key("folder-stat", count, repr(records)), newest / 1e9


def _folder_vertices(files: list, n_vertices: int | None) -> list:
    """The vertices of every file of a shape folder, in order.

    The files are read and hashed on the usable cores (both release the GIL); a
    folder seen before, byte for byte, is one cache entry of the stacked arrays;
    otherwise each file comes from its own entry or its parse.  A folder whose
    files have not been touched since they were hashed (:data:`STAT_SETTLED`) is
    not read at all: a small entry keyed by their stat records names the content
    key it had (53 ICT shapes, 44 MB: 45 ms of reading and hashing saved).  The
    arrays stay keyed by content; the stat entry only says which content it was.
    """
    count = -1 if n_vertices is None else n_vertices
    stat = _stat_key(files, count)
    if stat is not None:
        seen = load_arrays("folder-stat", stat[0], ["content", "hashed_at"],
                           version=_SHAPE_CACHE_VERSION)
        if seen is not None and stat[1] < float(seen["hashed_at"]) - STAT_SETTLED:
            hit = load_arrays("shape-folder", seen["content"].tobytes().decode("ascii"),
                              ["vertices"], version=_SHAPE_CACHE_VERSION)
            if hit is not None and _usable(hit["vertices"], n_vertices, len(files)):
                return list(hit["vertices"])
    hashed_at = time.time()          # before reading: a write during it is later
    datas = thread_map(lambda p: read_file_bytes(p, text=True), files)
    keys = thread_map(lambda d: content_key(d, count), datas)
    folder_key = content_key("shape-folder", *keys)
    hit = load_arrays("shape-folder", folder_key, ["vertices"],
                      version=_SHAPE_CACHE_VERSION)
    if hit is not None and _usable(hit["vertices"], n_vertices, len(files)):
        out = list(hit["vertices"])
    else:
        out = [_shape_vertices(p, n_vertices, d, k) for p, d, k in zip(files, datas, keys)]
        if len({len(v) for v in out}) != 1:      # several topologies: not stacked
            return out
        save_arrays("shape-folder", folder_key, {"vertices": np.stack(out)},
                    version=_SHAPE_CACHE_VERSION)
    if stat is not None:
        save_arrays("folder-stat", stat[0],
                    {"content": np.frombuffer(folder_key.encode("ascii"), np.uint8),
                     "hashed_at": np.array(hashed_at)}, version=_SHAPE_CACHE_VERSION)
    return out


def load_shape_folder(folder, reference: Mesh | None = None,
                      exclude=("neutral",)) -> dict[str, np.ndarray]:
    """Read every OBJ in a folder as a shape in one topology.

    Each file is parsed once per content and machine: later reads of the same
    bytes come from the on-disk cache (:mod:`facewrap.io.cache`; ``FACEWRAP_CACHE=0``
    turns it off), with the same values; the files are read and hashed on the
    usable cores (:mod:`facewrap.parallel`).

    Parameters
    ----------
    folder : path
    reference : Mesh, optional
        The neutral: every shape must have its vertex count.  A file whose vertices
        equal the reference's exactly is skipped (a neutral inside the folder).
    exclude : sequence of str
        File stems (case-insensitive substrings) to skip.

    Returns
    -------
    dict name -> (n, 3) float64, sorted by name.

    Examples
    --------
    >>> import os, tempfile
    >>> from pathlib import Path
    >>> folder = Path(tempfile.mkdtemp())
    >>> _ = (folder / "smile.obj").write_text("v 0 0 0\\nv 1 0 0\\nv 0 1 1\\n")
    >>> before = os.environ.get("FACEWRAP_CACHE_DIR")
    >>> os.environ["FACEWRAP_CACHE_DIR"] = str(folder / "cache")  # not ~/.cache here
    >>> load_shape_folder(folder)["smile"][2].tolist()
    [0.0, 1.0, 1.0]
    >>> load_shape_folder(folder)["smile"][2].tolist()   # from the cache
    [0.0, 1.0, 1.0]
    >>> _ = os.environ.pop("FACEWRAP_CACHE_DIR") if before is None else \\
    ...     os.environ.update(FACEWRAP_CACHE_DIR=before)
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError("not a folder", folder)
    files = [p for p in folder_files(folder, [".obj"])
             if not any(e.lower() in p.stem.lower() for e in exclude)]
    n = None if reference is None else reference.n_vertices
    shapes = {}
    stems = {}
    for p in files:   # smile.obj and smile.OBJ: one name, one shape would be lost
        if stems.setdefault(p.stem, p) != p:
            raise InputError(f"two files hold the shape {p.stem!r}: {stems[p.stem].name} "
                             f"and {p.name}; remove one", folder)
    for p, v in zip(files, _folder_vertices(files, n)):
        if reference is not None and np.array_equal(v, reference.vertices):
            continue
        shapes[p.stem] = v
    if not shapes and files:   # "none found" would send the user looking for files
        raise InputError(f"no shapes: its {len(files)} OBJ file(s) all equal the "
                         "neutral exactly", folder)
    if not shapes:
        raise InputError("no OBJ shapes found", folder)
    return shapes


@dataclass
class PoseSet:
    """A reference mesh and poses of it in the same topology."""
    reference: Mesh
    poses: list[np.ndarray] = field(default_factory=list)
    names: list[str] = field(default_factory=list)


def load_pose_set(reference, poses) -> PoseSet:
    """Read a reference mesh and pose files (vertex positions only for poses)."""
    ref = read_mesh(reference)
    return PoseSet(ref, [read_obj_vertices(p, ref.n_vertices) for p in poses],
                   [Path(p).stem for p in poses])


@dataclass
class SumnerPair:
    """A deformation-transfer case: source and target pose sets and markers."""
    source: PoseSet
    target: PoseSet
    markers: tuple[np.ndarray, np.ndarray]


def load_sumner_pair(description) -> SumnerPair:
    """Read a ``markers-*.yml`` description (source/target files and markers).

    The YAML names ``source.reference``, ``source.poses``, ``target.reference``,
    ``target.poses`` relative to its folder.
    """
    # deferred: only YAML files need PyYAML (start-up of every other command)
    import yaml
    description = Path(description)
    with open(description) as fh:
        d = yaml.safe_load(fh)
    root = description.parent
    try:
        src, tgt = d["source"], d["target"]
        source = load_pose_set(root / src["reference"], [root / p for p in src["poses"]])
        target = load_pose_set(root / tgt["reference"],
                               [root / p for p in tgt.get("poses", [])])
    except (KeyError, TypeError):
        raise InputError("expects source/target with reference and poses",
                         description) from None
    return SumnerPair(source, target, read_markers(description))
