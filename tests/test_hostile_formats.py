"""Hostile inputs of a sweep of the mesh formats other than OBJ: one test per bug class.

Classes:

- PLY: a second ``vertex`` or ``face`` element, or a ``vertex``/``face`` property
  named twice, was read silently (the first kept, the rest dropped, an
  out-of-range face in the second element never seen); it is now refused as
  ambiguous, naming the header line; an ASCII PLY whose counts leave lines out
  (``element face 1`` over two face lines) was read without them, and is now
  refused naming the first line left out;
- glTF: accessors trimesh misreads without a word were taken: float face indices
  (garbage faces), positions that are not float VEC3 (bytes of a float read as
  uint8, or 2D positions that failed as a numpy error naming no file), sparse
  accessors (the sparse values never applied), accessors without a bufferView
  (all zeros: a scan of one point), triangle fans (dropped); they are now refused
  naming the mesh and primitive.  A glTF JSON nested too deeply failed with a line
  naming no file; it is now named;
- OFF: a header under more than 4 KiB of comments was not found (or its counts
  cut short where the 4 KiB ended); it is now looked for in up to 1 MiB of whole
  lines;
- OFF: trimesh's reader mangles ``#`` comments in the body (the text before the
  first comment is repeated, so the counts row became vertex 0 and the last face
  was dropped, or a real scan failed with "invalid literal for int()"), and takes
  a face row with fewer indices than its count as a smaller polygon; OFF is now
  read by facewrap itself, row by row, each bad row named by its line;
  a header whose counts leave rows out (trimesh dropped them) is refused;
- glTF external files: a buffer or image naming a FIFO beside the file hung every
  command (``info`` too), and a buffer file far bigger than its ``byteLength`` (a
  sparse 3 GB file) was read whole; each external file is now checked first: inside
  the glTF's folder (symlinks resolved), a regular file, a buffer of the size it
  states.  (Paths outside the folder were already refused by trimesh, with a
  message telling the user to "pass FilePathResolver(...)"; they are now refused
  saying where the file is.)

Inputs are tiny meshes written here (no sample files are needed).
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.obj import read_obj
from test_hostile_more import one_line_error


def _run_info(path: Path, capsys, *needles: str) -> str:
    return one_line_error(capsys, facewrap("info", path), str(path), *needles)


# -- PLY: an element or property given twice ------------------------------------------------
_PLY_HEAD = ("ply\nformat ascii 1.0\nelement vertex 4\n{vprops}element face 2\n"
             "property list uchar int vertex_indices\n{more}end_header\n"
             "0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n")
_XYZ = "property float x\nproperty float y\nproperty float z\n"


@pytest.mark.parametrize("vprops, more, rows, needle", [
    (_XYZ, "element vertex 4\n" + _XYZ, "9 9 9\n" * 4, "second 'vertex' element"),
    (_XYZ, "element face 1\nproperty list uchar int vertex_indices\n", "3 0 0 9\n",
     "second 'face' element"),
    ("property float x\n" + _XYZ, "", None, "property 'x' given twice"),
])
def test_a_ply_element_or_property_given_twice_is_refused(tmp_path, capsys, vprops,
                                                          more, rows, needle):
    text = _PLY_HEAD.format(vprops=vprops, more=more)
    if rows is None:   # one more column per vertex row
        head, body = text.split("end_header\n")
        lines = body.splitlines()
        text = head + "end_header\n" + "\n".join(
            ["5 " + ln for ln in lines[:4]] + lines[4:]) + "\n"
    else:
        text += rows
    p = tmp_path / "scan.ply"
    p.write_text(text)
    _run_info(p, capsys, needle)


def test_an_ascii_ply_whose_counts_leave_lines_out_is_refused(tmp_path, capsys):
    p = tmp_path / "scan.ply"
    p.write_text(_PLY_HEAD.format(vprops=_XYZ, more="").replace("face 2", "face 1"))
    err = _run_info(p, capsys, "1 more lines than the header's element counts take")
    assert f"{p}:15:" in err
    p.write_text(_PLY_HEAD.format(vprops=_XYZ, more="") + "\n  \n")   # blank: fine
    assert facewrap("info", p) == 0


# -- glTF: accessors trimesh misreads -------------------------------------------------------
_V = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 10]], np.float32)
_I = np.array([0, 1, 2, 1, 3, 2], np.uint32)


def quad_gltf_doc() -> dict:
    """The glTF JSON of a quad (two triangles): positions then uint32 indices."""
    return {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
            "nodes": [{"mesh": 0}],
            "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
            "buffers": [{"byteLength": 72}],
            "bufferViews": [{"buffer": 0, "byteLength": 48},
                            {"buffer": 0, "byteOffset": 48, "byteLength": 24}],
            "accessors": [{"bufferView": 0, "componentType": 5126, "count": 4,
                           "type": "VEC3", "min": [0, 0, 0], "max": [100, 100, 10]},
                          {"bufferView": 1, "componentType": 5125, "count": 6,
                           "type": "SCALAR"}]}


def _glb(doc: dict) -> bytes:
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary = _V.tobytes() + _I.tobytes()
    chunks = (struct.pack("<II", len(js), 0x4E4F534A) + js
              + struct.pack("<II", len(binary), 0x004E4942) + binary)
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def _sparse(d):
    d["accessors"][0]["sparse"] = {"count": 1, "indices": {"bufferView": 1,
                                                           "componentType": 5125},
                                   "values": {"bufferView": 0}}


@pytest.mark.parametrize("change, needle", [
    (lambda d: d["accessors"][1].update(componentType=5126), "indices are not unsigned"),
    (lambda d: d["accessors"][0].update(componentType=5121), "POSITION is not float VEC3"),
    (lambda d: d["accessors"][0].update(type="VEC2"), "POSITION is not float VEC3"),
    (_sparse, "sparse accessor"),
    (lambda d: d["accessors"][0].pop("bufferView"), "has no data"),
    (lambda d: d["meshes"][0]["primitives"][0].update(mode=6), "has mode 6"),
])
def test_a_glb_accessor_trimesh_misreads_is_refused(tmp_path, capsys, change, needle):
    doc = quad_gltf_doc()
    p = tmp_path / "scan.glb"
    p.write_bytes(_glb(doc))
    assert facewrap("info", p) == 0            # the file as it is reads
    capsys.readouterr()
    change(doc)
    p.write_bytes(_glb(doc))
    _run_info(p, capsys, needle, "mesh 0 primitive 0")


@pytest.mark.parametrize("ext", [".gltf", ".glb"])
def test_a_gltf_nested_too_deeply_names_its_file(tmp_path, capsys, ext):
    js = b'{"asset": {"version": "2.0"}, "x": ' + b"[" * 50000 + b"]" * 50000 + b"}"
    js += b" " * (-len(js) % 4)
    p = tmp_path / f"scan{ext}"
    if ext == ".glb":
        js = (b"glTF" + struct.pack("<II", 2, 20 + len(js))
              + struct.pack("<II", len(js), 0x4E4F534A) + js)
    p.write_bytes(js)
    _run_info(p, capsys, "nested too deeply")


# -- OFF: comments, short face rows, counts that leave rows out ------------------------------
_OFF_V = [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]


def _off(tmp_path, text: str) -> Path:
    p = tmp_path / "scan.off"
    p.write_text(text)
    return p


@pytest.mark.parametrize("text", [
    "OFF\n4 2 0\n# vertices\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n",
    "OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2 # first\n3 1 3 2\n",
    "OFF\n4 2 0\n0 0 0 # origin\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n",
])
def test_an_off_with_comments_in_its_body_reads_as_written(tmp_path, capsys, text):
    out = tmp_path / "out.obj"
    assert facewrap("convert", _off(tmp_path, text), out) == 0, capsys.readouterr().err
    mesh = read_obj(out)
    assert np.abs(mesh.vertices - np.array(_OFF_V, float)).max() < 1e-9
    assert mesh.triangles.tolist() == [[0, 1, 2], [1, 3, 2]]


def test_a_scanner_off_with_comments_everywhere_reads_as_written(tmp_path, capsys):
    V = np.random.default_rng(0).random((30, 3)) * 100
    F = np.array([[i, i + 1, i + 2] for i in range(28)])
    rows = [" ".join(repr(float(x)) for x in v) + "  # a vertex" for v in V]
    text = (f"OFF\n{len(V)} {len(F)} 0\n# vertices\n"
            + "\n".join(rows) + "\n# faces\n"
            + "".join(f"3 {a} {b} {c}\n" for a, b, c in F))
    out = tmp_path / "out.obj"
    assert facewrap("convert", _off(tmp_path, text), out) == 0, capsys.readouterr().err
    assert np.abs(read_obj(out).vertices - V).max() < 1e-9
    assert np.array_equal(read_obj(out).triangles, F)


@pytest.mark.parametrize("face, line", [("4 0 1 2", 7), ("1000000000 0 1 2", 7)])
def test_an_off_face_row_short_of_its_count_is_named(tmp_path, capsys, face, line):
    p = _off(tmp_path, f"OFF\n4 2 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n{face}\n3 1 3 2\n")
    err = _run_info(p, capsys, "OFF face row")
    assert f"{p}:{line}:" in err


def test_an_off_whose_counts_leave_rows_out_is_refused(tmp_path, capsys):
    p = _off(tmp_path, "OFF\n4 1 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n3 1 3 2\n")
    _run_info(p, capsys, "4 vertices and 1 faces but 6 rows follow")


@pytest.mark.parametrize("pad", [4093, 10_000])
def test_an_off_under_a_long_block_of_comments_reads(tmp_path, capsys, pad):
    # the header was looked for in the first 4 KiB only: under a licence block the
    # counts were missing, or cut short where the 4 KiB ended (4093: the counts
    # line starts 2 bytes before it, "0004" was read as "00")
    comments = "".join(f"# {'x' * 60}\n" for _ in range(pad // 63 + 1))[:pad - 4]
    text = ("OFF\n" + comments + "\n0004 0002 0\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n"
            "3 0 1 2\n3 1 3 2\n")
    assert pad > 4096 or text.index("0004") == 4094
    out = tmp_path / "out.obj"
    assert facewrap("convert", _off(tmp_path, text), out) == 0, capsys.readouterr().err
    assert len(read_obj(out).triangles) == 2


# -- glTF: external files -------------------------------------------------------------------
def _gltf_beside(tmp_path, buffer_uri: str, image_uri: str | None = None) -> Path:
    """A .gltf whose one buffer is the file ``buffer_uri`` (and an image, if given)."""
    doc = quad_gltf_doc()
    doc["buffers"][0]["uri"] = buffer_uri
    if image_uri is not None:
        doc["images"] = [{"uri": image_uri}]
    (tmp_path / "scan.bin").write_bytes(_V.tobytes() + _I.tobytes())
    p = tmp_path / "scan.gltf"
    p.write_text(json.dumps(doc))
    return p


def _info_in_a_child(path: Path, limit_bytes: int | None = None):
    """``facewrap info PATH`` in a child process (a hang or a blow-up stays there)."""
    import os
    import subprocess
    import sys

    def limit():
        if limit_bytes:
            import resource
            resource.setrlimit(resource.RLIMIT_AS, (limit_bytes, limit_bytes))
    src = str(Path(__file__).resolve().parents[1] / "src")
    env = dict(os.environ, PYTHONPATH=src + os.pathsep + os.environ.get("PYTHONPATH", ""))
    try:
        return subprocess.run([sys.executable, "-m", "facewrap.cli", "info", str(path)],
                              capture_output=True, text=True, timeout=20, env=env,
                              preexec_fn=limit)
    except subprocess.TimeoutExpired:
        pytest.fail(f"facewrap info {path} hung")


@pytest.mark.parametrize("what", ["buffer", "image"])
def test_a_fifo_beside_a_gltf_is_named_not_opened(tmp_path, what):
    import os
    os.mkfifo(tmp_path / "fifo")
    p = (_gltf_beside(tmp_path, "fifo") if what == "buffer"
         else _gltf_beside(tmp_path, "scan.bin", "fifo"))
    done = _info_in_a_child(p)
    assert done.returncode == 2 and "is a fifo" in done.stderr, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1


def test_a_gltf_buffer_far_bigger_than_stated_is_refused_unread(tmp_path):
    p = _gltf_beside(tmp_path, "big.bin")
    with open(tmp_path / "big.bin", "wb") as fh:   # sparse: takes no disk
        fh.write(_V.tobytes() + _I.tobytes())
        fh.truncate(3 << 30)
    done = _info_in_a_child(p, limit_bytes=2 << 30)
    assert done.returncode == 2, done.stderr
    assert "has 3221225472 bytes, its byteLength says 72" in done.stderr, done.stderr


@pytest.mark.parametrize("where", ["../outside.bin", "/abs", "link.bin", "%2E%2E/outside.bin"])
def test_a_gltf_buffer_outside_its_folder_is_refused(tmp_path, capsys, where):
    folder = tmp_path / "scan"
    folder.mkdir()
    (tmp_path / "outside.bin").write_bytes(_V.tobytes() + _I.tobytes())
    (folder / "link.bin").symlink_to(tmp_path / "outside.bin")
    uri = str(tmp_path / "outside.bin") if where == "/abs" else where
    p = _gltf_beside(folder, uri)
    _run_info(p, capsys, "outside the glTF's folder")
    p = _gltf_beside(folder, "scan.bin")           # beside it, it reads
    assert facewrap("info", p) == 0
