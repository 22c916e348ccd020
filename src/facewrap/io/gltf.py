"""glTF 2.0 with morph targets: a neutral mesh and named shapes, ``.glb`` or ``.gltf``.

:func:`write_gltf_morphs` writes the target neutral and every shape as a named
morph target (``mesh.extras.targetNames``, the convention three.js, Blender and
Babylon read; ARKit names such as ``jawOpen`` pass through unchanged), so a
blendshape set opens in any glTF viewer.  The extension picks the form: ``.glb`` is
binary glTF, ``.gltf`` is JSON text with its one buffer embedded as a base64 data
URI (one self-contained file, which viewers and the Khronos validator accept, and
which is replaced atomically like every output; a ``.bin`` beside it would be a
second output that could be left half-written or go missing when the ``.gltf`` is
moved).  glTF stores attributes per vertex, so a mesh with UV seams is written
with its vertices split at the seams; each written vertex carries its original id
in the application attribute ``_FACEWRAP_VERTEX`` so :func:`read_gltf_morphs`
gives back the original vertices and shapes exactly (to float32 precision).
Polygons are written as their fan triangulation.

What an engine expects is there too: smooth vertex normals computed from the mesh
(the same normal on both sides of a UV seam, so seams do not show) with a normal
delta per morph target, a PBR material (metallic 0), and, when the mesh has UVs and
images are given, each image embedded as PNG as the base colour of its own
primitive and material, one per UDIM tile or per material group of a tile (REPEAT
wrapping, so a tile's UVs in ``[k, k + 1)`` read its image as they are).

:func:`read_gltf_morphs` reads both forms, buffers embedded as data URIs or in
files beside the ``.gltf``, and checks every accessor against its buffer view and
buffer before reading it.
"""

from __future__ import annotations

import base64
import binascii
import os
import struct
import urllib.parse
from dataclasses import dataclass

import numpy as np

from facewrap.errors import InputError
from facewrap.geometry.normals import vertex_normals
from facewrap.mesh import Mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.files import file_size, nul_at_ends, read_file_head
from facewrap.io.images import as_image, png_bytes

__all__ = ["write_gltf_morphs", "read_gltf_morphs", "gltf_format", "GltfMorphs",
           "GltfLayout", "gltf_layout"]

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963
_COMPONENTS = {_FLOAT: "<f4", _UINT: "<u4", 5123: "<u2", 5122: "<i2", 5121: "u1",
               5120: "i1"}
_WIDTHS = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}
_DATA_URI = "data:application/octet-stream;base64,"
_PNG = b"\x89PNG\r\n\x1a\n"
_FORMATS = {".glb": "glb", ".gltf": "gltf"}
# Original vertex ids are stored as float32 (glTF has no integer vertex attribute
# every viewer keeps), which is exact up to 2**24.
_MAX_VERTEX_ID = 1 << 24


def _pygltflib():
    try:
        import pygltflib  # ~0.1 s to import, and only glTF files need it
    except ImportError:  # pragma: no cover - optional dependency
        raise ImportError("writing glTF needs pygltflib: pip install pygltflib") from None
    return pygltflib


def gltf_format(path) -> str:
    """The glTF form a path asks for by its extension: ``"glb"`` or ``"gltf"``.

    Parameters
    ----------
    path : str or os.PathLike

    Raises
    ------
    InputError
        Naming the path, for any other extension.

    Examples
    --------
    >>> gltf_format("shapes.glb"), gltf_format("shapes.GLTF")
    ('glb', 'gltf')
    """
    ext = os.path.splitext(os.fspath(path))[1].lower()
    if ext not in _FORMATS:
        raise InputError(f"a glTF output must end in .glb (binary) or .gltf (JSON), "
                         f"not {ext or 'no extension'!r}", path)
    return _FORMATS[ext]


