"""Hostile input corpus: malformed and adversarial files through the CLI.

Every case of :data:`CASES` builds its inputs from the built-in sample, runs
``facewrap run`` / ``facewrap batch`` (or a reader, for formats no command reads
yet) and expects one of:

* ``error`` — exit status 2 and exactly one line on stderr naming the file and the
  problem, nothing written;
* ``job error`` — a batch job fails with one line naming the file (exit status 1),
  the other jobs finish;
* ``warning`` — legal but odd: a correct result and a one-line warning naming the
  file;
* ``ok`` — a correct result, no warning.

``docs/reliability.md`` is generated from this list (``python
tests/test_hostile.py`` rewrites it with the messages observed); a test checks
that it lists every case.  Hypothesis fuzzes the readers at the end.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import json
import os
import re
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings as hsettings, strategies as st

from facewrap.batch import read_manifest
from facewrap.errors import InputError
from facewrap.io import read_mesh
from facewrap.io.landmarks import read_landmarks, read_markers
from facewrap.io.obj import read_obj, write_obj
from facewrap.io.ply import read_ply, write_ply
from facewrap.jobs import load_job
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from conftest import facewrap

ROOT = Path(__file__).resolve().parents[1]
DOC = ROOT / "docs" / "reliability.md"


# -- the sample every case starts from ----------------------------------------------------
class Base:
    """Sample files (template 24, scan 40) and the result of the untouched job."""

    def __init__(self, folder: Path):
        self.template_mesh = make_template(24)
        scan = make_scan(self.template_mesh, resolution=40, texture_size=16)
        self.paths = write_sample(folder, self.template_mesh, scan)
        self.scan_V = np.asarray(scan.mesh.vertices)
        self.scan_T = np.asarray(scan.mesh.triangles)
        self.points = np.asarray(scan.landmarks.points)
        self.template_points = self.template_mesh.landmarks.positions(
            self.template_mesh.mesh)
        ctx = Ctx(folder / "base", self)
        assert facewrap("run", "-q", ctx.job()) == 0
        self.result = read_mesh(ctx.out).vertices
        self.report = json.loads(ctx.report_path.read_text())
        self.folder, self.digest = folder, digest(folder)


@dataclass
class Run:
    """How a case is run: CLI arguments or a reader call, and the file to blame."""
    culprit: Path
    argv: list | None = None
    call: Callable | None = None


class Ctx:
    """One case's folder, with writers of modified inputs and the job file."""

    def __init__(self, folder: Path, base: Base):
        self.dir, self.base = folder, base
        folder.mkdir(parents=True, exist_ok=True)
        self.out = folder / "out" / "fitted.obj"
        self.report_path = folder / "out" / "report.json"

    def write(self, name: str, data) -> Path:
        p = self.dir / name
        p.write_bytes(data if isinstance(data, bytes) else data.encode())
        return p

    def mesh(self, name: str, V, T) -> Path:
        p = self.dir / name
        (write_obj if name.endswith(".obj") else write_ply)(p, Mesh(V, T))
        return p

    def scan_text(self) -> str:
        return self.mesh("_scan.obj", self.base.scan_V, self.base.scan_T).read_text()

    def points(self, name: str, P) -> Path:
        return self.write(name, "".join(f"{x!r} {y!r} {z!r}\n"
                                        for x, y, z in np.asarray(P).tolist()))

    def job(self, report: bool = True, **inputs) -> Path:
        p = self.base.paths
        files = {"template": p["template"], "template_landmarks": p["template_landmarks"],
                 "scan": p["scan"], "scan_landmarks": p["scan_landmarks"], **inputs}
        body = "".join(f'{k} = "{v}"\n' for k, v in files.items())
        rep = 'report = "out/report.json"\n' if report else ""
        return self.write("job.toml", f'[inputs]\n{body}[outputs]\noutput = "out/fitted.obj"'
                                      f'\n{rep}[wrap]\nmodel = "rbf"\n')

    def run(self, culprit: Path, **inputs) -> Run:
        return Run(culprit, ["run", self.job(**inputs)])


@dataclass(frozen=True)
class Case:
    name: str
    kind: str
    what: str
    expect: str      # "error", "job error", "warning" or "ok"
    match: str       # regular expression the message must match
    build: Callable[[Ctx], Run]
    check: Callable | None = None  # (ctx, vertices) -> None, for results
    slow: bool = False


CASES: list[Case] = []


def case(kind, what, expect, match="", check=None, slow=False):
    def register(build):
        CASES.append(Case(build.__name__, kind, what, expect, match, build, check, slow))
        return build
    return register


def scan_with(ctx: Ctx, extra_V=None, extra_T=None, name="scan.obj") -> Run:
    V, T = ctx.base.scan_V, ctx.base.scan_T
    if extra_V is not None:
        V = np.vstack([V, extra_V])
    if extra_T is not None:
        T = np.vstack([T, extra_T])
    p = ctx.mesh(name, V, T)
    return ctx.run(p, scan=p)


def close_to_base(scale=1.0, offset=0.0, atol=1e-6):
    def check(ctx, V):
        expected = ctx.base.result * scale + offset
        np.testing.assert_allclose(V, expected, atol=atol * max(scale, 1.0))
    return check


def fits_like_base(ctx, V, scale=1.0):
    """Quality comparable to the untouched job (fit distances from the report), to
    1e-4 of the head's size: the untouched job fits its own surface to ~1e-15."""
    fit = json.loads(ctx.report_path.read_text())["metrics"]["fit_mean"]
    slack = 1e-4 * ctx.base.template_mesh.mesh.scale()
    assert fit <= scale * (1.5 * ctx.base.report["metrics"]["fit_mean"] + slack)


def fits_like_base_x1000(ctx, V):
    fits_like_base(ctx, V, 1000.0)


# -- OBJ ---------------------------------------------------------------------------------
@case("OBJ", "empty scan file", "error", "empty file")
def obj_empty(ctx):
    p = ctx.write("scan.obj", b"")
    return ctx.run(p, scan=p)


@case("OBJ", "comments and blank lines only", "error", r"no vertices")
def obj_comments_only(ctx):
    p = ctx.write("scan.obj", "# exported by nothing\n\n\n")
    return ctx.run(p, scan=p)


@case("OBJ", "truncated in the middle of a face line", "error", "at least 3 corners")
def obj_truncated(ctx):
    text = ctx.scan_text()
    cut = text.rindex("\nf ") + 1
    p = ctx.write("scan.obj", text[:cut] + " ".join(text[cut:].split()[:2]))
    return ctx.run(p, scan=p)


@case("OBJ", "binary garbage named .obj", "error", "binary data")
def obj_binary_garbage(ctx):
    p = ctx.write("scan.obj", np.random.default_rng(0).bytes(4096))
    return ctx.run(p, scan=p)


@case("OBJ", "UTF-16 encoded text (with its byte-order mark)", "ok", check=close_to_base())
def obj_utf16(ctx):
    p = ctx.write("scan.obj", ctx.scan_text().encode("utf-16"))
    return ctx.run(p, scan=p)


@case("OBJ", "a coordinate that is not a number", "error", "not a number")
def obj_not_a_number(ctx):
    text = ctx.scan_text().replace("\nv ", "\nv 1.0 abc 2.0\nv ", 1)
    p = ctx.write("scan.obj", text)
    return ctx.run(p, scan=p)


@case("OBJ", "NaN coordinate", "error", "NaN or infinite")
def obj_nan(ctx):
    p = ctx.write("scan.obj", ctx.scan_text().replace("\nv ", "\nv nan 0 0\nv ", 1))
    return ctx.run(p, scan=p)


