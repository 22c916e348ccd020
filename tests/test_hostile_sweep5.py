"""Hostile inputs of a fifth sweep: files that are valid but implausible.

Classes:

- an ASCII STL missing only its last ``endsolid`` line was "holds no triangles"
  (trimesh's reader looks for ``endsolid`` before anything else), and a vertex row
  with a word among its numbers was read as the numbers before it, silently; STL
  is now read by facewrap itself (``io/stl.py``), a missing last ``endsolid`` read
  as the end of the solid, every other row checked against the format's pattern
  and a bad one named by its line;
- a GLB whose accessor or bufferView points beyond the bytes it reads from failed
  with "cannot read GLB: AssertionError" (or a numpy reshape error); each
  bufferView is now checked inside its buffer and each accessor inside its
  bufferView (a byteStride shorter than an element, which trimesh read as
  overlapping garbage, too), naming the one that overruns;
- a scan of something that is not a face (a plane, a ball) with landmarks on it
  passed every check and was fitted silently (29 mm median error against the
  sample's truth, 3.5 mm on its scan); under the landmark similarity a quarter of
  the template's face lies far from such a scan, which is now one warning naming
  it (``wrapping/likeness.py``);
- a template whose faces face into the head made a good scan look flipped: the
  warning named the scan; the template is now named (the fit is unchanged);
- ``--pca-components`` with a model that fits no blendshapes (graph, rbf) and a
  job's ``[[wrap.stages]]`` with a model fitted in closed form (rbf) were dropped
  silently; both are refused naming the setting;
- template landmark ids on a part that is not skin (an eye corner on the eyeball)
  were fitted without a word; they are now named in one warning;
- ``animate`` interpolated ends that cannot be two poses of one head (a mirror
  image, one in metres, one turned around: the middle frame a flat or shrunk
  head), and ``evaluate`` measured against a ground truth mirrored, in other units
  or in another frame (a wrap run with ``--output-frame template``), silently;
  each now says so in one line naming the file;
- ``transfer`` carried over source shapes that are no pose of the source neutral
  (other units, mirrored, moved, turned, in metres) silently; the wrap's
  blendshape check now runs on them too, and also says shapes of another size
  (a shape in metres moves no vertex far and passed it).

Inputs are tiny meshes written here and the built-in sample at its smallest.
"""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.dispatch import read_mesh
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_formats import quad_gltf_doc
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, warning_lines, wrap_argv


# -- STL: a missing last endsolid, rows out of the pattern -----------------------------------
def ascii_stl(n: int = 3) -> list[str]:
    """The rows of an ASCII STL of ``n`` triangles of a fan, ``endsolid`` last."""
    rows = ["solid scan"]
    for k in range(n):
        a, b = 2 * np.pi * k / n, 2 * np.pi * (k + 1) / n
        rows += ["  facet normal 0 0 1", "    outer loop", "      vertex 0 0 0",
                 f"      vertex {10 * np.cos(a):.9g} {10 * np.sin(a):.9g} 0",
                 f"      vertex {10 * np.cos(b):.9g} {10 * np.sin(b):.9g} 0",
                 "    endloop", "  endfacet"]
    return rows + ["endsolid scan"]


def test_an_ascii_stl_without_its_last_endsolid_reads(tmp_path):
    whole, cut = tmp_path / "whole.stl", tmp_path / "cut.stl"
    whole.write_text("\n".join(ascii_stl()) + "\n")
    cut.write_text("\n".join(ascii_stl()[:-1]) + "\n")
    a, b = read_mesh(whole), read_mesh(cut)
    assert len(a.triangles) == 3
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.triangles, b.triangles)