def _split_vertices(mesh: Mesh):
    """Per written vertex: original vertex id and UV (None without UVs); triangles.

    Vertices no triangle uses are written too (with UV (0, 0)), so every original
    id is in the file and the reader can give the original vertices back.
    """
    T = mesh.triangles
    if mesh.face_uvs is None:
        return np.arange(mesh.n_vertices), None, T
    tuv = mesh.triangle_uvs
    pairs = np.stack([T.reshape(-1), tuv.reshape(-1)], axis=1)
    uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
    uv = mesh.uvs[uniq[:, 1]]
    unused = np.setdiff1d(np.arange(mesh.n_vertices), uniq[:, 0])
    vid = np.concatenate([uniq[:, 0], unused])
    uv = np.concatenate([uv, np.zeros((len(unused), 2))])
    return vid, uv, inverse.reshape(-1, 3)


def _shape_deltas(neutral: Mesh, shapes: dict, vid, scale: float) -> list:
    deltas = []
    for key, value in shapes.items():
        S = np.asarray(value, dtype=np.float64)
        if S.shape != neutral.vertices.shape:
            raise ValueError(f"shape {key!r} has shape {S.shape}, expected "
                             f"{neutral.vertices.shape}")
        deltas.append(((S[vid] - neutral.vertices[vid]) * scale).astype(np.float32))
    return deltas


def _smooth_normals(V: np.ndarray, T: np.ndarray) -> np.ndarray:
    """(n, 3) unit vertex normals; +z where a vertex has none (unused, degenerate),
    since glTF requires every NORMAL to be a unit vector."""
    N = vertex_normals(V, T)
    N[np.linalg.norm(N, axis=1) < 0.5] = (0.0, 0.0, 1.0)
    return N