@case("OBJ", "infinite coordinate (1e999)", "error", "NaN or infinite")
def obj_inf(ctx):
    p = ctx.write("scan.obj", ctx.scan_text().replace("\nv ", "\nv 1e999 0 0\nv ", 1))
    return ctx.run(p, scan=p)


@case("OBJ", "coordinates near the float limit (1e308)", "error", "too large")
def obj_huge_coordinates(ctx):
    p = ctx.write("scan.obj", ctx.scan_text().replace("\nv ", "\nv 1e308 -1e308 0\nv ", 1))
    return ctx.run(p, scan=p)


@case("OBJ", "face index beyond the vertex count", "error", "index 4294967299 out of range")
def obj_huge_index(ctx):
    p = ctx.write("scan.obj", ctx.scan_text() + "f 1 2 4294967299\n")
    return ctx.run(p, scan=p)


@case("OBJ", "face index beyond int64", "error", "beyond the int64 range")
def obj_overflow_index(ctx):
    p = ctx.write("scan.obj", ctx.scan_text() + "f 1 2 99999999999999999999999\n")
    return ctx.run(p, scan=p)


@case("OBJ", "negative (relative) index before the first vertex", "error", "out of range")
def obj_negative_index(ctx):
    p = ctx.write("scan.obj", ctx.scan_text() + "f -1 -2 -999999\n")
    return ctx.run(p, scan=p)


@case("OBJ", "face index 0 (OBJ counts from 1)", "error", "index 0")
def obj_zero_index(ctx):
    p = ctx.write("scan.obj", ctx.scan_text() + "f 0 1 2\n")
    return ctx.run(p, scan=p)


@case("OBJ", "vertices only (a point cloud)", "error", "no faces")
def obj_no_faces(ctx):
    text = "".join(ln + "\n" for ln in ctx.scan_text().splitlines() if ln.startswith("v "))
    p = ctx.write("scan.obj", text)
    return ctx.run(p, scan=p)


@case("OBJ", "classic Mac line ends (CR only)", "ok", check=close_to_base())
def obj_cr_line_ends(ctx):
    p = ctx.write("scan.obj", ctx.scan_text().replace("\n", "\r"))
    return ctx.run(p, scan=p)


# -- PLY ---------------------------------------------------------------------------------
def ply_bytes(ctx, binary=True) -> bytes:
    p = ctx.dir / "_scan.ply"
    write_ply(p, Mesh(ctx.base.scan_V, ctx.base.scan_T), binary=binary)
    return p.read_bytes()


@case("PLY", "binary PLY cut short", "error", "truncated")
def ply_truncated(ctx):
    p = ctx.write("scan.ply", ply_bytes(ctx)[:-1000])
    return ctx.run(p, scan=p)


@case("PLY", "header without end_header", "error", "end_header")
def ply_no_end_header(ctx):
    p = ctx.write("scan.ply", ply_bytes(ctx).split(b"end_header")[0])
    return ctx.run(p, scan=p)


@case("PLY", "header claims 10^12 vertices", "error", "truncated")
def ply_huge_count(ctx):
    data = re.sub(rb"element vertex \d+", b"element vertex 1000000000000", ply_bytes(ctx))
    p = ctx.write("scan.ply", data)
    return ctx.run(p, scan=p)


def sparse_file(ctx, name: str, head: bytes, size: int = 2 << 30) -> Path:
    """A file of ``size`` bytes that is ``head`` and then a hole (takes no disk)."""
    p = ctx.dir / name
    with open(p, "wb") as fh:
        fh.write(head)
        fh.truncate(size)
    return p


@case("PLY", "2 GB sparse binary PLY claiming 10^8 vertices", "error", "needs at least")
def ply_sparse_2gb(ctx):
    head = (b"ply\nformat binary_little_endian 1.0\nelement vertex 100000000\n"
            b"property double x\nproperty double y\nproperty double z\n"
            b"element face 1\nproperty list uchar int vertex_indices\nend_header\n")
    p = sparse_file(ctx, "scan.ply", head)
    return ctx.run(p, scan=p)


@case("OBJ", "2 GB sparse OBJ (a few vertices, then a hole)", "error", "binary data")
def obj_sparse_2gb(ctx):
    p = sparse_file(ctx, "scan.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return ctx.run(p, scan=p)


@case("PLY", "face index out of range", "error", "out of range")
def ply_index_out_of_range(ctx):
    text = ply_bytes(ctx, binary=False).decode().rstrip("\n").rsplit(" ", 1)[0]
    p = ctx.write("scan.ply", text + " 99999999\n")
    return ctx.run(p, scan=p)


@case("PLY", "NaN coordinate (ASCII)", "error", "NaN or infinite")
def ply_nan(ctx):
    head, body = ply_bytes(ctx, binary=False).split(b"end_header\n")
    first, rest = body.split(b"\n", 1)
    p = ctx.write("scan.ply", head + b"end_header\nnan 0 0\n" + rest)
    return ctx.run(p, scan=p)


@case("PLY", "not a PLY file (first line)", "error", "not a PLY file")
def ply_not_ply(ctx):
    p = ctx.write("scan.ply", b"plx\n" + ply_bytes(ctx)[4:])
    return ctx.run(p, scan=p)


@case("PLY", "unknown property type", "error", "unknown property type")
def ply_unknown_type(ctx):
    data = ply_bytes(ctx).replace(b"property double x", b"property float128 x", 1)
    p = ctx.write("scan.ply", data)
    return ctx.run(p, scan=p)


# -- landmarks ---------------------------------------------------------------------------
@case("landmarks", "empty scan landmark file", "error", "empty file")
def lm_empty(ctx):
    p = ctx.write("scan_landmarks.txt", "")
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "67 scan landmarks for 68 template landmarks", "error",
      "has 67 landmarks but")
def lm_count_mismatch(ctx):
    p = ctx.points("scan_landmarks.txt", ctx.base.points[:67])
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "template landmark vertex id beyond the template", "error",
      "out of range")
def lm_index_out_of_range(ctx):
    ids = ctx.base.paths["template_landmarks"].read_text().split()
    p = ctx.write("template_landmarks.txt", "\n".join(ids[:-1] + ["1000000"]))
    return ctx.run(p, template_landmarks=p)


@case("landmarks", "negative template landmark vertex id", "error",
      "negative vertex index")
def lm_negative_index(ctx):
    ids = ctx.base.paths["template_landmarks"].read_text().split()
    p = ctx.write("template_landmarks.txt", "\n".join(["-5"] + ids[1:]))
    return ctx.run(p, template_landmarks=p)


@case("landmarks", "vertex id beyond int64", "error", "too large")
def lm_huge_index(ctx):
    ids = ctx.base.paths["template_landmarks"].read_text().split()
    p = ctx.write("template_landmarks.txt", "\n".join(["99999999999999999999999"] + ids[1:]))
    return ctx.run(p, template_landmarks=p)


@case("landmarks", "NaN landmark coordinate", "error", "NaN or infinite")
def lm_nan(ctx):
    text = ctx.points("x.txt", ctx.base.points).read_text().split("\n", 1)
    p = ctx.write("scan_landmarks.txt", "nan 1 2\n" + text[1])
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "all landmarks far from the scan (another scan's file)", "error",
      "not on the scan")
def lm_all_off_mesh(ctx):
    p = ctx.points("scan_landmarks.txt", ctx.base.points + [0, 0, 3000.0])
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "three landmarks 60 mm off the scan surface", "warning",
      r"3 landmark\(s\) lie off the scan surface")
