"""Scans in STL, OFF and glTF (``.glb``/``.gltf``), glTF read through trimesh.

glTF is read by `trimesh <https://trimesh.org>`_ (imported on first use: no other
command pays for it); each format is turned into a :class:`~facewrap.mesh.Mesh`:

* **STL** — read by :mod:`facewrap.io.stl`, binary or ASCII; a triangle soup by
  design (three corners per triangle), exactly coincident corners are merged into
  shared vertices here, so the scan is one surface and not a heap of loose
  triangles.
* **OFF** (and ``COFF``) — read here, not by trimesh (whose reader mangles ``#``
  comments and takes a face row short of its count as a smaller polygon): vertices
  in file order, each polygon a fan of triangles from its first corner, in file
  order; every row is checked and a bad one named by its line.
* **glTF 2.0** (binary ``.glb``, or ``.gltf`` with its buffers) — every triangle
  mesh of the scene, each instance placed by its node's world transform, one after
  another in the order of the file's meshes; per-vertex texture coordinates are kept
  when every piece has them, and each piece's material name is kept per face.
  :func:`read_scene_texture` gives the base-colour image the pieces use, so a GLB
  scan can be baked from.

The errors follow the other readers: anything wrong is one
:class:`~facewrap.errors.InputError` naming the file.  Counts the file's header
states (STL triangles, OFF vertices and faces, the GLB length and chunks, each
glTF accessor and bufferView inside the bytes it points into) are checked against
its size before it is read, so a bogus file is refused without reading it whole.
"""

from __future__ import annotations

import json
import os
import re
import struct
from urllib.parse import unquote

import numpy as np

from facewrap.errors import InputError
from facewrap.io.files import (file_size, not_a_file, nul_at_ends, read_file_bytes,
                               read_file_head)
from facewrap.io.stl import read_stl
from facewrap.mesh import Mesh

__all__ = ["TRIMESH_EXTENSIONS", "read_trimesh_format", "read_scene_texture"]

#: Extensions read here (lower case, with the dot) and trimesh's name of each format.
TRIMESH_EXTENSIONS = {".stl": "stl", ".off": "off", ".glb": "glb", ".gltf": "gltf"}

# Fewest bytes a vertex and a face line of an OFF file can take ("0 0 0\n",
# "3 0 1 2\n"): a header promising more than the file can hold is refused at once.
_OFF_VERTEX_BYTES, _OFF_FACE_BYTES = 6, 8
_GLB_MAGIC, _GLB_JSON, _GLB_BIN = b"glTF", 0x4E4F534A, 0x004E4942


#: how much of an OFF file its header is looked for in, in turn
_OFF_HEAD_BYTES = (4096, 1 << 20)


def _content_rows(text: str) -> list[tuple[int, str]]:
    """(line number, text) of the lines that are not blank or ``#`` comments,
    comments cut off and the text stripped (a UTF-8 byte-order mark left out)."""
    rows = ((no, ln.split("#", 1)[0].strip())
            for no, ln in enumerate(text.lstrip("\ufeff").splitlines(), start=1))
    return [(no, row) for no, row in rows if row]


def _off_counts(path) -> tuple[int, int, int]:
    """(vertices, faces, header rows) from an OFF header; only the head is read
    (its whole lines: 4 KiB, or up to 1 MiB under a long block of comments)."""
    for limit in _OFF_HEAD_BYTES:
        head = read_file_head(path, limit)
        if len(head) == limit:       # a line cut at the end would cut a count short
            head = head[:head.rfind(b"\n") + 1]
        rows = [row for _, row in _content_rows(head.decode("utf-8", errors="replace"))]
        tokens = " ".join(rows[:2]).split()
        if len(tokens) >= 3:
            break
    if not tokens or tokens[0] not in ("OFF", "COFF"):
        raise InputError("not an OFF file (no 'OFF' or 'COFF' first; this reader "
                         "takes those two)", path)
    counts = tokens[1:3]
    if len(counts) < 2 or not all(re.fullmatch(r"[0-9]+", t) for t in counts):
        raise InputError("OFF header needs the vertex and face counts after 'OFF'", path)
    return int(counts[0]), int(counts[1]), 2 if rows[0] == tokens[0] else 1