def _triangle_tiles(uv: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """UDIM tile (1001 + floor(u) + 10 floor(v)) of each triangle's UV centroid; -1
    outside the UDIM range (u in [0, 10), v in [0, 100)), which no tile holds."""
    cell = np.floor(uv[tris].mean(axis=1)).astype(np.int64)
    inside = (cell[:, 0] >= 0) & (cell[:, 0] < 10) & (cell[:, 1] >= 0) & (cell[:, 1] < 100)
    return np.where(inside, 1001 + cell[:, 0] + 10 * cell[:, 1], -1)


def _texture_key(key):
    """A key of ``textures``: a tile, or ``(tile, material ids)``, as ints."""
    if isinstance(key, tuple):
        tile, materials = key
        return int(tile), tuple(sorted(int(m) for m in materials))
    return int(key)


def _checked_textures(textures) -> dict:
    """``textures`` as key → PNG bytes (an image alone is tile 1001's), keys in order."""
    if textures is None:
        return {}
    if not isinstance(textures, dict):
        textures = {1001: textures}
    pngs = {}
    for key, im in textures.items():
        try:
            key = _texture_key(key)
        except (TypeError, ValueError):
            raise ValueError(f"textures: key {key!r} is neither a tile nor a (tile, "
                             "material ids) pair") from None
        pngs[key] = (bytes(im) if isinstance(im, bytes) and im.startswith(_PNG)  # as is
                     else png_bytes(as_image(im, f"texture {key}")))
    if len({isinstance(k, tuple) for k in pngs}) > 1:
        raise ValueError("textures: keys are tiles or (tile, material ids) pairs, "
                         "not both")
    return dict(sorted(pngs.items()))


def _triangle_textures(neutral: Mesh, uv: np.ndarray, tris: np.ndarray,
                       pngs: dict) -> np.ndarray:
    """(t,) index into ``list(pngs)`` of the image each triangle shows, -1 for none.

    A tile key holds the tile's triangles; a ``(tile, materials)`` key those of the
    tile whose face has one of the materials (-1: no material), as a bake of one
    texture set holds them.
    """
    tiles = _triangle_tiles(uv, tris)
    out = np.full(len(tris), -1, dtype=np.int64)
    if neutral.face_materials is None:
        materials = np.full(len(tris), -1, dtype=np.int64)
    else:
        materials = np.asarray(neutral.face_materials, np.int64)[neutral.triangle_faces]
    for k, key in enumerate(pngs):
        if isinstance(key, tuple):
            out[(tiles == key[0]) & np.isin(materials, key[1]) & (out < 0)] = k
        else:
            out[(tiles == key) & (out < 0)] = k
    return out


class _Blob:
    """The one binary buffer of a document, its buffer views and accessors."""

    def __init__(self, gl):
        self.gl, self.parts, self.views, self.accessors = gl, [], [], []

    def view(self, data: bytes, target: int | None = None) -> int:
        offset = sum(len(b) for b in self.parts)
        self.parts.append(data + b"\0" * (-len(data) % 4))
        self.views.append(self.gl.BufferView(buffer=0, byteOffset=offset,
                                             byteLength=len(data), target=target))
        return len(self.views) - 1

    def add(self, array: np.ndarray, component: int, kind: str, target: int | None,
            minmax: bool = False) -> int:
        view = self.view(np.ascontiguousarray(array).tobytes(), target)
        acc = self.gl.Accessor(bufferView=view, componentType=component,
                               count=len(array), type=kind)
        if minmax:
            acc.min = np.asarray(array, np.float64).min(axis=0).tolist()
            acc.max = np.asarray(array, np.float64).max(axis=0).tolist()
        self.accessors.append(acc)
        return len(self.accessors) - 1

    def bytes(self) -> bytes:
        return b"".join(self.parts)


def _key_name(key, material_names) -> str:
    """``facewrap_1001`` for a tile, ``skin+eye_1001`` for the materials of a tile
    (``facewrap`` standing for faces without one)."""
    if not isinstance(key, tuple):
        return f"facewrap_{key}"
    names = [material_names[m] if 0 <= m < len(material_names) else "facewrap"
             for m in key[1]]
    return f"{'+'.join(names) or 'facewrap'}_{key[0]}"


def _materials(gl, blob: _Blob, used, pngs: dict, material_names=()):
    """PBR materials (one per image shown, a plain one for the rest when there is
    a rest), textures, images, samplers, and the material of each index into
    ``list(pngs)`` in ``used`` (-1: no image)."""
    keys = list(pngs)
    materials, images, textures, of_tile = [], [], [], {}
    for k in used:
        if k < 0:
            continue
        name = _key_name(keys[k], material_names)
        images.append(gl.Image(bufferView=blob.view(pngs[keys[k]]), mimeType="image/png",
                               name=name.replace("facewrap_", "tile_", 1)))
        textures.append(gl.Texture(source=len(images) - 1, sampler=0))
        of_tile[k] = len(materials)
        materials.append(gl.Material(
            name=name, pbrMetallicRoughness=gl.PbrMetallicRoughness(
                baseColorTexture=gl.TextureInfo(index=len(textures) - 1),
                metallicFactor=0.0, roughnessFactor=0.7)))
    plain = [t for t in used if t not in of_tile]
    if plain:
        of_tile.update({t: len(materials) for t in plain})
        materials.append(gl.Material(name="facewrap", pbrMetallicRoughness=(
            gl.PbrMetallicRoughness(baseColorFactor=[0.8, 0.8, 0.8, 1.0],
                                    metallicFactor=0.0, roughnessFactor=0.7))))
    # REPEAT wrapping: a tile's UVs (u in [k, k + 1)) read its own image unshifted
    samplers = [gl.Sampler(magFilter=9729, minFilter=9987, wrapS=10497, wrapT=10497)
                ] if textures else []
    return materials, images, textures, samplers, of_tile


@dataclass(frozen=True)
class GltfLayout:
    """How :func:`write_gltf_morphs` lays a mesh out (what :func:`gltf_layout` returns).

    Attributes
    ----------
    vertex_ids : (k,) int64
        Original vertex of each written vertex (split at UV seams).
    uvs : (k, 2) float64 or None
        Texture coordinates as the mesh has them (v up; the file stores 1 - v).
    triangles : (t, 3) int64
        The fan triangulation into the written vertices.
    normals : (k, 3) float64
        Smooth unit normals of the original vertices (equal across a seam).
    images : dict
        Texture key (tile or ``(tile, material ids)``) → PNG bytes, in order.
    image_of : (t,) int64
        Index into ``list(images)`` of the image each triangle shows, -1: none.
    """

    vertex_ids: np.ndarray
    uvs: np.ndarray | None
    triangles: np.ndarray
    normals: np.ndarray
    images: dict
    image_of: np.ndarray


def gltf_layout(mesh: Mesh, textures=None) -> GltfLayout:
    """The written vertices, normals and per-triangle images of a mesh's glTF
    (``textures`` as :func:`write_gltf_morphs` takes them; the report draws this).

    Examples
    --------
    >>> m = Mesh(np.eye(3), [[0, 1, 2]], uvs=[[0, 0], [1, 0], [0, 1]],
    ...          face_uvs=[[0, 1, 2]])
    >>> lay = gltf_layout(m, np.zeros((2, 2, 3), np.uint8))
    >>> lay.vertex_ids.tolist(), lay.image_of.tolist(), list(lay.images)
    ([0, 1, 2], [0], [1001])
    """
    pngs = _checked_textures(textures)
    vid, uv, tris = _split_vertices(mesh)
    image_of = (_triangle_textures(mesh, uv, tris, pngs) if uv is not None and pngs
                else np.full(len(tris), -1, dtype=np.int64))   # into pngs, -1: none
    normals = _smooth_normals(mesh.vertices, mesh.triangles)[vid]
    return GltfLayout(vid, uv, tris, normals, pngs, image_of)


def _document(neutral: Mesh, shapes: dict, scale: float, name: str, textures=None):
    """The glTF document and its one binary buffer (bytes, 4-byte aligned parts)."""
    gl = _pygltflib()
    if neutral.n_vertices > _MAX_VERTEX_ID:
        raise ValueError(f"glTF output holds at most {_MAX_VERTEX_ID} vertices, the "
                         f"mesh has {neutral.n_vertices}")
    lay = gltf_layout(neutral, textures)
    vid, uv, tris, pngs, image_of = lay.vertex_ids, lay.uvs, lay.triangles, lay.images, \
        lay.image_of
    base = (neutral.vertices[vid] * scale).astype(np.float32)
    names = list(shapes)
    deltas = _shape_deltas(neutral, shapes, vid, scale)
    blob = _Blob(gl)
    attrs = gl.Attributes(POSITION=blob.add(base, _FLOAT, "VEC3", _ARRAY_BUFFER, True),
                          NORMAL=blob.add(lay.normals.astype(np.float32), _FLOAT, "VEC3",
                                          _ARRAY_BUFFER))
    if uv is not None:
        flipped = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]]).astype(np.float32)
        attrs.TEXCOORD_0 = blob.add(flipped, _FLOAT, "VEC2", _ARRAY_BUFFER)
    setattr(attrs, "_FACEWRAP_VERTEX",
            blob.add(vid.astype(np.float32), _FLOAT, "SCALAR", _ARRAY_BUFFER))
    targets = []
    for k, d in enumerate(deltas):
        moved = _smooth_normals(np.asarray(shapes[names[k]], np.float64), neutral.triangles)
        targets.append({"POSITION": blob.add(d, _FLOAT, "VEC3", _ARRAY_BUFFER, True),
                        "NORMAL": blob.add((moved[vid] - lay.normals).astype(np.float32),
                                           _FLOAT, "VEC3", _ARRAY_BUFFER)})
    # primitives in the order of the images, the plain one last
    used = sorted((int(t) for t in np.unique(image_of)), key=lambda t: (t < 0, t))
    materials, images, gl_textures, samplers, of_tile = _materials(gl, blob, used, pngs,
                                                                  neutral.materials)
    prims = [gl.Primitive(attributes=attrs, targets=targets or None,
                          material=of_tile[t],
                          indices=blob.add(tris[image_of == t].astype(np.uint32).reshape(-1),
                                           _UINT, "SCALAR", _ELEMENT_ARRAY_BUFFER))
             for t in used]
    mesh = gl.Mesh(name=name, primitives=prims, weights=[0.0] * len(names) or None,
                   extras={"targetNames": names})
    data = blob.bytes()
    doc = gl.GLTF2(asset=gl.Asset(generator="facewrap", version="2.0"), scene=0,
                   scenes=[gl.Scene(nodes=[0])], nodes=[gl.Node(mesh=0, name=name)],
                   meshes=[mesh], accessors=blob.accessors, bufferViews=blob.views,
                   buffers=[gl.Buffer(byteLength=len(data))], materials=materials,
                   images=images or None, textures=gl_textures or None,
                   samplers=samplers or None)
    return doc, data