def lm_some_off_mesh(ctx):
    P = ctx.base.points.copy()
    P[[0, 8, 16], 2] += 60.0
    p = ctx.points("scan_landmarks.txt", P)
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "landmarks on one line", "error", "on one line")
def lm_collinear(ctx):
    P = ctx.base.points[0] + np.linspace(0, 50, 68)[:, None] * [1.0, 0.5, 0.2]
    p = ctx.points("scan_landmarks.txt", P)
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "all landmarks at one point", "error", "at one point")
def lm_coincident(ctx):
    p = ctx.points("scan_landmarks.txt", np.repeat(ctx.base.points[:1], 68, axis=0))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "broken JSON", "error", "invalid JSON")
def lm_bad_json(ctx):
    p = ctx.write("scan_landmarks.json", '{"format": "facewrap.landmarks", "landmarks": [')
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "facewrap JSON with a name used twice", "error", "unique")
def lm_duplicate_names(ctx):
    items = [{"name": "tip" if k < 2 else f"p{k}", "point": list(map(float, q))}
             for k, q in enumerate(ctx.base.points)]
    p = ctx.write("scan_landmarks.json", json.dumps(
        {"format": "facewrap.landmarks", "version": 1, "landmarks": items}))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "menpo LJSON with a missing (null) point", "error",
      r"not an \[x, y, z\] point")
def lm_ljson_null_point(ctx):
    pts = ctx.base.points.tolist()
    pts[5] = None
    p = ctx.write("scan.ljson", json.dumps({"version": 2, "landmarks": {"points": pts}}))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "binary garbage as landmarks", "error", "binary data")
def lm_binary(ctx):
    p = ctx.write("scan_landmarks.txt", np.random.default_rng(1).bytes(500))
    return ctx.run(p, scan_landmarks=p)


# -- STL, OFF, glTF scans (through trimesh) and iBUG .pts landmarks ------------------------
def trimesh_scan(ctx, name: str, **kw) -> bytes:
    """The sample scan exported by trimesh (the format from ``name``'s extension)."""
    import trimesh
    p = ctx.dir / ("_" + name)
    trimesh.Trimesh(ctx.base.scan_V, ctx.base.scan_T, process=False).export(p, **kw)
    return p.read_bytes()