def _read_off(path, size: int) -> Mesh:
    """An OFF file, read here row by row (trimesh's reader mangles ``#`` comments
    and takes a face row short of its count as a smaller polygon, silently)."""
    if nul_at_ends(path, size):  # before reading it whole: a sparse or binary file
        raise InputError("binary data, not a text OFF file", path)
    nv, nf, header_rows = _off_counts(path)
    if nv == 0 or nf == 0:
        raise InputError(f"OFF header says {nv} vertices and {nf} faces; a scan needs "
                         "both", path)
    need = nv * _OFF_VERTEX_BYTES + nf * _OFF_FACE_BYTES
    if need > size:
        raise InputError(f"OFF header says {nv} vertices and {nf} faces (at least "
                         f"{need} bytes) but the file has {size} bytes", path)
    rows = _content_rows(read_file_bytes(path).decode("utf-8", errors="replace"))
    rows = rows[header_rows:]
    if len(rows) != nv + nf:   # fewer: cut short; more: counts that leave rows out
        raise InputError(f"OFF header says {nv} vertices and {nf} faces but "
                         f"{'only ' if len(rows) < nv + nf else ''}{len(rows)} rows "
                         "follow", path)
    V = _off_vertices(rows[:nv], path)
    return _mesh(V, _off_faces(rows[nv:], nv, path), path)


def _off_vertices(rows, path) -> np.ndarray:
    """x y z of each vertex row (a COFF colour after them, up to 4 values, skipped)."""
    tokens = [row.split() for _, row in rows]
    for (no, _), t in zip(rows, tokens):
        if not 3 <= len(t) <= 7:
            raise InputError(f"OFF vertex row has {len(t)} values; it needs x y z "
                             "(and at most a colour)", path, no)
    try:
        return np.array([t[:3] for t in tokens], dtype=np.float64)
    except ValueError:
        for (no, _), t in zip(rows, tokens):
            try:
                np.array(t[:3], dtype=np.float64)
            except ValueError:
                raise InputError(f"OFF vertex row is not three numbers: "
                                 f"{' '.join(t[:3])[:60]!r}", path, no) from None
        raise


def _off_faces(rows, nv: int, path) -> np.ndarray:
    """Each face row ``n i1 .. in [colour]`` as triangles (a fan from its first
    corner), in file order; every row checked and named by its line."""
    fast = _uniform_faces(rows, nv)
    if fast is not None:
        return fast
    polys = []
    for no, row in rows:
        t = row.split()
        n = int(t[0]) if t[0].isdecimal() and t[0].isascii() else -1
        if n < 3 or not n <= len(t) - 1 <= n + 4:
            raise InputError(f"OFF face row {row[:40]!r}: a face is its number of "
                             "corners (3 or more), that many vertex indices and at "
                             "most a colour", path, no)
        try:
            corners = [int(i) for i in t[1:n + 1]]
        except ValueError:
            raise InputError(f"OFF face row has an index that is not a whole number: "
                             f"{row[:60]!r}", path, no) from None
        bad = next((i for i in corners if not 0 <= i < nv), None)
        if bad is not None:
            raise InputError(f"OFF face index {bad} is outside the range of the "
                             f"{nv} vertices", path, no)
        polys.append(corners)
    return _fan(polys)


def _uniform_faces(rows, nv: int) -> np.ndarray | None:
    """Faces of one size and nothing after their indices (the usual OFF), read in
    bulk; None when any row is otherwise (the row-by-row reading names it)."""
    tokens = [row.split() for _, row in rows]
    width = len(tokens[0])
    if width < 4 or any(len(t) != width for t in tokens):
        return None
    try:
        table = np.array(tokens, dtype=np.int64)
    except (ValueError, OverflowError):
        return None
    corners = table[:, 1:]
    if (table[:, 0] != width - 1).any() or corners.min() < 0 or corners.max() >= nv:
        return None
    k = np.arange(1, width - 2)
    return np.stack([np.broadcast_to(corners[:, :1], (len(table), len(k))),
                     corners[:, k], corners[:, k + 1]], axis=-1).reshape(-1, 3)