def write_gltf_morphs(path, neutral: Mesh, shapes: dict, *, scale: float = 1.0,
                      name: str = "facewrap", textures=None) -> None:
    """Write the neutral mesh and shapes as named morph targets, by extension.

    Parameters
    ----------
    path : str or os.PathLike
        Destination, replaced atomically: ``.glb`` for binary glTF, ``.gltf`` for
        JSON text with the buffer embedded (a data URI).
    neutral : Mesh
    shapes : dict of str to (n, 3) float
        Shape name → vertex positions in the neutral's topology (absolute
        positions; the file stores displacements).
    scale : float
        Multiplies all positions (glTF units are metres: 0.01 for a mesh in cm).
    name : str
        Name of the glTF mesh and node.
    textures : (H, W, 3) uint8, or dict of int to (H, W, 3) uint8, optional
        Base-colour images (or PNG files' bytes, kept as they are), embedded as PNG: per
        UDIM tile (1001 the unit square), an image alone being tile 1001's.  Used when
        the mesh has UVs; each tile with an image becomes a primitive with its own
        textured PBR material, the other triangles share a plain one.  Keys may instead
        be ``(tile, material ids)`` pairs: the image of the triangles of that tile whose
        face has one of those materials (-1: no material), for materials whose UVs
        overlap inside one tile and so each have an image of their own (the texture sets
        of :func:`facewrap.texture.tiles.texture_sets`).

    Raises
    ------
    InputError
        When ``path`` ends in neither ``.glb`` nor ``.gltf`` (nothing is written).
    ValueError
        When a shape has the wrong vertex count, or the mesh more than 2**24
        vertices.
    """
    form = gltf_format(path)
    doc, blob = _document(neutral, shapes, scale, name, textures)
    if form == "glb":
        doc.set_binary_blob(blob)
        data = b"".join(doc.save_to_bytes())
    else:
        doc.buffers[0].uri = _DATA_URI + base64.b64encode(blob).decode("ascii")
        data = doc.to_json().encode("utf-8")
    with atomic_write(path, "wb") as fh:
        fh.write(data)