def glb_bytes(doc: dict) -> bytes:
    """A GLB file holding only the glTF JSON ``doc``."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    return (b"glTF" + (2).to_bytes(4, "little") + (20 + len(js)).to_bytes(4, "little")
            + len(js).to_bytes(4, "little") + b"JSON" + js)


@case("STL", "binary STL scan (a triangle soup: corners merged)", "ok",
      check=close_to_base(atol=1e-3))
def stl_binary_ok(ctx):
    p = ctx.write("scan.stl", trimesh_scan(ctx, "scan.stl"))
    return ctx.run(p, scan=p)


@case("STL", "binary STL cut short", "error", r"header says \d+ triangles")
def stl_truncated(ctx):
    p = ctx.write("scan.stl", trimesh_scan(ctx, "scan.stl")[:-100])
    return ctx.run(p, scan=p)


@case("STL", "2 GB sparse STL claiming 10^9 triangles", "error", "header says 1000000000")
def stl_sparse_2gb(ctx):
    p = sparse_file(ctx, "scan.stl", b"\0" * 80 + (10 ** 9).to_bytes(4, "little"))
    return ctx.run(p, scan=p)


@case("OFF", "OFF scan", "ok", check=close_to_base(atol=1e-3))
def off_ok(ctx):
    p = ctx.write("scan.off", trimesh_scan(ctx, "scan.off"))
    return ctx.run(p, scan=p)


@case("OFF", "header counts more faces than follow", "error", "rows follow")
def off_bad_counts(ctx):
    text = trimesh_scan(ctx, "scan.off").decode()
    nv, nf = len(ctx.base.scan_V), len(ctx.base.scan_T)
    p = ctx.write("scan.off", text.replace(f"{nv} {nf} 0", f"{nv} {nf + 50} 0", 1))
    return ctx.run(p, scan=p)


@case("OFF", "face index beyond the vertex count", "error", "outside the range|must lie in")
def off_bad_index(ctx):
    lines = trimesh_scan(ctx, "scan.off").decode().splitlines()
    lines[-1] = f"3 0 1 {len(ctx.base.scan_V) + 7}"
    p = ctx.write("scan.off", "\n".join(lines) + "\n")
    return ctx.run(p, scan=p)


@case("glTF", "GLB scan placed by its node's transform", "ok",
      check=close_to_base(atol=1e-3))
def glb_node_transform_ok(ctx):
    import trimesh
    move = trimesh.transformations.translation_matrix([0, 0, 50.0])
    scene = trimesh.Scene()
    scene.add_geometry(trimesh.Trimesh(ctx.base.scan_V - move[:3, 3], ctx.base.scan_T,
                                       process=False), node_name="scan", transform=move)
    p = ctx.dir / "scan.glb"
    scene.export(p)
    return ctx.run(p, scan=p)


@case("glTF", "GLB with no mesh (an empty scene)", "error", "holds no triangle mesh")
def glb_no_mesh(ctx):
    p = ctx.write("scan.glb", glb_bytes({"asset": {"version": "2.0"}, "scene": 0,
                                         "scenes": [{"nodes": []}]}))
    return ctx.run(p, scan=p)


@case("glTF", "GLB cut short", "error", "truncated GLB")
def glb_truncated(ctx):
    p = ctx.write("scan.glb", trimesh_scan(ctx, "scan.glb")[:-64])
    return ctx.run(p, scan=p)


@case("glTF", ".gltf that is not JSON", "error", "not glTF JSON")
def gltf_not_json(ctx):
    p = ctx.write("scan.gltf", "solid scan\nfacet normal 0 0 1\n")
    return ctx.run(p, scan=p)


def pts_text(P) -> str:
    rows = "".join(" ".join(repr(float(x)) for x in r) + "\n" for r in np.asarray(P))
    return f"version: 1\nn_points: {len(P)}\n{{\n{rows}}}\n"


@case("landmarks", "iBUG .pts scan landmarks (3-D rows)", "ok", check=close_to_base())
def pts_3d_ok(ctx):
    p = ctx.write("scan_landmarks.pts", pts_text(ctx.base.points))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", "iBUG .pts with 2-D rows (image landmarks)", "error",
      "2-D landmarks; facewrap needs 3-D points")
def pts_2d(ctx):
    p = ctx.write("scan_landmarks.pts", pts_text(ctx.base.points[:, :2]))
    return ctx.run(p, scan_landmarks=p)


@case("landmarks", ".pts whose n_points disagrees with its rows", "error",
      "n_points says")
def pts_count(ctx):
    text = pts_text(ctx.base.points)
    p = ctx.write("scan_landmarks.pts", text.replace(f"n_points: {len(ctx.base.points)}",
                                                     f"n_points: {len(ctx.base.points) + 1}"))
    return ctx.run(p, scan_landmarks=p)


# -- markers (read by transfer jobs; the reader directly) ---------------------------------
@case("markers", "count line disagrees with the pairs", "error", "count line says 3")
def markers_count_mismatch(ctx):
    p = ctx.write("markers.cons", "3\n1 2\n4 5\n")
    return Run(p, call=lambda: read_markers(p))


@case("markers", "negative vertex id", "error", "negative vertex id")
def markers_negative(ctx):
    p = ctx.write("markers.txt", "1 2\n-4 5\n")
    return Run(p, call=lambda: read_markers(p))


@case("markers", "JSON pairs that are not integers", "error", "integers")
def markers_not_integers(ctx):
    p = ctx.write("markers.json", '{"format": "facewrap.markers", "pairs": [[1.5, 2]]}')
    return Run(p, call=lambda: read_markers(p))


@case("markers", "id beyond int64", "error", "too large")
def markers_huge(ctx):
    p = ctx.write("markers.txt", "99999999999999999999999 1\n")
    return Run(p, call=lambda: read_markers(p))


@case("markers", "broken YAML", "error", "invalid YAML")
def markers_bad_yaml(ctx):
    p = ctx.write("markers.yaml", "markers: [\n")
    return Run(p, call=lambda: read_markers(p))


# -- manifests ---------------------------------------------------------------------------
def manifest(ctx, rows: list[str], header="scan,scan_landmarks,output") -> Run:
    ctx.job(report=False)
    p = ctx.write("manifest.csv", header + "\n" + "\n".join(rows) + "\n")
    return Run(p, ["batch", p, "--job", ctx.dir / "job.toml", "--workers", "1", "-q"])


def good_row(ctx, out="a.obj") -> str:
    return f"{ctx.base.paths['scan']},{ctx.base.paths['scan_landmarks']},{out}"


@case("manifest", "unknown column", "error", "unknown column 'colour'")
def manifest_unknown_column(ctx):
    return manifest(ctx, [good_row(ctx) + ",red"], "scan,scan_landmarks,output,colour")


@case("manifest", "two jobs write one file", "error", "both write")
def manifest_duplicate_output(ctx):
    return manifest(ctx, [good_row(ctx), good_row(ctx)])


@case("manifest", "an output that is an input", "error", "also an input|an input of job")
def manifest_output_is_input(ctx):
    return manifest(ctx, [good_row(ctx, str(ctx.base.paths["template"]))])


@case("manifest", "a value of the wrong type", "error", "must be a number")
def manifest_bad_value(ctx):
    return manifest(ctx, [good_row(ctx) + ",lots"], "scan,scan_landmarks,output,smoothing")


@case("manifest", "binary garbage", "error", "binary data|not UTF-8")
def manifest_binary(ctx):
    p = ctx.write("manifest.csv", np.random.default_rng(2).bytes(300))
    return Run(p, ["batch", p])


@case("manifest", "one job's scan is missing", "job error", "no such file")
def manifest_missing_scan(ctx):
    missing = ctx.dir / "nowhere.obj"
    run = manifest(ctx, [good_row(ctx, "a.obj"), f"{missing},"
                         f"{ctx.base.paths['scan_landmarks']},b.obj"])
    return Run(missing, run.argv)


# -- job files (TOML) ---------------------------------------------------------------------
@case("TOML", "invalid TOML", "error", "invalid TOML")
def toml_invalid(ctx):
    p = ctx.write("job.toml", "[inputs\nscan = 1\n")
    return Run(p, ["run", p])


@case("TOML", "misspelt key", "error", "unknown key 'smothing'")
def toml_unknown_key(ctx):
    p = ctx.job()
    p.write_text(p.read_text() + "smothing = 0.1\n")
    return Run(p, ["run", p])


@case("TOML", "a value of the wrong type", "error", "must be a number")
def toml_wrong_type(ctx):
    p = ctx.job()
    p.write_text(p.read_text() + 'smoothing = "high"\n')
    return Run(p, ["run", p])


@case("TOML", "empty job file", "error", "empty file")
def toml_empty(ctx):
    p = ctx.write("job.toml", "")
    return Run(p, ["run", p])


@case("TOML", "output is an input", "error", "also an input")
def toml_output_over_input(ctx):
    p = ctx.job()
    p.write_text(p.read_text().replace('"out/fitted.obj"', f'"{ctx.base.paths["scan"]}"'))
    return Run(p, ["run", p])


# -- geometry: legal but odd -----------------------------------------------------------------
@case("geometry", "scan faces with a repeated vertex", "warning", "repeated vertex",
      check=fits_like_base)
def scan_repeated_vertex_faces(ctx):
    T = ctx.base.scan_T
    return scan_with(ctx, extra_T=np.stack([T[:20, 0], T[:20, 0], T[:20, 1]], axis=1))


@case("geometry", "zero-area (collinear) scan triangles", "warning", "zero-area",
      check=fits_like_base)
def scan_zero_area(ctx):
    V, n = ctx.base.scan_V, len(ctx.base.scan_V)
    mid = (V[ctx.base.scan_T[:10, 0]] + V[ctx.base.scan_T[:10, 1]]) / 2
    T = np.stack([ctx.base.scan_T[:10, 0], ctx.base.scan_T[:10, 1], n + np.arange(10)], 1)
    return scan_with(ctx, mid, T)


@case("geometry", "non-manifold edges (fins on the scan)", "warning", "non-manifold",
      check=fits_like_base)
def scan_non_manifold(ctx):
    V, T, n = ctx.base.scan_V, ctx.base.scan_T, len(ctx.base.scan_V)
    tips = V[T[:10]].mean(axis=1) + [0, 0, 2.0]
    return scan_with(ctx, tips, np.stack([T[:10, 0], T[:10, 1], n + np.arange(10)], 1))


@case("geometry", "the scan cut off below the mouth (its landmarks clicked before)",
      "warning", "lie past the edge of the scan")
def scan_chin_cut(ctx):
    V, T, P = ctx.base.scan_V, ctx.base.scan_T, ctx.base.points
    keep = ~(V[T, 1] < 0.5 * (P[57, 1] + P[8, 1])).any(axis=1)
    used = np.unique(T[keep])
    index = np.full(len(V), -1)
    index[used] = np.arange(len(used))
    p = ctx.mesh("scan.obj", V[used], index[T[keep]])
    return ctx.run(p, scan=p)


@case("geometry", "a loose piece far from the face", "warning", "disconnected pieces",
      check=fits_like_base)
def scan_disconnected(ctx):
    V, T, n = ctx.base.scan_V, ctx.base.scan_T, len(ctx.base.scan_V)
    piece = V[T[:30]].reshape(-1, 3) + [400.0, 0, 0]
    return scan_with(ctx, piece, n + np.arange(len(piece)).reshape(-1, 3))


@case("geometry", "every vertex duplicated (unwelded triangle soup)", "warning",
      "duplicate vertices", check=fits_like_base)
def scan_duplicate_vertices(ctx):
    V, T = ctx.base.scan_V, ctx.base.scan_T
    p = ctx.mesh("scan.obj", V[T].reshape(-1, 3), np.arange(3 * len(T)).reshape(-1, 3))
    return ctx.run(p, scan=p)


@case("geometry", "template face with a repeated vertex", "warning",
      "template has 1 triangle")
def template_repeated_vertex_face(ctx):
    tm = read_mesh(ctx.base.paths["template"])
    p = ctx.dir / "template.obj"
    write_obj(p, Mesh(tm.vertices, list(tm.polygons()) + [[0, 0, 1]]))
    return ctx.run(p, template=p)


@case("geometry", "scan 100 m away from the origin", "ok",
      check=close_to_base(offset=np.array([1e5, -1e5, 1e5]), atol=0.1))
def scan_far_away(ctx):
    off = np.array([1e5, -1e5, 1e5])
    p = ctx.mesh("scan.obj", ctx.base.scan_V + off, ctx.base.scan_T)
    lm = ctx.points("scan_landmarks.txt", ctx.base.points + off)
    return Run(p, ["run", ctx.job(scan=p, scan_landmarks=lm)])


@case("geometry", "scan in other units (x1000)", "warning", r"scaled by \d{4}",
      check=fits_like_base_x1000)
def scan_other_scale(ctx):
    p = ctx.mesh("scan.obj", ctx.base.scan_V * 1000, ctx.base.scan_T)
    lm = ctx.points("scan_landmarks.txt", ctx.base.points * 1000)
    return Run(p, ["run", ctx.job(scan=p, scan_landmarks=lm)])


# -- plausibility: inputs that read fine but cannot be fitted as given -------------------
MIRROR_X = np.array([-1.0, 1.0, 1.0])


@case("plausibility", "mirrored scan with mirrored landmarks", "error", "mirror image")
def mirrored_scan_and_landmarks(ctx):
    p = ctx.mesh("scan.obj", ctx.base.scan_V * MIRROR_X, ctx.base.scan_T[:, ::-1])
    lm = ctx.points("scan_landmarks.txt", ctx.base.points * MIRROR_X)
    return ctx.run(lm, scan=p, scan_landmarks=lm)


@case("plausibility", "jaw landmarks in reversed order", "warning",
      "wrong order, pairing or a left/right")
def jaw_landmarks_reversed(ctx):
    P = ctx.base.points.copy()
    P[:17] = P[:17][::-1]
    lm = ctx.points("scan_landmarks.txt", P)
    return ctx.run(lm, scan_landmarks=lm)


@case("plausibility", "scan landmarks named, template landmarks not", "error",
      "names")
def landmark_names_on_one_side(ctx):
    text = "".join(f"{x!r} {y!r} {z!r} point_{i}\n"
                   for i, (x, y, z) in enumerate(ctx.base.points.tolist()))
    lm = ctx.write("scan_landmarks.txt", text)
    return ctx.run(lm, scan_landmarks=lm)


@case("plausibility", "a scan landmark given twice", "warning", "at the same point")
def landmark_given_twice(ctx):
    P = ctx.base.points.copy()
    P[30] = P[33]
    lm = ctx.points("scan_landmarks.txt", P)
    return ctx.run(lm, scan_landmarks=lm)


@case("plausibility", "every scan face flipped", "warning", "faces are flipped",
      check=fits_like_base)
def scan_faces_flipped(ctx):
    p = ctx.mesh("scan.obj", ctx.base.scan_V, ctx.base.scan_T[:, ::-1])
    return ctx.run(p, scan=p)


@case("plausibility", "every scan face duplicated", "warning", "duplicated faces",
      check=fits_like_base)
def scan_faces_duplicated(ctx):
    T = ctx.base.scan_T
    p = ctx.mesh("scan.obj", ctx.base.scan_V, np.vstack([T, T]))
    return ctx.run(p, scan=p)


@case("plausibility", "left and right eye landmarks swapped", "warning",
      "wrong order, pairing or a left/right")
def eyes_swapped(ctx):
    P = ctx.base.points.copy()
    P[36:42], P[42:48] = ctx.base.points[42:48], ctx.base.points[36:42]
    lm = ctx.points("scan_landmarks.txt", P)
    return ctx.run(lm, scan_landmarks=lm)


@case("plausibility", "scan landmarks shuffled", "warning",
      "wrong order, pairing or a left/right")
def landmarks_shuffled(ctx):
    order = np.random.default_rng(5).permutation(len(ctx.base.points))
    lm = ctx.points("scan_landmarks.txt", ctx.base.points[order])
    return ctx.run(lm, scan_landmarks=lm)


def equals_template(ctx, V):
    T = read_mesh(ctx.base.paths["template"]).vertices
    np.testing.assert_allclose(V, T, atol=1e-9 * np.ptp(T))


@case("geometry", "scan identical to the template (its eyes are separate pieces)",
      "warning", "scan has 3 disconnected pieces", check=equals_template)
def scan_identical(ctx):
    lm = ctx.points("scan_landmarks.txt", ctx.base.template_points)
    return ctx.run(ctx.base.paths["template"], scan=ctx.base.paths["template"],
                   scan_landmarks=lm)


@case("geometry", "a scan of one triangle (landmarks on it)", "warning",
      "only 1 triangle")
def scan_one_triangle(ctx):
    P = ctx.base.points.copy()
    P[:, 2] = P[:, 2].mean()
    lo, hi = P.min(axis=0) - 10, P.max(axis=0) + 10
    tri = np.array([[lo[0], lo[1], lo[2]], [2 * hi[0] - lo[0] + 20, lo[1], lo[2]],
                    [lo[0], 2 * hi[1] - lo[1] + 20, lo[2]]])
    p = ctx.mesh("scan.obj", tri, [[0, 1, 2]])
    lm = ctx.points("scan_landmarks.txt", P)
    return Run(p, ["run", ctx.job(scan=p, scan_landmarks=lm)])


@case("geometry", "scan collapsed to a point", "error", "zero area")
def scan_collapsed(ctx):
    p = ctx.mesh("scan.obj", np.zeros_like(ctx.base.scan_V) + 5.0, ctx.base.scan_T)
    return ctx.run(p, scan=p)


@case("geometry", "a million-triangle scan (slow; see benchmarks/bench_memory.py)", "ok",
      check=fits_like_base, slow=True)
def scan_million_triangles(ctx):
    scan = make_scan(ctx.base.template_mesh, resolution=1000, texture_size=8)
    p = ctx.mesh("scan.obj", scan.mesh.vertices, scan.mesh.triangles)
    lm = ctx.points("scan_landmarks.txt", scan.landmarks.points)
    return Run(p, ["run", ctx.job(scan=p, scan_landmarks=lm)])


# -- outputs: never on an input, creatable, checked before any work -------------------------
def sample_copy(ctx) -> dict:
    """The sample's files copied into the case's folder (so a failure harms no other case)."""
    own = {}
    for key, src in ctx.base.paths.items():
        dst = ctx.dir / "in" / Path(src).relative_to(Path(ctx.base.paths["template"]).parent)
        dst.parent.mkdir(parents=True, exist_ok=True)
        dst.write_bytes(Path(src).read_bytes())
        own[key] = dst
    return own


def wrap_argv(p: dict, *more) -> list:
    return ["wrap", p["template"], p["scan"], "--template-landmarks",
            p["template_landmarks"], "--scan-landmarks", p["scan_landmarks"],
            "--model", "rbf", "-q", *more]


def transfer_argv(ctx, p: dict, shapes, *more) -> list:
    ids = p["template_landmarks"].read_text().split()[:12]
    markers = ctx.write("markers.txt", "".join(f"{i} {i}\n" for i in ids))
    return ["transfer", p["template"], p["template"], "--markers", markers,
            "--source-shapes", shapes, "-q", *more]


def track_argv(ctx, p: dict, *more) -> list:
    seq = ctx.dir / "seq"
    seq.mkdir()
    (seq / "frame_0000.obj").write_bytes(p["scan"].read_bytes())
    return ["track", p["template"], seq, "--template-landmarks", p["template_landmarks"],
            "--scan-landmarks", p["scan_landmarks"], "--model", "rbf", "-q", *more]


def in_the_way(ctx) -> Path:
    return ctx.write("a_file", "a file where a folder is needed\n")


@case("outputs", "convert onto its own input", "error", "also an input")
def convert_onto_input(ctx):
    p = sample_copy(ctx)["scan"]
    return Run(p, ["convert", p, p])


@case("outputs", "convert onto a link to its input", "error", "also an input")
def convert_onto_symlink(ctx):
    p = sample_copy(ctx)["scan"]
    link = ctx.dir / "link.obj"
    os.symlink(p, link)
    return Run(p, ["convert", p, link])


@case("outputs", "wrap -o the scan, spelt with ..", "error", "also an input")
def wrap_output_is_scan(ctx):
    p = sample_copy(ctx)
    return Run(p["scan"], wrap_argv(p, "-o", p["scan"].parent / "blendshapes" / ".." /
                                    p["scan"].name))


@case("outputs", "wrap --report onto the landmarks", "error", "also an input")
def wrap_report_on_landmarks(ctx):
    p = sample_copy(ctx)
    return Run(p["scan_landmarks"], wrap_argv(p, "-o", ctx.out, "--report",
                                              p["scan_landmarks"]))


@case("outputs", "wrap -o inside the blendshapes folder", "error", "lies in the input folder")
def wrap_output_in_blendshapes(ctx):
    p = sample_copy(ctx)
    shapes = p["blendshapes/blink"].parent
    return Run(shapes, wrap_argv(p, "--blendshapes", shapes, "-o", shapes / "fit.obj"))


@case("outputs", "run: a job file's report is the template", "error", "also an input")
def run_report_is_template(ctx):
    p = ctx.job()
    p.write_text(p.read_text().replace('"out/report.json"',
                                       f'"{ctx.base.paths["template"]}"'))
    return Run(ctx.base.paths["template"], ["run", p])


@case("outputs", "batch: a job writes into its blendshapes folder", "error",
      "lies in the input folder")
def batch_output_in_blendshapes(ctx):
    shapes = sample_copy(ctx)["blendshapes/blink"].parent
    return manifest(ctx, [good_row(ctx, str(shapes / "fit.obj")) + f",{shapes}"],
                    "scan,scan_landmarks,output,blendshapes")


@case("outputs", "batch: one job writes another's scan", "error", "an input of job 2")
def batch_job_writes_other_input(ctx):
    p = sample_copy(ctx)
    return manifest(ctx, [good_row(ctx, str(p["scan"])),
                          f"{p['scan']},{p['scan_landmarks']},b.obj"])


@case("outputs", "transfer -o the --source-shapes folder", "error", "also an input")
def transfer_into_source_shapes(ctx):
    p = sample_copy(ctx)
    shapes = p["blendshapes/blink"].parent
    return Run(shapes, transfer_argv(ctx, p, shapes, "-o", shapes))


@case("outputs", "transfer --gltf with neither .glb nor .gltf", "error", r"\.glb \(binary\)")
def transfer_gltf_extension(ctx):
    p = sample_copy(ctx)
    shapes = p["blendshapes/blink"].parent
    bad = ctx.dir / "shapes.obj"
    return Run(bad, transfer_argv(ctx, p, shapes, "-o", ctx.dir / "out", "--gltf", bad))


@case("outputs", "wrap --gltf with neither .glb nor .gltf", "error", r"\.glb \(binary\)")
def wrap_gltf_extension(ctx):
    p = sample_copy(ctx)
    bad = ctx.dir / "out" / "fitted.fbx"
    return Run(bad, wrap_argv(p, "-o", ctx.out, "--gltf", bad))


@case("outputs", "wrap --gltf onto its own GLB scan", "error", "also an input")
def wrap_gltf_onto_scan(ctx):
    p = sample_copy(ctx)
    scan = ctx.write("scan.glb", trimesh_scan(ctx, "scan.glb"))
    return Run(scan, ["wrap", p["template"], scan, "--template-landmarks",
                      p["template_landmarks"], "--scan-landmarks", p["scan_landmarks"],
                      "--model", "rbf", "-q", "-o", ctx.out, "--gltf", scan])


@case("outputs", "wrap --gltf an existing folder", "error", "is a folder")
def wrap_gltf_is_folder(ctx):
    p = sample_copy(ctx)
    folder = ctx.dir / "fitted.glb"
    folder.mkdir()
    (folder / "keep.txt").write_text("a file of the user's\n")
    return Run(folder, wrap_argv(p, "-o", ctx.out, "--gltf", folder))


@case("outputs", "wrap --gltf and --report the same file", "error", "same file")
def wrap_gltf_is_report(ctx):
    p = sample_copy(ctx)
    both = ctx.dir / "out" / "fitted.gltf"
    return Run(both, wrap_argv(p, "-o", ctx.out, "--report", both, "--gltf", both))


@case("outputs", "run: a job file's gltf key with an unknown extension", "error",
      r"\.glb \(binary\)")
def run_gltf_extension(ctx):
    p = ctx.job()
    p.write_text(p.read_text().replace('[wrap]', 'gltf = "out/fitted.usdz"\n[wrap]'))
    return Run(ctx.dir / "out" / "fitted.usdz", ["run", p])


@case("outputs", "convert: OUT.mtl would overwrite the input's library", "error",
      "also an input")
def convert_library_onto_input(ctx):
    p = sample_copy(ctx)
    # scan.OBJ is another file than scan.obj, but its library would be scan.mtl
    return Run(p["scan_mtl"], ["convert", p["scan"], p["scan"].with_name("scan.OBJ")])


@case("outputs", "transfer: a source shape file inside -o", "error", "also an input")
def transfer_shape_file_in_out(ctx):
    p = sample_copy(ctx)
    smile = p["blendshapes/smile"]
    return Run(smile, transfer_argv(ctx, p, smile, "-o", smile.parent))


@case("outputs", "track -o the scan folder", "error", "lies in the input folder")
def track_into_scan_folder(ctx):
    p = sample_copy(ctx)
    return Run(ctx.dir / "seq", track_argv(ctx, p, "-o", ctx.dir / "seq"))


@case("outputs", "evaluate --json onto the result", "error", "also an input")
def evaluate_json_on_result(ctx):
    p = sample_copy(ctx)
    return Run(p["template"], ["evaluate", p["template"], p["scan"], "--json",
                               p["template"], "-q"])


@case("outputs", "evaluate --heatmap onto the scan's texture", "error", r"read with")
def evaluate_heatmap_on_texture(ctx):
    p = sample_copy(ctx)
    return Run(p["scan_texture"], ["evaluate", p["template"], p["scan"], "--heatmap",
                                   p["scan_texture"], "-q"])


@case("outputs", "report -o the folder of a run JSON named index.html", "error",
      "also an input")
def report_over_run_json(ctx):
    run = ctx.write("index.html", json.dumps(ctx.base.report))
    return Run(run, ["report", run, "-o", ctx.dir])


@case("outputs", "animate -o the folder of its start frame", "error", "also an input")
def animate_over_start(ctx):
    p = sample_copy(ctx)
    start = ctx.dir / "frame_0000.obj"
    start.write_bytes(p["template"].read_bytes())
    return Run(start, ["animate", start, p["template"], "--frames", "2", "-o", ctx.dir])


@case("outputs", "sample into a folder holding a template.obj of the user's", "error",
      "already exists")
def sample_over_users_file(ctx):
    mine = ctx.write("template.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return Run(mine, ["sample", ctx.dir])


# outputs that cannot be created (a path through a file, a file where a folder goes):
# name -> (what, build(ctx, sample copy, file in the way) -> (culprit, argv))
CANNOT_CREATE = {
    "wrap_output_through_file": ("wrap -o under a path through a file", lambda ctx, p, f: (
        f / "x.obj", wrap_argv(p, "-o", f / "x.obj"))),
    "wrap_report_through_file": ("wrap --report under a path through a file",
                                 lambda ctx, p, f: (f / "r.json", wrap_argv(
                                     p, "-o", ctx.out, "--report", f / "r.json"))),
    "transfer_gltf_through_file": ("transfer --gltf under a path through a file",
                                   lambda ctx, p, f: (f / "x.glb", transfer_argv(
                                       ctx, p, p["blendshapes/blink"].parent, "-o",
                                       ctx.dir / "shapes", "--gltf", f / "x.glb"))),
    "wrap_gltf_through_file": ("wrap --gltf under a path through a file",
                               lambda ctx, p, f: (f / "x.glb", wrap_argv(
                                   p, "-o", ctx.out, "--gltf", f / "x.glb"))),
    "track_out_is_file": ("track -o a file", lambda ctx, p, f: (
        f, track_argv(ctx, p, "-o", f))),
    "evaluate_heatmap_through_file": ("evaluate --heatmap under a path through a file",
                                      lambda ctx, p, f: (f / "h.png", [
                                          "evaluate", p["template"], p["scan"],
                                          "--heatmap", f / "h.png"])),
    "report_out_is_file": ("report -o a file", lambda ctx, p, f: (f, [
        "report", ctx.write("run.json", json.dumps(ctx.base.report)), "-o", f])),
    "convert_onto_folder": ("convert to a folder", lambda ctx, p, f: (
        p["blendshapes/blink"].parent, ["convert", p["scan"], p["blendshapes/blink"].parent])),
    "animate_out_through_file": ("animate -o under a path through a file",
                                 lambda ctx, p, f: (f / "a", [
                                     "animate", p["template"], p["template"], "-o", f / "a"])),
    "sample_into_file": ("sample into a file", lambda ctx, p, f: (f, ["sample", f])),
    "demo_through_file": ("demo --out under a path through a file", lambda ctx, p, f: (
        f / "demo", ["demo", "--out", f / "demo", "-q"])),
}


def _cannot_create(build):
    def run(ctx):
        culprit, argv = build(ctx, sample_copy(ctx), in_the_way(ctx))
        return Run(culprit, argv)
    return run


for _name, (_what, _build) in CANNOT_CREATE.items():
    CASES.append(Case(_name, "outputs", _what, "error", "is a (file|folder)",
                      _cannot_create(_build)))


# -- running the corpus -------------------------------------------------------------------------
def run_case(c: Case, folder: Path, base: Base, capsys=None
             ) -> tuple[int, list[str], Ctx, Run]:
    ctx = Ctx(folder, base)
    r = c.build(ctx)
    ctx.before = digest(folder)   # the case's inputs, as built
    if r.call is not None:
        try:
            r.call()
            rc, lines = 0, []
        except InputError as exc:
            rc, lines = 2, [f"facewrap: error: {exc}"]
    else:
        if capsys is not None:
            capsys.readouterr()
        rc = facewrap(*r.argv)
        lines = capsys.readouterr().err.strip().splitlines() if capsys else []
    return rc, lines, ctx, r


#: files larger than this (the sparse 2 GB cases) are fingerprinted, not read whole
WHOLE_HASH_LIMIT = 64 << 20


def file_fingerprint(p: Path) -> str:
    """SHA-256 of the file; for a huge one, of its size, mtime and first and last MiB
    (any write to it changes its mtime; reading 2 GB of holes twice per case would
    cost seconds and the case's memory)."""
    st = p.stat()
    if st.st_size <= WHOLE_HASH_LIMIT:
        return hashlib.sha256(p.read_bytes()).hexdigest()
    h = hashlib.sha256(f"{st.st_size} {st.st_mtime_ns}".encode())
    with open(p, "rb") as fh:
        h.update(fh.read(1 << 20))
        fh.seek(-(1 << 20), os.SEEK_END)
        h.update(fh.read())
    return h.hexdigest()


def digest(folder: Path) -> dict:
    """Name → fingerprint of every file under ``folder`` (links followed)."""
    return {str(p.relative_to(folder)): file_fingerprint(p)
            for p in sorted(folder.rglob("*")) if p.is_file()}


def check_inputs_kept(c: Case, ctx: Ctx, base_before: dict, base_folder: Path) -> None:
    """No case modifies an input (its own or the shared sample); an error writes nothing."""
    after = digest(ctx.dir)
    if c.expect == "error":
        assert after == ctx.before, "an error case wrote or changed files"
    else:
        changed = [k for k, h in ctx.before.items() if after.get(k) != h]
        assert not changed, f"inputs modified: {changed}"
    assert digest(base_folder) == base_before, "the shared sample was modified"


@pytest.fixture(scope="module")
def base(tmp_path_factory) -> Base:
    return Base(tmp_path_factory.mktemp("hostile"))


def test_corpus_has_at_least_30_kinds():
    assert len(CASES) >= 30 and len({c.name for c in CASES}) == len(CASES)


@pytest.mark.parametrize("c", [pytest.param(c, id=c.name,
                                             marks=[pytest.mark.slow] if c.slow else [])
                               for c in CASES])
def test_hostile_input(c, base, tmp_path, capsys):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rc, lines, ctx, r = run_case(c, tmp_path, base, capsys)
    check_inputs_kept(c, ctx, base.digest, base.folder)
    culprit = str(r.culprit)
    if c.expect == "error":
        assert rc == 2, lines
        assert len(lines) == 1 and lines[0].startswith("facewrap: error: "), lines
        assert culprit in lines[0] and re.search(c.match, lines[0]), lines[0]
        assert not ctx.out.exists()
        return
    if c.expect == "job error":
        assert rc == 1
        failed = [ln for ln in lines if "failed:" in ln]
        assert len(failed) == 1 and culprit in failed[0] and re.search(c.match, failed[0])
        assert (ctx.dir / "a.obj").is_file()
        return
    assert rc == 0, lines
    warned = [ln for ln in lines if ln.startswith("facewrap: warning: ")]
    if c.expect == "warning":
        assert any(re.search(c.match, w) and culprit in w for w in warned), lines
    else:
        assert not warned, warned
    fitted = read_mesh(ctx.out)
    template = read_mesh(load_job(ctx.dir / "job.toml")[0].template)
    assert np.array_equal(fitted.face_indices, template.face_indices)
    assert np.isfinite(fitted.vertices).all()
    if c.check is not None:
        c.check(ctx, fitted.vertices)


def test_reliability_doc_lists_every_case():
    rows = [ln.split("|") for ln in DOC.read_text().splitlines()
            if ln.startswith("| `")]
    listed = {r[1].strip().strip("`"): r[4].strip() for r in rows}
    assert listed == {c.name: c.expect for c in CASES}, (
        "docs/reliability.md is out of date: run `python tests/test_hostile.py`")


# -- fuzzing the readers ---------------------------------------------------------------------------
def _fuzz_file(data: bytes, suffix: str) -> Path:
    folder = Path(tempfile.gettempdir()) / f"facewrap-fuzz-{os.getpid()}"
    folder.mkdir(exist_ok=True)
    p = folder / f"fuzz{suffix}"
    p.write_bytes(data)
    return p


def _read_or_input_error(read, data: bytes, suffix: str):
    p = _fuzz_file(data, suffix)
    try:
        return read(p)
    except InputError as exc:
        assert str(p) in str(exc) and "\n" not in str(exc)
        return None


_OBJ = (b"# fuzz\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0.5\nvt 0 0\nvt 1 0\nvt 0 1\n"
        b"vn 0 0 1\nusemtl skin\nf 1/1/1 2/2/1 3/3/1\nf 2/2/1 4/1/1 3/3/1\n")
_FUZZ = hsettings(max_examples=int(os.environ.get("FACEWRAP_FUZZ", "120")), deadline=None,
                  suppress_health_check=[HealthCheck.too_slow])


def _mutations(seed: bytes):
    """Valid file with a few bytes changed, cut short, or spliced with junk."""
    return st.one_of(
        st.binary(max_size=400),
        st.tuples(st.integers(0, len(seed)), st.binary(max_size=20)).map(
            lambda t: seed[:t[0]] + t[1] + seed[t[0]:]),
        st.integers(0, len(seed)).map(lambda k: seed[:k]),
        st.lists(st.tuples(st.integers(0, len(seed) - 1), st.integers(0, 255)),
                 max_size=6).map(lambda edits: _edit(seed, edits)))


def _edit(seed: bytes, edits) -> bytes:
    b = bytearray(seed)
    for i, v in edits:
        b[i] = v
    return bytes(b)


@_FUZZ
@given(_mutations(_OBJ))
def test_fuzz_obj_reader(data):
    _check_mesh(_read_or_input_error(read_obj, data, ".obj"))


def _check_mesh(mesh):
    if mesh is not None:
        assert np.isfinite(mesh.vertices).all()
        idx = mesh.face_indices
        assert len(idx) == 0 or (idx.min() >= 0 and idx.max() < mesh.n_vertices)


def _ply_seed(binary: bool) -> bytes:
    p = _fuzz_file(b"x", ".ply")
    write_ply(p, Mesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 1.0]],
                      [[0, 1, 2, 3], [0, 2, 3]], uvs=[[0, 0], [1, 0], [0, 1], [1, 1.0]]),
              binary=binary)
    return p.read_bytes()


