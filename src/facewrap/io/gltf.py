"""glTF 2.0 binary (``.glb``) with morph targets: a neutral mesh and named shapes.

:func:`write_gltf_morphs` writes the target neutral and every shape as a named
morph target (``mesh.extras.targetNames``, the convention three.js, Blender and
Babylon read; ARKit names such as ``jawOpen`` pass through unchanged), so a
blendshape set opens in any glTF viewer.  glTF stores attributes per vertex, so a
mesh with UV seams is written with its vertices split at the seams; each written
vertex carries its original id in the application attribute ``_FACEWRAP_VERTEX``
so :func:`read_gltf_morphs` gives back the original vertices and shapes exactly
(to float32 precision).  Polygons are written as their fan triangulation.
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from facewrap.errors import InputError
from facewrap.mesh import Mesh
from facewrap.io.atomic import atomic_write

__all__ = ["write_gltf_morphs", "read_gltf_morphs", "GltfMorphs"]

_FLOAT, _UINT = 5126, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def _pygltflib():
    try:
        import pygltflib  # ~0.1 s to import, and only glTF files need it
    except ImportError:  # pragma: no cover - optional dependency
        raise ImportError("writing glTF needs pygltflib: pip install pygltflib") from None
    return pygltflib


def _split_vertices(mesh: Mesh):
    """Per written vertex: original vertex id and UV (None without UVs); triangles."""
    T = mesh.triangles
    if mesh.face_uvs is None:
        return np.arange(mesh.n_vertices), None, T
    tuv = mesh.triangle_uvs
    pairs = np.stack([T.reshape(-1), tuv.reshape(-1)], axis=1)
    uniq, inverse = np.unique(pairs, axis=0, return_inverse=True)
    return uniq[:, 0], mesh.uvs[uniq[:, 1]], inverse.reshape(-1, 3)


def write_gltf_morphs(path, neutral: Mesh, shapes: dict, *, scale: float = 1.0,
                      name: str = "facewrap") -> None:
    """Write a ``.glb`` with the neutral mesh and shapes as named morph targets.

    Parameters
    ----------
    path : str or os.PathLike
        Destination (``.glb``), replaced atomically.
    neutral : Mesh
    shapes : dict of str to (n, 3) float
        Shape name → vertex positions in the neutral's topology (absolute
        positions; the file stores displacements).
    scale : float
        Multiplies all positions (glTF units are metres: 0.01 for a mesh in cm).
    name : str
        Name of the glTF mesh and node.

    Raises
    ------
    ValueError
        When a shape has the wrong vertex count.
    """
    gl = _pygltflib()
    vid, uv, tris = _split_vertices(neutral)
    base = (neutral.vertices[vid] * scale).astype(np.float32)
    names = list(shapes)
    deltas = []
    for key in names:
        S = np.asarray(shapes[key], dtype=np.float64)
        if S.shape != neutral.vertices.shape:
            raise ValueError(f"shape {key!r} has shape {S.shape}, expected "
                             f"{neutral.vertices.shape}")
        deltas.append(((S[vid] - neutral.vertices[vid]) * scale).astype(np.float32))
    blobs, views, accessors = [], [], []

    def add(array: np.ndarray, component: int, kind: str, target: int | None,
            minmax: bool = False) -> int:
        data = np.ascontiguousarray(array).tobytes()
        offset = sum(len(b) for b in blobs)
        blobs.append(data + b"\0" * (-len(data) % 4))
        views.append(gl.BufferView(buffer=0, byteOffset=offset, byteLength=len(data),
                                   target=target))
        acc = gl.Accessor(bufferView=len(views) - 1, componentType=component,
                          count=len(array), type=kind)
        if minmax:
            acc.min = np.asarray(array, np.float64).min(axis=0).tolist()
            acc.max = np.asarray(array, np.float64).max(axis=0).tolist()
        accessors.append(acc)
        return len(accessors) - 1

    attrs = gl.Attributes(POSITION=add(base, _FLOAT, "VEC3", _ARRAY_BUFFER, True))
    if uv is not None:
        flipped = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]]).astype(np.float32)
        attrs.TEXCOORD_0 = add(flipped, _FLOAT, "VEC2", _ARRAY_BUFFER)
    ids = add(vid.astype(np.float32), _FLOAT, "SCALAR", _ARRAY_BUFFER)
    setattr(attrs, "_FACEWRAP_VERTEX", ids)
    indices = add(tris.astype(np.uint32).reshape(-1), _UINT, "SCALAR",
                  _ELEMENT_ARRAY_BUFFER)
    targets = [{"POSITION": add(d, _FLOAT, "VEC3", _ARRAY_BUFFER, True)}
               for d in deltas]
    prim = gl.Primitive(attributes=attrs, indices=indices, targets=targets or None)
    mesh = gl.Mesh(name=name, primitives=[prim], weights=[0.0] * len(names) or None,
                   extras={"targetNames": names})
    blob = b"".join(blobs)
    doc = gl.GLTF2(asset=gl.Asset(generator="facewrap", version="2.0"), scene=0,
                   scenes=[gl.Scene(nodes=[0])], nodes=[gl.Node(mesh=0, name=name)],
                   meshes=[mesh], accessors=accessors, bufferViews=views,
                   buffers=[gl.Buffer(byteLength=len(blob))])
    doc.set_binary_blob(blob)
    data = b"".join(doc.save_to_bytes())
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


def read_gltf_morphs(path) -> GltfMorphs:
    """Read the first mesh primitive of a ``.glb``/``.gltf`` and its morph targets.

    Raises
    ------
    InputError
        Missing file or a file without a readable mesh.
    """
    gl = _pygltflib()
    if not os.path.isfile(path):
        raise InputError("no such file", path)
    try:
        doc = gl.GLTF2().load(os.fspath(path))
    except Exception as exc:  # pygltflib raises many kinds on bad files
        raise InputError(f"not a readable glTF file ({exc})", path) from None
    if doc is None or not doc.meshes or not doc.meshes[0].primitives:
        raise InputError("no mesh in the glTF file", path)
    blob = doc.binary_blob()

    def read(index: int) -> np.ndarray:
        acc = doc.accessors[index]
        view = doc.bufferViews[acc.bufferView]
        width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
        dtype = {_FLOAT: np.float32, _UINT: np.uint32, 5123: np.uint16,
                 5121: np.uint8}[acc.componentType]
        start = (view.byteOffset or 0) + (acc.byteOffset or 0)
        arr = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
        return arr.reshape(acc.count, width) if width > 1 else arr

    mesh = doc.meshes[0]
    prim = mesh.primitives[0]
    pos = read(prim.attributes.POSITION).astype(np.float64)
    tris = read(prim.indices).astype(np.int64).reshape(-1, 3)
    ids = getattr(prim.attributes, "_FACEWRAP_VERTEX", None)
    names = list((mesh.extras or {}).get("targetNames", []))
    targets = prim.targets or []
    names += [f"target_{k}" for k in range(len(names), len(targets))]
    deltas = [read(t["POSITION"] if isinstance(t, dict) else t.POSITION)
              .astype(np.float64) for t in targets]
    if ids is not None:
        vid = read(ids).astype(np.int64)
        n = int(vid.max()) + 1
        first = np.full(n, -1, dtype=np.int64)
        first[vid[::-1]] = np.arange(len(vid))[::-1]
        pos_n = pos[first]
        tris = vid[tris]
        deltas = [d[first] for d in deltas]
        pos = pos_n
    return GltfMorphs(pos, tris, {k: pos + d for k, d in zip(names, deltas)})