@dataclass(frozen=True)
class GltfMorphs:
    """What :func:`read_gltf_morphs` returns.

    Attributes
    ----------
    vertices : (n, 3) float64
        Neutral positions (original vertex order when the file has
        ``_FACEWRAP_VERTEX``).
    triangles : (t, 3) int64
        Into ``vertices``.
    shapes : dict of str to (n, 3) float64
        Absolute positions of every morph target, by name (``target_<k>`` when the
        file names none).
    """

    vertices: np.ndarray
    triangles: np.ndarray
    shapes: dict


def _buffer_bytes(doc, k: int, path) -> bytes:
    """The bytes of buffer ``k``: the GLB chunk, a data URI or a file beside ``path``."""
    buf = doc.buffers[k]
    uri = buf.uri
    if uri is None:
        data = doc.binary_blob() if k == 0 else None
        if data is None:
            raise InputError(f"buffer {k} has no data (no uri, no GLB binary chunk)",
                             path)
    elif uri.startswith("data:"):
        try:
            data = base64.b64decode(uri.partition(",")[2], validate=True)
        except (binascii.Error, ValueError):
            raise InputError(f"buffer {k}: its data URI is not valid base64",
                             path) from None
    else:
        folder = os.path.dirname(os.path.abspath(path))
        bin_path = os.path.join(folder, urllib.parse.unquote(uri))
        try:
            size = os.path.getsize(bin_path)
            if size < (buf.byteLength or 0):
                raise InputError(f"buffer {k} needs {buf.byteLength} bytes, "
                                 f"{bin_path} has {size}", path)
            with open(bin_path, "rb") as fh:
                data = fh.read(buf.byteLength or 0)
        except OSError as exc:
            raise InputError(f"buffer {k}: cannot read {bin_path}: {exc.strerror}",
                             path) from None
    if len(data) < (buf.byteLength or 0):
        raise InputError(f"buffer {k} holds {len(data)} bytes, its byteLength says "
                         f"{buf.byteLength}", path)
    return data