@pytest.mark.slow
@_FUZZ
@given(st.sampled_from([True, False]).flatmap(lambda b: _mutations(_ply_seed(b))))
def test_fuzz_ply_reader(data):
    _check_mesh(_read_or_input_error(read_ply, data, ".ply"))


_LANDMARK_SEEDS = {
    ".txt": b"1.0 2.0 3.0 a\n4 5 6 b\n7,8,9 c\n",
    ".json": b'{"format": "facewrap.landmarks", "version": 1, "landmarks": [{"vertex": 3}, '
             b'{"triangle": 1, "barycentric": [0.2, 0.3, 0.5]}, {"point": [1, 2, 3]}]}',
    ".ljson": b'{"version": 3, "groups": {"LJSON": {"landmarks": {"points": [[1, 2, 3], '
              b'[4, 5, 6]]}, "labels": [{"label": "nose", "mask": [0, 1]}]}}}',
    ".pts": b"version: 1\nn_points: 3\n{\n1 2 3\n4.5 5 6\n7 8 9e1\n}\n",
}


@_FUZZ
@given(st.sampled_from(sorted(_LANDMARK_SEEDS)).flatmap(
    lambda ext: st.tuples(st.just(ext), _mutations(_LANDMARK_SEEDS[ext]))))
def test_fuzz_landmark_readers(case_):
    ext, data = case_
    lm = _read_or_input_error(read_landmarks, data, ext)
    if lm is not None:
        assert len(lm) > 0