def _fan(polys: list[list[int]]) -> np.ndarray:
    """Polygons as triangles (0, k, k + 1), in order; (m, 3) int64."""
    sizes = np.fromiter((len(p) for p in polys), dtype=np.int64, count=len(polys))
    flat = np.fromiter((i for p in polys for i in p), dtype=np.int64, count=sizes.sum())
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    per = sizes - 2
    first = np.repeat(starts, per)
    k = np.arange(per.sum()) - np.repeat(np.cumsum(per) - per, per) + 1
    return np.column_stack([flat[first], flat[first + k], flat[first + k + 1]])


def _check_glb(path, size: int) -> None:
    """GLB: magic, version 2, the stated length is the file's, chunks inside it."""
    head = read_file_head(path, 20)
    if len(head) < 20 or head[:4] != _GLB_MAGIC:
        raise InputError("not a binary glTF file (no 'glTF' magic)", path)
    version, length, chunk_length, chunk_type = struct.unpack("<IIII", head[4:20])
    if version != 2:
        raise InputError(f"glTF version {version}; this reader takes version 2", path)
    if length != size:
        raise InputError(f"truncated GLB: its header says {length} bytes, the file has "
                         f"{size}", path)
    if chunk_type != _GLB_JSON or 20 + chunk_length > size:
        raise InputError("GLB does not start with a JSON chunk that fits in the file",
                         path)
    with open(path, "rb") as fh:
        fh.seek(20)
        doc = _json_doc(fh.read(chunk_length), path)
        fh.seek(20 + chunk_length + (-chunk_length) % 4)  # chunks start 4-byte aligned
        bin_head = fh.read(8)
    bin_size = 0
    if len(bin_head) == 8:
        length, kind = struct.unpack("<II", bin_head)
        if kind == _GLB_BIN:       # the bytes the file holds, whatever it says
            bin_size = min(length, size - 28 - chunk_length - (-chunk_length) % 4)
    _check_gltf_doc(doc, path, bin_size)


def _json_doc(data: bytes, path) -> dict:
    """The glTF JSON document, as one error naming the file when it is not one."""
    try:
        doc = json.loads(data)
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"not glTF JSON: {' '.join(str(exc).split())}", path) from None
    except RecursionError:
        raise InputError("not glTF JSON: nested too deeply", path) from None
    if not isinstance(doc, dict) or "asset" not in doc:
        raise InputError("not glTF JSON (no 'asset')", path)
    return doc


def _accessor(doc: dict, index, what: str, path) -> dict:
    accessors = doc.get("accessors")
    if not isinstance(index, int) or not isinstance(accessors, list) \
            or not 0 <= index < len(accessors) or not isinstance(accessors[index], dict):
        raise InputError(f"{what} names accessor {index!r}, which the file does not "
                         "have", path)
    accessor = accessors[index]
    if "sparse" in accessor:
        raise InputError(f"{what} is a sparse accessor, which this reader does not "
                         "apply (export without sparse accessors)", path)
    if "bufferView" not in accessor:
        raise InputError(f"{what} has no data (an accessor without a bufferView: "
                         "a compression extension this reader does not decode?)", path)
    return accessor


def _external_file(uri, what: str, path) -> str | None:
    """The file a buffer's or image's ``uri`` names, checked: inside the glTF's
    folder (symlinks resolved) and a regular file (a missing image is left to
    trimesh, which reads none); None for a ``data:`` URI."""
    if not isinstance(uri, str):
        raise InputError(f"{what} has a uri that is not a string", path)
    if uri.startswith("data:"):
        return None
    name = unquote(uri)
    folder = os.path.realpath(os.path.dirname(os.path.abspath(path)))
    target = os.path.realpath(os.path.join(folder, name))
    if "://" in uri or os.path.isabs(name) or os.path.commonpath(
            [folder, target]) != folder:
        raise InputError(f"{what} names {uri[:80]!r}, outside the glTF's folder; "
                         "only files beside it (or data: URIs) are read", path)
    if not os.path.isfile(target) and (what.startswith("buffer")
                                       or os.path.lexists(target)):
        raise InputError(f"{what} names {uri[:80]!r}: {not_a_file(target).problem}",
                         path)
    return target