def test_an_ascii_stl_reads_alike_through_either_reader(tmp_path):
    """One clean solid takes the fast reader; two solids the row-by-row one."""
    one, two = tmp_path / "one.stl", tmp_path / "two.stl"
    rows = ascii_stl(4)
    one.write_text("\n".join(rows) + "\n")
    two.write_text("\n".join(rows[:15] + ["endsolid a", "solid b"] + rows[15:]) + "\n")
    a, b = read_mesh(one), read_mesh(two)
    assert len(a.triangles) == len(b.triangles) == 4
    np.testing.assert_allclose(a.vertices, b.vertices, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(a.triangles, b.triangles)


@pytest.mark.parametrize("edit, needle", [
    (lambda r: r[:-4], "the facet of line 16 runs to the end of the file (cut short?)"),
    (lambda r: r[:-4] + ["endsolid"], "the facet of line 16 ends early"),
    (lambda r: r[:3] + ["      vertex 1 abc 2"] + r[4:], "cut.stl:4: vertex row is not "
                                                          "three numbers"),
    (lambda r: r[:3] + ["      vertex 1 2"] + r[4:], "cut.stl:4: vertex row is not three"),
    (lambda r: r[:6] + r[7:], "cut.stl:7: expected 'endloop', found 'endfacet'"),
    (lambda r: [r[0], r[-1]], "holds no triangles"),
])
def test_an_ascii_stl_out_of_its_pattern_names_the_line(tmp_path, capsys, edit, needle):
    p = tmp_path / "cut.stl"
    p.write_text("\n".join(edit(ascii_stl())) + "\n")
    error_line(capsys, facewrap("info", p), str(p), needle)


# -- GLB: accessors and bufferViews beyond their bytes ----------------------------------------
def glb(doc: dict, binary: bytes) -> bytes:
    """A GLB of the glTF JSON ``doc`` and one binary chunk."""
    js = json.dumps(doc).encode()
    js += b" " * (-len(js) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = (struct.pack("<II", len(js), 0x4E4F534A) + js
              + struct.pack("<II", len(binary), 0x004E4942) + binary)
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def quad_doc() -> tuple[dict, bytes]:
    """A quad's glTF JSON (``test_hostile_formats``') and its binary chunk."""
    V = np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0], [100, 100, 10]], np.float32)
    I = np.array([0, 1, 2, 1, 3, 2], np.uint32)
    return quad_gltf_doc(), V.tobytes() + I.tobytes()


@pytest.mark.parametrize("change, needle", [
    (lambda d: d["accessors"][0].update(byteOffset=4096),
     "accessor 0 overruns bufferView 0: its 4 elements need bytes 4096 to 4144, the view "
     "holds 48 bytes"),
    (lambda d: d["accessors"][1].update(count=600),
     "accessor 1 overruns bufferView 1"),
    (lambda d: d["bufferViews"][1].update(byteOffset=4096),
     "bufferView 1 overruns buffer 0: it spans bytes 4096 to 4120, the buffer holds 72"),
    (lambda d: d["bufferViews"][0].update(byteLength=4096), "bufferView 0 overruns"),
    # the JSON says the buffer is bigger, the file's binary chunk is not
    (lambda d: (d["buffers"][0].update(byteLength=8192),
                d["bufferViews"][1].update(byteOffset=4096)), "the buffer holds 72"),
    (lambda d: d["bufferViews"][0].update(buffer=3), "names buffer 3, which the file"),
    (lambda d: d["accessors"][1].update(bufferView=7), "names bufferView 7"),
    (lambda d: d["bufferViews"][0].update(byteStride=4), "byteStride 4, less than the "
                                                         "12 bytes"),
    (lambda d: d["accessors"][1].update(count=-1), "count is -1, not a whole number"),
])
def test_a_glb_overrunning_its_buffer_names_the_culprit(tmp_path, capsys, change,
                                                        needle):
    doc, binary = quad_doc()
    p = tmp_path / "scan.glb"
    p.write_bytes(glb(doc, binary))
    assert facewrap("info", p) == 0            # the file as it is reads
    capsys.readouterr()
    change(doc)
    p.write_bytes(glb(doc, binary))
    line = error_line(capsys, facewrap("info", p), str(p), needle)
    assert "AssertionError" not in line and "reshape" not in line