class _Accessors:
    """Reads accessors, each checked against its buffer view and buffer first."""

    def __init__(self, doc, path):
        self.doc, self.path = doc, path
        self._buffers: dict[int, bytes] = {}

    def __call__(self, index) -> np.ndarray:
        """Accessor ``index`` as a (count,) or (count, width) array (a copy)."""
        doc, path = self.doc, self.path
        if not isinstance(index, int) or not 0 <= index < len(doc.accessors or []):
            raise InputError(f"accessor {index!r} does not exist", path)
        acc = doc.accessors[index]
        if acc.type not in _WIDTHS or acc.componentType not in _COMPONENTS:
            raise InputError(f"accessor {index}: unsupported type {acc.type} of "
                             f"component {acc.componentType}", path)
        if acc.sparse is not None or acc.bufferView is None:
            raise InputError(f"accessor {index}: sparse accessors and accessors "
                             "without a buffer view are not supported", path)
        width, dtype = _WIDTHS[acc.type], np.dtype(_COMPONENTS[acc.componentType])
        if not 0 <= acc.bufferView < len(doc.bufferViews or []) or acc.count < 0:
            raise InputError(f"accessor {index}: buffer view {acc.bufferView} or "
                             f"count {acc.count} out of range", path)
        view = doc.bufferViews[acc.bufferView]
        if not 0 <= view.buffer < len(doc.buffers or []):
            raise InputError(f"buffer view {acc.bufferView}: buffer {view.buffer} "
                             "does not exist", path)
        if view.buffer not in self._buffers:
            self._buffers[view.buffer] = _buffer_bytes(doc, view.buffer, path)
        data = self._buffers[view.buffer]
        element = width * dtype.itemsize
        stride = view.byteStride or element
        span = (acc.count - 1) * stride + element if acc.count else 0
        view_start = view.byteOffset or 0
        if ((acc.byteOffset or 0) + span > view.byteLength
                or view_start + view.byteLength > len(data) or stride < element):
            raise InputError(f"accessor {index} ({acc.count} x {acc.type}) runs past "
                             f"its buffer view or buffer", path)
        arr = np.ndarray((acc.count, width), dtype=dtype, buffer=data,
                         offset=view_start + (acc.byteOffset or 0),
                         strides=(stride, dtype.itemsize)).copy()
        return arr if width > 1 else arr.reshape(-1)


def _original_order(read, prim, pos, tris, deltas, path):
    """Vertices, triangles and deltas in the original vertex order (by the ids)."""
    vid = read(prim.attributes._FACEWRAP_VERTEX)
    if len(vid) != len(pos) or not np.all((vid >= 0) & (vid == np.floor(vid))):
        raise InputError("_FACEWRAP_VERTEX must hold one non-negative integer id per "
                         "vertex", path)
    vid = vid.astype(np.int64)
    n = int(vid.max()) + 1 if len(vid) else 0
    first = np.full(n, -1, dtype=np.int64) if n <= len(vid) else None
    if first is not None:
        first[vid[::-1]] = np.arange(len(vid))[::-1]
    if first is None or (first < 0).any():
        raise InputError("_FACEWRAP_VERTEX ids leave original vertices out (the file "
                         "cannot give back the original mesh)", path)
    return pos[first], vid[tris], [d[first] for d in deltas]