def _check_uris(doc: dict, path) -> None:
    """Every external buffer and image beside the file, regular, and each buffer of
    the size it states (a bigger one would be read whole: a sparse 2 GB file)."""
    for kind in ("buffers", "images"):
        items = doc.get(kind)
        for k, item in enumerate(items if isinstance(items, list) else []):
            if not isinstance(item, dict) or "uri" not in item:
                continue
            what = f"{kind[:-1]} {k}"
            target = _external_file(item["uri"], what, path)
            if target is None or kind == "images":
                continue
            stated, size = item.get("byteLength"), os.path.getsize(target)
            if not isinstance(stated, int) or not stated <= size < stated + 4:
                raise InputError(f"{what} file {item['uri'][:80]!r} has {size} bytes, "
                                 f"its byteLength says {stated!r}", path)


#: bytes of each glTF componentType, and components of each accessor type
_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_COMPONENTS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9,
                    "MAT4": 16}


def _whole(item: dict, key: str, what: str, path, default=None) -> int:
    value = item.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError(f"{what} {key} is {value!r}, not a whole number >= 0", path)
    return value


def _buffer_sizes(doc: dict, bin_size: int) -> list[int]:
    """The bytes each buffer holds: its file (checked by ``_check_uris``) or data:
    URI, the GLB's binary chunk for the first buffer without a uri, else none;
    never more than its ``byteLength`` says."""
    sizes, chunk = [], bin_size
    for item in doc.get("buffers") or []:
        item = item if isinstance(item, dict) else {}
        stated = item.get("byteLength")
        stated = stated if isinstance(stated, int) and stated >= 0 else 0
        uri = item.get("uri")
        if uri is None:
            held, chunk = chunk, 0
        elif isinstance(uri, str) and uri.startswith("data:") and "base64," in uri:
            payload = uri[uri.index("base64,") + 7:].rstrip("=")
            held = len(payload) * 3 // 4
        else:
            held = stated
        sizes.append(min(stated, held))
    return sizes


def _check_layout(doc: dict, path, bin_size: int) -> None:
    """Each bufferView inside its buffer, each accessor inside its bufferView
    (trimesh failed on an overrun with a bare AssertionError or a reshape error)."""
    buffers, views = _buffer_sizes(doc, bin_size), doc.get("bufferViews") or []
    for k, view in enumerate(views):
        what = f"bufferView {k}"
        view = view if isinstance(view, dict) else {}
        b = _whole(view, "buffer", what, path)
        if b >= len(buffers):
            raise InputError(f"{what} names buffer {b}, which the file does not have",
                             path)
        start, length = (_whole(view, key, what, path, 0)
                         for key in ("byteOffset", "byteLength"))
        if start + length > buffers[b]:
            raise InputError(f"{what} overruns buffer {b}: it spans bytes {start} to "
                             f"{start + length}, the buffer holds {buffers[b]} bytes", path)
    for k, acc in enumerate(doc.get("accessors") or []):
        if not isinstance(acc, dict) or "bufferView" not in acc:
            continue
        what = f"accessor {k}"
        v = _whole(acc, "bufferView", what, path)
        if v >= len(views):
            raise InputError(f"{what} names bufferView {v}, which the file does not "
                             "have", path)
        size = _COMPONENT_BYTES.get(acc.get("componentType"), 0) \
            * _TYPE_COMPONENTS.get(acc.get("type"), 0)
        if not size:
            raise InputError(f"{what} has componentType {acc.get('componentType')!r} "
                             f"and type {acc.get('type')!r}, not glTF's", path)
        count, start = _whole(acc, "count", what, path), _whole(acc, "byteOffset",
                                                               what, path, 0)
        view = views[v] if isinstance(views[v], dict) else {}
        stride = view.get("byteStride", size)
        if isinstance(stride, bool) or not isinstance(stride, int) or stride < size:
            raise InputError(f"bufferView {v} has byteStride {stride!r}, less than the "
                             f"{size} bytes of each element of {what}", path)
        need = start + (count - 1) * stride + size if count else start
        if need > view.get("byteLength", 0):
            raise InputError(f"{what} overruns bufferView {v}: its {count} elements "
                             f"need bytes {start} to {need}, the view holds "
                             f"{view.get('byteLength', 0)} bytes", path)