def _trimesh_seed(ext: str) -> bytes:
    import trimesh
    p = _fuzz_file(b"x", ext)
    trimesh.Trimesh([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], [[0, 1, 2], [1, 3, 2]],
                    process=False).export(p)
    return p.read_bytes()


@pytest.mark.slow
@_FUZZ
@given(st.sampled_from([".stl", ".off", ".glb"]).flatmap(
    lambda ext: st.tuples(st.just(ext), _mutations(_trimesh_seed(ext)))))
def test_fuzz_trimesh_formats(case_):
    ext, data = case_
    _check_mesh(_read_or_input_error(read_mesh, data, ext))


_MARKER_SEEDS = {".cons": b"2\n1 2\n3, 4\n", ".yaml": b"markers: ['1:2', '3:4']\n",
                 ".json": b'{"format": "facewrap.markers", "pairs": [[1, 2], [3, 4]]}'}


@_FUZZ
@given(st.sampled_from(sorted(_MARKER_SEEDS)).flatmap(
    lambda ext: st.tuples(st.just(ext), _mutations(_MARKER_SEEDS[ext]))))
def test_fuzz_marker_readers(case_):
    ext, data = case_
    pairs = _read_or_input_error(read_markers, data, ext)
    if pairs is not None:
        src, tgt = pairs
        assert len(src) == len(tgt) > 0 and src.min() >= 0 and tgt.min() >= 0