# -- a scan of something else than a face ------------------------------------------------------
def flat_and_round_scans(sample, folder: Path) -> dict:
    """The sample's scan landmarks on a plane (flattened onto it) and on a ball
    (pushed out onto it), each with its scan, as file paths."""
    from facewrap.io.obj import write_obj
    from facewrap.mesh import Mesh
    import trimesh
    P = np.loadtxt(sample["scan_landmarks"])
    flat = P.copy()
    flat[:, 2] = P[:, 2].mean()
    n = 30
    lo, hi = flat.min(axis=0) - 60, flat.max(axis=0) + 60
    x, y = np.meshgrid(np.linspace(lo[0], hi[0], n), np.linspace(lo[1], hi[1], n))
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)).ravel()
    plane = Mesh(np.column_stack([x.ravel(), y.ravel(), np.full(n * n, flat[0, 2])]),
                 np.vstack([np.column_stack([i, i + 1, i + n]),
                            np.column_stack([i + 1, i + n + 1, i + n])]))
    ball = trimesh.creation.icosphere(3, radius=100.0)
    centre = P.mean(axis=0)
    out = {}
    for name, mesh, points in [
            ("plane", plane, flat),
            ("ball", Mesh(np.asarray(ball.vertices) + centre, np.asarray(ball.faces)),
             centre + 100 * (P - centre) / np.linalg.norm(P - centre, axis=1)[:, None])]:
        write_obj(folder / f"{name}.obj", mesh)
        np.savetxt(folder / f"{name}_landmarks.txt", points)
        out[name] = (folder / f"{name}.obj", folder / f"{name}_landmarks.txt")
    return out


@pytest.mark.parametrize("shape", ["plane", "ball"])
def test_a_scan_that_is_no_face_is_said(sample, tmp_path, capsys, shape):
    """A plane or a ball with the landmarks on it passed every check and was fitted
    (the sample onto the plane: 29 mm median error against its truth), silently."""
    scan, landmarks = flat_and_round_scans(sample, tmp_path)[shape]
    out = tmp_path / "o.obj"
    rc = facewrap(*wrap_argv(dict(sample, scan=scan, scan_landmarks=landmarks), out))
    line, = warning_lines(capsys, rc, f"{scan}: under the landmark alignment",
                          "% of the landmarks' spread", "is it a scan of a face")


def test_a_face_scan_is_not_said_to_be_unlike(sample, tmp_path, capsys):
    rc = facewrap(*wrap_argv(sample, tmp_path / "o.obj"))
    assert rc == 0
    assert "landmark alignment" not in capsys.readouterr().err


# -- a template wound inward -------------------------------------------------------------------
def test_a_flipped_template_is_named_not_the_scan(sample, tmp_path, capsys):
    """A template whose faces face into the head made the good scan look flipped: the
    warning named the scan ("100 % of the scan ... faces inward")."""
    from facewrap.io.obj import read_obj, write_obj
    from facewrap.mesh import Mesh
    template = read_obj(sample["template"])
    flipped = tmp_path / "template.obj"
    write_obj(flipped, Mesh(template.vertices, [p[::-1] for p in template.polygons()]))
    rc = facewrap(*wrap_argv(dict(sample, template=flipped), tmp_path / "o.obj"))
    err = capsys.readouterr().err
    assert rc == 0, err
    assert f"{flipped}: its faces are flipped (they face into the head)" in err
    assert str(sample["scan"]) not in err


# -- options that contradict -------------------------------------------------------------------
@pytest.mark.parametrize("model", ["graph", "rbf"])
def test_pca_components_with_a_model_of_no_blendshapes_is_refused(sample, tmp_path, capsys,
                                                                  model):
    """``--model graph --blendshapes DIR --pca-components 3`` dropped the setting
    silently (only its absence of blendshapes was refused)."""
    argv = wrap_argv(sample, tmp_path / "o.obj", "--blendshapes",
                     Path(sample["template"]).parent / "blendshapes", "--pca-components",
                     "3", "--model", model)
    error_line(capsys, facewrap(*argv), "--pca-components", f"the model {model!r} fits "
                                                             "no blendshapes")
    assert not (tmp_path / "o.obj").exists()