def _check_gltf_doc(doc: dict, path, bin_size: int = 0) -> None:
    """Refuse what trimesh would misread without a word: triangle fans (dropped),
    sparse or bufferless accessors (read as zeros), positions that are not float
    VEC3 and indices that are not unsigned integers (read as garbage), views and
    accessors beyond the bytes they point into (a bare AssertionError)."""
    _check_uris(doc, path)
    _check_layout(doc, path, bin_size)
    meshes = doc.get("meshes", [])
    for m, mesh in enumerate(meshes if isinstance(meshes, list) else []):
        prims = mesh.get("primitives", []) if isinstance(mesh, dict) else []
        for k, prim in enumerate(prims if isinstance(prims, list) else []):
            if not isinstance(prim, dict):
                continue
            where = f"mesh {m} primitive {k}"
            mode = prim.get("mode", 4)
            if mode not in (0, 1, 2, 3, 4, 5):
                raise InputError(f"{where} has mode {mode!r}; this reader takes "
                                 "triangles and triangle strips (4, 5)", path)
            if mode < 4:
                continue            # points and lines: no surface, left out
            attributes = prim.get("attributes")
            if not isinstance(attributes, dict) or "POSITION" not in attributes:
                raise InputError(f"{where} has no POSITION attribute", path)
            pos = _accessor(doc, attributes["POSITION"], f"{where} POSITION", path)
            if pos.get("componentType") != 5126 or pos.get("type") != "VEC3":
                raise InputError(f"{where} POSITION is not float VEC3 (componentType "
                                 f"{pos.get('componentType')!r}, type "
                                 f"{pos.get('type')!r})", path)
            if "indices" in prim:
                idx = _accessor(doc, prim["indices"], f"{where} indices", path)
                if idx.get("componentType") not in (5121, 5123, 5125) \
                        or idx.get("type") != "SCALAR":
                    raise InputError(f"{where} indices are not unsigned integer "
                                     f"SCALARs (componentType {idx.get('componentType')!r}"
                                     f", type {idx.get('type')!r})", path)


def _check_gltf(path, size: int) -> None:
    """A ``.gltf`` must be JSON with an ``asset`` (buffers are checked by trimesh)."""
    if size > 256 << 20:
        raise InputError(f"a .gltf of {size} bytes is not JSON a scan needs; embed "
                         "large buffers as .bin files or use .glb", path)
    with open(path, "rb") as fh:
        _check_gltf_doc(_json_doc(fh.read(), path), path)


def _load(path, kind: str):
    """trimesh's scene of the file, with every error as one line naming it."""
    import trimesh  # deferred: only these formats need it
    try:
        return trimesh.load(os.fspath(path), file_type=kind, force="scene",
                            process=False)
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for bad files
        text = " ".join(str(exc).split())[:200] or type(exc).__name__
        raise InputError(f"cannot read {kind.upper()}: {text}", path) from None


def _pieces(scene) -> list:
    """(world transform, trimesh.Trimesh, geometry name) of every mesh instance, in
    the order of the file's meshes (instances of one mesh by node name)."""
    import trimesh
    order = {name: k for k, name in enumerate(scene.geometry)}
    found = []
    for node in scene.graph.nodes_geometry:
        transform, name = scene.graph[node]
        geom = scene.geometry.get(name)
        if isinstance(geom, trimesh.Trimesh) and len(geom.faces):
            found.append((order[name], str(node), np.asarray(transform), geom, name))
    found.sort(key=lambda item: item[:2])
    return [(T, geom, name) for _, _, T, geom, name in found]


def _uv_of(geom):
    visual = getattr(geom, "visual", None)
    uv = getattr(visual, "uv", None) if getattr(visual, "kind", None) == "texture" else None
    return None if uv is None or len(uv) != len(geom.vertices) else np.asarray(uv)