@_FUZZ
@given(_mutations(b"scan,scan_landmarks,output,smoothing,name\n"
                  b"a.obj,a.txt,out/a.obj,0.5,first\nb.ply,b.txt,out/b.ply,,\n"))
def test_fuzz_manifest_reader(data):
    _read_or_input_error(read_manifest, data, ".csv")


# -- docs/reliability.md -----------------------------------------------------------------------------
def write_doc() -> None:
    """Run every case (the slow one too when FACEWRAP_SLOW is set) and write the doc."""
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        base = Base(Path(tmp) / "base")
        for k, c in enumerate(CASES):
            folder = Path(tmp) / c.name
            if c.slow and not os.environ.get("FACEWRAP_SLOW"):
                message = "(not run here: see benchmarks/bench_memory.py)"
            else:
                err = io.StringIO()
                with warnings.catch_warnings(), contextlib.redirect_stderr(err):
                    warnings.simplefilter("ignore")
                    rc, lines, _, _ = run_case(c, folder, base)
                lines = err.getvalue().strip().splitlines() or lines
                shown = [ln for ln in lines if c.match and re.search(c.match, ln)]
                message = (shown[0] if shown else "(fitted, no warning)" if rc == 0
                           else f"exit {rc}").replace(str(folder) + "/", "")
                message = message.replace(str(Path(tmp) / "base") + "/", "")
                message = message.replace("|", "\\|")
            rows.append(f"| `{c.name}` | {c.kind} | {c.what} | {c.expect} | {message} |")
    DOC.write_text(DOC_HEAD + "\n".join(rows) + "\n" + DOC_TAIL)