# -- template landmarks on a part that is not skin --------------------------------------------
def test_template_landmarks_on_an_eyeball_are_said(sample, tmp_path, capsys):
    """Eye-corner ids pointing at the eyeball beside them (a piece the scanner does
    not see and the fit does not pull) were fitted without a word."""
    from facewrap.io.obj import read_obj
    from scipy.sparse import coo_matrix, csgraph
    template = read_obj(sample["template"])
    T, n = template.triangles, template.n_vertices
    _, piece = csgraph.connected_components(coo_matrix(
        (np.ones(T.size), (T.ravel(), np.roll(T, 1, axis=1).ravel())), shape=(n, n)))
    eyeball = np.flatnonzero(piece != np.argmax(np.bincount(piece)))
    ids = np.loadtxt(sample["template_landmarks"], dtype=int)
    for j in (36, 45):       # the outer eye corners: onto the nearest eyeball vertex
        ids[j] = eyeball[np.argmin(np.linalg.norm(
            template.vertices[eyeball] - template.vertices[ids[j]], axis=1))]
    moved = tmp_path / "template_landmarks.txt"
    np.savetxt(moved, ids, fmt="%d")
    rc = facewrap(*wrap_argv(dict(sample, template_landmarks=moved), tmp_path / "o.obj"))
    warning_lines(capsys, rc, f"{moved}: 2 of 68 landmarks (36, 45) lie on a part that "
                              "is not skin")


# -- two poses that cannot be of one head: animate's ends, evaluate's truth ---------------
def moved_copies(sample, folder: Path) -> dict:
    """The sample's template mirrored, in metres (from mm), turned 180 degrees about
    its vertical axis, and its smile shape as it is; as OBJ files."""
    from facewrap.io.obj import read_obj, write_obj
    from facewrap.mesh import Mesh
    template = read_obj(sample["template"])
    V, faces = template.vertices, list(template.polygons())
    out = {}
    for name, W in [("mirrored", V * [-1, 1, 1]), ("metres", V / 1000),
                    ("turned", V * [-1, 1, -1])]:
        out[name] = folder / f"{name}.obj"
        write_obj(out[name], Mesh(W, faces))
    out["smile"] = Path(sample["template"]).parent / "blendshapes" / "smile.obj"
    return out


@pytest.mark.parametrize("end, needle", [
    ("mirrored", "is a mirror image of"), ("metres", "is 0.001 times the size of"),
    ("turned", "is turned 180 degrees from")])
def test_animate_says_ends_that_are_not_two_poses_of_one_head(sample, tmp_path, capsys,
                                                              end, needle):
    """A mirrored end, an end in metres or one turned around was interpolated
    without a word (the middle frame of the mirrored pair is a flat head)."""
    path = moved_copies(sample, tmp_path)[end]
    rc = facewrap("animate", sample["template"], path, "--frames", "3", "-o",
                  tmp_path / "a")
    line, = warning_lines(capsys, rc, f"{path}: {needle}")
    assert len(list((tmp_path / "a").glob("*.obj"))) == 3


def test_animate_says_nothing_of_an_expression(sample, tmp_path, capsys):
    path = moved_copies(sample, tmp_path)["smile"]
    assert facewrap("animate", sample["template"], path, "-o", tmp_path / "a") == 0
    assert "warning" not in capsys.readouterr().err