def _scene_mesh(scene, path) -> Mesh:
    """Every piece of a scene in world space, one Mesh (see the module docstring)."""
    pieces = _pieces(scene)
    if not pieces:
        raise InputError("holds no triangle mesh", path)
    V, F, uvs, face_material, materials = [], [], [], [], []
    offset = 0
    for T, geom, name in pieces:
        v = np.asarray(geom.vertices, dtype=np.float64)
        V.append(v @ T[:3, :3].T + T[:3, 3])
        F.append(np.asarray(geom.faces, dtype=np.int64) + offset)
        uvs.append(_uv_of(geom))
        material = getattr(getattr(geom.visual, "material", None), "name", None) or name
        if material not in materials:
            materials.append(material)
        face_material.append(np.full(len(geom.faces), materials.index(material)))
        offset += len(v)
    kw = {}
    if all(uv is not None for uv in uvs):
        kw["uvs"] = np.vstack(uvs)
    return _mesh(np.vstack(V), np.vstack(F), path, face_materials=np.concatenate(
        face_material), materials=materials, **kw)


def _mesh(V, F, path, **kw) -> Mesh:
    if not np.isfinite(V).all():
        raise InputError("NaN or infinite coordinate", path)
    try:
        return Mesh(V, F, **kw)
    except ValueError as exc:
        raise InputError(str(exc), path) from None


def _welded(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exactly coincident vertices merged (first occurrence kept, in order)."""
    rows = np.ascontiguousarray(V).view(np.dtype((np.void, V.dtype.itemsize * 3)))[:, 0]
    _, first, inverse = np.unique(rows, return_index=True, return_inverse=True)
    order = np.argsort(first)              # unique vertices in order of first use
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    return V[first[order]], rank[inverse.reshape(-1)][F]


def read_trimesh_format(path) -> Mesh:
    """Read an STL, OFF, GLB or glTF scan (see the module docstring).

    Parameters
    ----------
    path : str or os.PathLike
        With one of the extensions of :data:`TRIMESH_EXTENSIONS`.

    Returns
    -------
    Mesh
        Triangles; vertices in file order (STL: coincident corners merged); for glTF
        every mesh instance in world space, with per-vertex UVs when all have them
        and material names per face.

    Raises
    ------
    InputError
        Naming the file: missing, truncated, counts beyond the file's size, no
        triangles, NaN coordinates, or anything trimesh cannot read.
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    kind = TRIMESH_EXTENSIONS.get(ext)
    if kind is None:
        raise InputError(f"not a trimesh format: {ext!r}", path)
    size = file_size(path)
    if size == 0:
        raise InputError("empty file", path)
    if kind == "off":
        return _read_off(path, size)
    if kind == "stl":
        V, F = _welded(*read_stl(path, size))   # a triangle soup: corners merged
        return _mesh(V, F, path)
    if kind == "glb":
        _check_glb(path, size)
    else:
        _check_gltf(path, size)
    return _scene_mesh(_load(path, kind), path)


def read_scene_texture(path) -> np.ndarray | None:
    """The base-colour image of a glTF scan's textured pieces, or None.

    Parameters
    ----------
    path : str or os.PathLike
        A ``.glb`` or ``.gltf`` file.

    Returns
    -------
    (H, W, 3) uint8 or None
        RGB, row 0 at the top (as :func:`facewrap.io.images.load_image` gives);
        None when some piece has no texture coordinates (then the mesh read has
        none either) or none has a base-colour image.

    Raises
    ------
    InputError
        Naming the file when it cannot be read, or when its pieces use more than
        one base-colour image (a bake reads one image).
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in (".glb", ".gltf"):
        raise InputError("only glTF files (.glb, .gltf) carry a texture image", path)
    size = file_size(path)
    (_check_glb if ext == ".glb" else _check_gltf)(path, size)
    images, pieces = [], _pieces(_load(path, ext[1:]))
    if any(_uv_of(geom) is None for _, geom, _ in pieces):
        return None  # the mesh read keeps UVs only when every piece has them
    for _, geom, _ in pieces:
        material = getattr(geom.visual, "material", None)
        image = getattr(material, "baseColorTexture", None) or getattr(material, "image",
                                                                       None)
        if image is not None and _uv_of(geom) is not None:
            array = np.asarray(image.convert("RGB"), dtype=np.uint8)
            if not any(a.shape == array.shape and np.array_equal(a, array)
                       for a in images):
                images.append(array)
    if len(images) > 1:
        raise InputError(f"its meshes use {len(images)} different base-colour images; "
                         "bake from one image (export the scan with one texture)", path)
    return images[0] if images else None