DOC_HEAD = """# Reliability: hostile inputs

Generated by `python tests/test_hostile.py` from the corpus in `tests/test_hostile.py`
(the test suite checks that this table lists every case). Each case starts from the
built-in sample, breaks one file (or asks for an output where it must not go) and runs
`facewrap run` (job files), `facewrap batch` (manifests), another command (the
`outputs` cases: wrap, run, batch, transfer, track, evaluate, report, convert, animate,
sample, demo) or the reader itself (markers). For every case the harness checks that
no input changed (SHA-256 of every file before and after) and, for an error, that
nothing at all was written.

Behaviours: **error** — exit status 2, one line on stderr naming the file (and line)
and the problem, nothing written; **job error** — in a batch, that job fails with one
line naming the file (exit status 1) and the other jobs finish; **warning** — legal but
odd: the fit is done and correct, and one warning line names the file and the oddity;
**ok** — a correct result. The messages are those observed when the table was made.

| case | files | input | behaviour | message |
|---|---|---|---|---|
"""

DOC_TAIL = """
Beyond the table: the OBJ, PLY, STL, OFF, GLB, landmark (`.pts` too), marker and
manifest readers are fuzzed with
Hypothesis (random bytes, valid files with bytes changed, cut short or spliced): every
input is read or rejected with one `InputError` naming the file, never another
exception. Job files are fuzzed the same way in `tests/test_jobs_jobfile.py`.

Batches: a job that fails (a missing or malformed file, an exception in the fit, a
worker process killed by the out-of-memory killer) is reported in the summary with its
error and never stops the others; `kill -9` of a running batch leaves complete outputs
or none, and the re-run skips finished jobs (`tests/test_batch_runner.py`). The same inputs give
the same output meshes (topology exactly, positions to 1e-6 mm) run to run, serially, in
the process pool and on Dask.
"""


if __name__ == "__main__":
    write_doc()
    print(f"wrote {DOC}")
    sys.exit(0)