def test_evaluate_says_a_ground_truth_that_cannot_be_the_results(sample, tmp_path, capsys):
    """A truth in centimetres, mirrored, or in the template's frame (a wrap run with
    ``--output-frame template``) gave its errors as if they measured the fit."""
    fitted = tmp_path / "fitted.obj"
    assert facewrap(*wrap_argv(sample, fitted)) == 0
    framed = tmp_path / "framed.obj"
    assert facewrap(*wrap_argv(sample, framed, "--output-frame", "template")) == 0
    capsys.readouterr()
    truth = np.load(sample["ground_truth"])
    for name, G, result, needle in [
            ("cm", truth / 10, fitted, "times the size of the result"),
            ("mirrored", truth * [-1, 1, 1], fitted, "is a mirror image of the result"),
            ("truth", truth, framed, "in another frame (a wrap's --output-frame)")]:
        path = tmp_path / f"{name}.npy"
        np.save(path, G)
        rc = facewrap("evaluate", result, sample["scan"], "--ground-truth", path, "-q")
        warning_lines(capsys, rc, f"{path}: ", needle, "its errors measure that")
    rc = facewrap("evaluate", fitted, sample["scan"], "--ground-truth",
                  sample["ground_truth"], "-q")
    assert rc == 0 and "warning" not in capsys.readouterr().err


# -- transfer: source shapes that are no pose of the source neutral ---------------------------
@pytest.mark.parametrize("moved, needle", [
    (lambda N, V: N + 1000 * (V - N), "move a vertex farther than half the source neutral"),
    (lambda N, V: V * [-1, 1, 1], "move a vertex farther than half the source neutral"),
    (lambda N, V: V * [-1, 1, -1], "move a vertex farther than half the source neutral"),
    (lambda N, V: V / 1000, "are not of the source neutral's size (e.g. 'smile', 0.001"),
])
def test_transfer_says_a_source_shape_that_is_no_pose_of_its_neutral(sample, tmp_path,
                                                                     capsys, moved, needle):
    """A source shape in other units, mirrored, turned around or in metres was
    transferred without a word (the wrap's blendshape check was not made)."""
    from facewrap.io.obj import read_obj, write_obj
    from facewrap.mesh import Mesh
    neutral = read_obj(sample["template"])
    smile = read_obj(Path(sample["template"]).parent / "blendshapes" / "smile.obj")
    shapes = tmp_path / "shapes"
    shapes.mkdir()
    write_obj(shapes / "smile.obj", Mesh(moved(neutral.vertices, smile.vertices),
                                         list(smile.polygons())))
    target = tmp_path / "target.obj"
    write_obj(target, Mesh(1.5 * neutral.vertices + [10.0, 0, 0], neutral.triangles))
    markers = tmp_path / "markers.txt"
    ids = Path(sample["template_landmarks"]).read_text().split()[:12]
    markers.write_text("".join(f"{i} {i}\n" for i in ids))
    rc = facewrap("transfer", sample["template"], target, "--markers", markers,
                  "--source-shapes", shapes, "-o", tmp_path / "out", "-q")
    warning_lines(capsys, rc, f"{shapes}: 1 shape(s) ", needle)


def test_icp_stages_for_a_closed_form_model_are_refused(sample, tmp_path, capsys):
    """A job file's ``[[wrap.stages]]`` with ``model = "rbf"`` (fitted without ICP)
    were dropped silently."""
    job = tmp_path / "job.toml"
    job.write_text(f'version = 1\n[inputs]\ntemplate = "{sample["template"]}"\n'
                   f'scan = "{sample["scan"]}"\n'
                   f'template_landmarks = "{sample["template_landmarks"]}"\n'
                   f'scan_landmarks = "{sample["scan_landmarks"]}"\n'
                   f'[outputs]\noutput = "{tmp_path / "out" / "o.obj"}"\n'
                   '[wrap]\nmodel = "rbf"\n[[wrap.stages]]\niterations = 10\n')
    error_line(capsys, facewrap("run", job, "-q"), "[[wrap.stages]]",
               "the model 'rbf' is fitted in closed form")
    assert not (tmp_path / "out").exists()