def _check_container(path) -> None:
    """Refuse, before anything is read whole, a GLB whose header disagrees with the
    file's size (a GLB states its total length) and a JSON glTF holding NUL bytes."""
    size = file_size(path)
    head = read_file_head(path, 12)
    if head[:4] == b"glTF":
        if len(head) < 12:
            raise InputError("GLB header is cut short", path)
        (length,) = struct.unpack("<I", head[8:12])
        if length != size:
            raise InputError(f"GLB header says the file has {length} bytes, it has "
                             f"{size}", path)
    elif nul_at_ends(path, size):
        raise InputError("binary data, not a glTF (JSON) or GLB file", path)


def read_gltf_morphs(path) -> GltfMorphs:
    """Read the first mesh of a ``.glb``/``.gltf`` and its morph targets.

    The first primitive and every other primitive over the same vertices (one per
    material) are read as one mesh, their triangles one after the other.

    Raises
    ------
    InputError
        Missing file or a file without a readable mesh: not glTF, a buffer or an
        accessor out of bounds, indices out of range, a primitive that is not
        triangles.
    """
    gl = _pygltflib()
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    _check_container(path)
    try:
        doc = gl.GLTF2().load(os.fspath(path))
    except Exception as exc:  # pygltflib raises many kinds on bad files
        raise InputError(f"not a readable glTF file ({exc})", path) from None
    if doc is None or not doc.meshes or not doc.meshes[0].primitives:
        raise InputError("no mesh in the glTF file", path)
    try:
        return _read_mesh(doc, path)
    except InputError:
        raise
    except (IndexError, KeyError, TypeError, AttributeError, ValueError) as exc:
        # references a well-formed file never has (a view or buffer index too large)
        raise InputError(f"malformed glTF ({type(exc).__name__}: {exc})", path) from None


def _read_mesh(doc, path) -> GltfMorphs:
    read = _Accessors(doc, path)
    mesh = doc.meshes[0]
    prim = mesh.primitives[0]
    if prim.mode not in (None, 4):
        raise InputError(f"the first primitive is of mode {prim.mode}, not triangles "
                         "(4)", path)
    if prim.attributes.POSITION is None:
        raise InputError("the first primitive has no POSITION", path)
    pos = read(prim.attributes.POSITION).astype(np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise InputError("POSITION must be VEC3", path)
    # primitives over the same vertices (one per material: facewrap writes one per
    # UDIM tile) are one mesh; others (a second mesh in one file) are not read
    same = [p for p in mesh.primitives
            if p.attributes.POSITION == prim.attributes.POSITION and p.mode in (None, 4)]
    flat = (np.arange(len(pos)) if prim.indices is None else np.concatenate(
        [read(p.indices).astype(np.int64) for p in same if p.indices is not None]))
    if flat.ndim != 1 or len(flat) % 3 or (len(flat) and not (
            0 <= flat.min() and flat.max() < len(pos))):
        raise InputError(f"triangle indices must be 3 per triangle and index the "
                         f"{len(pos)} vertices", path)
    tris = flat.reshape(-1, 3)
    names = list((mesh.extras or {}).get("targetNames", []))
    targets = prim.targets or []
    names += [f"target_{k}" for k in range(len(names), len(targets))]
    deltas = [read(t["POSITION"] if isinstance(t, dict) else t.POSITION)
              .astype(np.float64) for t in targets]
    if any(d.shape != pos.shape for d in deltas):
        raise InputError("a morph target's POSITION has another vertex count than "
                         "the mesh", path)
    if getattr(prim.attributes, "_FACEWRAP_VERTEX", None) is not None:
        pos, tris, deltas = _original_order(read, prim, pos, tris, deltas, path)
    return GltfMorphs(pos, tris, {k: pos + d for k, d in zip(names, deltas)})
