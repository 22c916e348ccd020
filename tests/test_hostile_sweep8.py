"""Hostile inputs of an eighth sweep: one test per bug class it found.

Classes:

- meshes without a surface reached the commands that check none: ``evaluate`` of
  a PLY point cloud failed with "T must hold at least one triangle" naming no
  file, and measured a scan whose triangles all have zero area (a mesh collapsed
  to a line) as if it were one; ``transfer`` onto or from such a mesh solved it
  silently into garbage (exit status 0).  Each is now refused naming the file, as
  ``wrap`` refuses a scan (:func:`~facewrap.jobs.input_checks.check_surface`);
- ``convert`` of a PLY point cloud to OBJ wrote a file of ``v`` lines that every
  command, ``info`` too, then refused ("no faces ('f' lines)"); it is now refused
  before anything is written, pointing to PLY;
- the Python library took coordinates no file may hold (beyond 1e15 in magnitude,
  which every reader refuses): ``wrap`` of a scan with a 1e300 vertex fitted it
  with overflow warnings (of such a template: "V must be finite", naming neither),
  ``evaluate`` measured it, ``bake_texture`` baked it, ``find_correspondence``
  failed with "Singular matrix", ``DeformationTransfer.transfer`` returned
  infinities, a blendshape of 1e300 was fitted, a landmark of 1e300 failed in the
  fit as "weights must be (k,) non-negative with a positive sum", and
  ``landmark_errors``, ``surface_distances``, ``ground_truth_errors`` and
  ``interpolate_vertices`` overflowed into inf or NaN.  Each is now a
  ``ValueError`` naming the argument and the row (meshes:
  :func:`~facewrap.mesh.check_positions`; a head's arrays of points:
  :func:`~facewrap.geometry.checks.as_positions`; :class:`~facewrap.Landmarks`), with
  :data:`~facewrap.units.COORDINATE_LIMIT` moved to the units; ``bake_texture``
  now names ``template``/``scan`` for a NaN too ("points must be finite" before),
  and so does ``build_rig`` ("V must be finite"); ``snap_to_surface`` snapped to a
  1e300 vertex with "invalid value" warnings;
- ``write_mesh`` wrote an OBJ of a NaN or 1e300 vertex, a NaN texture coordinate or
  normal, that ``read_mesh`` then refused (a NaN vertex colour was read back as no
  colours at all; a PLY refused these naming no row); each is now refused naming
  the row;
- an output path written on Windows (a job file's ``output = "out\\\\fit.obj"``, a
  manifest's ``C:\\fits\\a.obj``, ``-o 'fits\\a.obj'``) was one file named with
  backslashes, written without a word where no one would look for it; a backslash
  in an output path is now refused where ``/`` separates folders, naming the path;
- ``report`` of a run report edited by hand failed naming no file: an output path
  that is a number ("TypeError: expected str, bytes or os.PathLike object, not
  int"), a transform that is text ("could not convert string to float: 'abc'");
  a NaN in the transform was "must be a 4x4 matrix, got shape (4, 4)", and a
  1e300 in it was drawn silently.  Each now names the report and the entry;
- landmark names with accents typed in the two Unicode forms ('é' as one
  character, NFC, in one file; 'e' and a combining accent, NFD, as macOS tools may
  write, in the other) look the same but did not pair: half the sample's 68
  landmarks were left out of the fit (a warning naming 'jaw_1_é', the very name
  the other file holds).  :class:`~facewrap.Landmarks` keeps names in NFC;
- ``transfer --correspondence F.npz`` reused a cache made with other markers (the
  marker file edited since) in their place: the new markers were ignored and the
  shapes came out byte for byte as before, without a word.  A cache of other
  marker pairs is now refused naming it (the same pairs in another order are
  still reused);
- ``transfer`` took neutrals with triangles a wrap's template is warned about
  (a repeated corner, zero area, an edge of three or more triangles) without a
  word, though a third of them with a repeated corner moved the shapes by
  millimetres; each is now one warning line naming the file, as for a wrap's
  template (:func:`~facewrap.jobs.input_checks.survey_mesh`);
- ``run_wrap_job`` took ``WrapJob(texture_size=True)`` as 1 (a bool is an int to
  Python) and baked a 1 x 1 texture without a word; it is refused as other
  non-integers are;
- a scan whose material names a texture that is not there (moved, a folder, a
  fifo) had its landmarks found on the shaded mesh (``landmarks``, a ``wrap``
  without scan landmarks) without a word; it is now one warning line naming the
  scan and the texture (:func:`~facewrap.detection.mesh_texture`);
- a bake from or into a UV layout of no area (every texture coordinate at one
  point, or on a line) was written without a word: the template's as an all-black
  image, the scan's as one flat colour; both are now refused naming the mesh
  (:func:`~facewrap.jobs.input_checks.check_uv_layouts`);
- a ground truth (``evaluate``/``report --ground-truth``) whose every row is NaN
  (no vertex with a known position) was measured as "correspondence mean n/a"
  without a word; it is now refused naming the file;
- ``animate`` of one mesh given as both ends (the same file twice, or a copy)
  wrote a sequence of identical frames without a word; it is now one warning
  line naming the end.

``facewrap.Mesh`` itself still holds what it is given (a container, as a reader's
arrays); every public function that takes one checks it at its door (those above
now; ``wrap``, ``track``, the transfers, the rig functions, ``evaluate``, the
renderers and ``detect_landmarks`` refused a NaN already).

Inputs are the built-in sample at its smallest and tiny meshes written here.
"""

from __future__ import annotations

import copy
import json
import os
import re
import unicodedata
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap import (DeformationTransfer, InputError, Landmarks, WrapJob, WrapSettings,
                      find_correspondence, pair_landmarks, run_wrap_job, wrap)
from facewrap.detection import mesh_texture
from facewrap.errors import InputWarning
from facewrap.landmarks import snap_to_surface
from facewrap.rig import build_rig
from facewrap.animation import interpolate_vertices
from facewrap.evaluate import (evaluate, ground_truth_errors, landmark_errors,
                               surface_distances)
from facewrap.io.dispatch import read_mesh, write_mesh
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template
from facewrap.texture import bake_texture
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, warning_lines


# -- meshes without a surface --------------------------------------------------------------
def collapsed(path, out):
    """The mesh at ``path`` with every triangle's third corner moved onto its second
    (all of zero area), written to ``out``."""
    mesh = read_mesh(path)
    T = mesh.triangles.copy()
    T[:, 2] = T[:, 1]
    write_mesh(out, Mesh(mesh.vertices, T))
    return out


def test_evaluate_and_transfer_refuse_a_mesh_without_a_surface(sample, tmp_path, capsys):
    cloud = tmp_path / "cloud.ply"
    write_mesh(cloud, Mesh(read_mesh(sample["scan"]).vertices, np.zeros((0, 3), int)))
    flat = collapsed(sample["scan"], tmp_path / "flat.obj")
    for scan, problem in ((cloud, "has no faces"), (flat, "scan is degenerate")):
        rc = facewrap("evaluate", sample["template"], scan, "-q")
        error_line(capsys, rc, str(scan), problem)
    rc = facewrap("evaluate", cloud, sample["scan"], "-q")
    error_line(capsys, rc, str(cloud), "has no faces")
    markers = tmp_path / "markers.txt"
    markers.write_text("0 0\n50 50\n99 99\n")
    shapes = sample["blendshapes/blink"].parent
    flat_template = collapsed(sample["template"], tmp_path / "flat_template.obj")
    for k, (source, target) in enumerate(((sample["template"], flat_template),
                                          (flat_template, sample["template"]))):
        out = tmp_path / f"out{k}"
        rc = facewrap("transfer", source, target, "--source-shapes", shapes,
                      "--markers", markers, "-o", out, "-q")
        error_line(capsys, rc, str(flat_template), "neutral is degenerate")
        assert not out.exists()


def test_convert_refuses_a_point_cloud_to_obj(sample, tmp_path, capsys):
    cloud = tmp_path / "cloud.ply"
    write_mesh(cloud, Mesh(read_mesh(sample["scan"]).vertices, np.zeros((0, 3), int)))
    out = tmp_path / "cloud.obj"
    error_line(capsys, facewrap("convert", cloud, out), str(cloud), "has no faces")
    assert not out.exists()
    assert facewrap("convert", cloud, tmp_path / "again.ply") == 0
    assert read_mesh(tmp_path / "again.ply").n_vertices == read_mesh(cloud).n_vertices


# -- the Python library: positions a file could not hold -----------------------------------
@pytest.fixture(scope="module")
def small():
    """The sample at its smallest, in memory: template 24, scan 40."""
    tpl = make_template(24)
    return {"tpl": tpl, "scan": make_scan(tpl, resolution=40, texture_size=16)}


def moved(mesh: Mesh, value: float, vertex: int = 5) -> Mesh:
    V = mesh.vertices.copy()
    V[vertex] = value
    return mesh.with_vertices(V)


def test_the_library_refuses_positions_no_file_may_hold(small, tmp_path):
    template, scan = small["tpl"].mesh, small["scan"].mesh
    tl, sl = small["tpl"].landmarks, small["scan"].landmarks
    image = np.full((8, 8, 3), 128, np.uint8)
    for name, call in (
            ("scan", lambda m: wrap(template, m, tl, sl, WrapSettings(model="rbf"))),
            ("template", lambda m: wrap(m, scan, tl, sl, WrapSettings(model="rbf"))),
            ("scan", lambda m: evaluate(template, m)),
            ("source", lambda m: find_correspondence(m, template, [[0, 0], [50, 50],
                                                                   [99, 99]])),
            ("template", lambda m: bake_texture(m, scan, image, size=8)),
            ("mesh", lambda m: write_mesh(tmp_path / "out.obj", m))):
        mesh = template if name in ("template", "source") else scan
        with pytest.raises(ValueError, match=rf"^{name}: vertex 5 has coordinate 1e\+300, "
                                             "too large"):
            call(moved(mesh, 1e300))
    with pytest.raises(ValueError, match=r"^template: vertex 5 is not finite"):
        bake_texture(moved(template, np.nan), scan, image, size=8)   # was "points ..."
    for ext in (".obj", ".ply"):
        with pytest.raises(ValueError, match=r"^mesh: vertex 5 is not finite"):
            write_mesh(tmp_path / f"nan{ext}", moved(scan, np.nan))
    assert not list(tmp_path.iterdir())
    face, keep = template.submesh(template.face_groups == 0)
    corr = find_correspondence(face, face, [[0, 0], [50, 50], [99, 99]])
    dt = DeformationTransfer(anchor=0, fix_flips=False).fit(face, face, corr)
    pose = face.vertices.copy()
    pose[3] = 1e300
    with pytest.raises(ValueError, match=r"^poses\[1\]: vertex 3 has coordinate 1e\+300"):
        dt.transfer([face.vertices, pose])
    points = sl.positions(scan)
    far = points.copy()
    far[3] = [0.0, 1e300, 0.0]
    with pytest.raises(ValueError, match=r"^landmark 3 has coordinate 1e\+300"):
        Landmarks.from_points(far)   # the fit said "weights must be ... positive sum"
    for name, call in (("positions", lambda: landmark_errors(far, points)),
                       ("points", lambda: surface_distances(far, scan)),
                       ("vertices", lambda: ground_truth_errors(far, points)),
                       ("end", lambda: interpolate_vertices(points, far, 3))):
        with pytest.raises(ValueError, match=rf"^{name}: row 3 has coordinate 1e\+300"):
            call()   # each overflowed into inf or NaN, with a RuntimeWarning at most
    shapes = {k: v.copy() for k, v in small["tpl"].blendshapes.items()}
    shapes["smile"][7] = -1e300
    with pytest.raises(ValueError, match=r"^blendshapes\['smile'\]: vertex 7 has"):
        wrap(template, scan, tl, sl, WrapSettings(model="blendshape"), blendshapes=shapes)


# -- Windows paths -------------------------------------------------------------------------
def test_an_output_path_written_on_windows_is_refused(sample, tmp_path, capsys):
    job = tmp_path / "job.toml"
    job.write_text(
        f'version = 1\n[inputs]\ntemplate = "{sample["template"]}"\n'
        f'scan = "{sample["scan"]}"\nscan_landmarks = "{sample["scan_landmarks"]}"\n'
        f'template_landmarks = "{sample["template_landmarks"]}"\n'
        '[outputs]\noutput = "out\\\\fit.obj"\n[wrap]\nmodel = "rbf"\n')
    error_line(capsys, facewrap("run", "-q", job), str(job), "out\\fit.obj' holds a backslash")
    manifest = tmp_path / "m.csv"
    manifest.write_text(f"scan,scan_landmarks,output\n{sample['scan']},"
                        f"{sample['scan_landmarks']},C:\\fits\\a.obj\n")
    error_line(capsys, facewrap("batch", "--job", job, "-q", manifest), str(manifest),
               "a.obj' holds a backslash")
    argv = ["wrap", sample["template"], sample["scan"], "--template-landmarks",
            sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
            "--model", "rbf", "-q", "-o", tmp_path / "fits\\a.obj"]
    error_line(capsys, facewrap(*argv), "holds a backslash", "use '/'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["job.toml", "m.csv"]


# -- a run report edited by hand ---------------------------------------------------------
@pytest.fixture(scope="module")
def run_report(sample, tmp_path_factory) -> dict:
    """The JSON report of a wrap of the sample (its paths absolute)."""
    folder = tmp_path_factory.mktemp("run")
    argv = ["wrap", sample["template"], sample["scan"], "--template-landmarks",
            sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
            "--model", "rbf", "-q", "-o", folder / "fit.obj", "--report", folder / "run.json"]
    assert facewrap(*argv) == 0
    return json.loads((folder / "run.json").read_text())


@pytest.mark.parametrize("edit, problem", [
    (lambda run: run["job"].update(output=5), "the run's output must be a path (a string)"),
    (lambda run: run.update(transform="abc"), "'transform' must be a 4x4 matrix of numbers"),
    (lambda run: run["transform"][0].__setitem__(0, float("nan")),
     "'transform' entry [0][0] is nan"),
    (lambda run: run["transform"][1].__setitem__(2, 1e300),
     "'transform' entry [1][2] is 1e+300")])
def test_report_names_the_run_report_a_hand_edit_broke(run_report, tmp_path, capsys, edit,
                                                       problem):
    run = copy.deepcopy(run_report)
    edit(run)
    run_json = tmp_path / "run.json"
    run_json.write_text(json.dumps(run))
    capsys.readouterr()
    rc = facewrap("report", run_json, "-o", tmp_path / "page")
    error_line(capsys, rc, str(run_json), problem)
    assert not (tmp_path / "page").exists()


# -- one name, two spellings -------------------------------------------------------------
def test_landmark_names_typed_in_either_unicode_form_pair():
    composed = ["sourcil_gauche_é", "nez_bout", "lèvre_haut"]
    decomposed = [unicodedata.normalize("NFD", n) for n in composed]
    assert decomposed[0] != composed[0]    # the same to the eye, not to the bytes
    a = Landmarks.from_vertices([0, 1, 2], names=composed)
    b = Landmarks.from_points(np.eye(3), names=decomposed[::-1])
    ia, ib = pair_landmarks(a, b)
    assert ia.tolist() == [0, 1, 2] and ib.tolist() == [2, 1, 0]
    with pytest.raises(ValueError, match="must be unique"):
        Landmarks.from_vertices([0, 1], names=[composed[0], decomposed[0]])


@pytest.mark.parametrize("attribute, what", [
    ({"uvs": np.full((3, 2), np.nan)}, "texture coordinate 0"),
    ({"normals": np.full((3, 3), np.inf), "face_normals": [[0, 1, 2]]}, "normal 0"),
    ({"vertex_colors": np.full((3, 3), np.nan)}, "vertex colour 0")])
@pytest.mark.parametrize("ext", [".obj", ".ply"])
def test_write_mesh_refuses_what_no_reader_takes_back(tmp_path, attribute, what, ext):
    """An OBJ wrote them as 'nan': UVs and normals then refused by read_mesh, colours
    dropped by it without a word."""
    with pytest.raises(ValueError, match=rf"^mesh: {what} is not finite"):
        write_mesh(tmp_path / f"a{ext}", Mesh(np.eye(3), [[0, 1, 2]], **attribute))
    assert not list(tmp_path.iterdir())


# -- a cache of an earlier run -----------------------------------------------------------
def test_a_correspondence_made_with_other_markers_is_not_reused(sample, tmp_path, capsys):
    markers, cache = tmp_path / "markers.txt", tmp_path / "corr.npz"
    argv = ["transfer", sample["template"], sample["template"], "--source-shapes",
            sample["blendshapes/blink"].parent, "--markers", markers, "--correspondence",
            cache, "-q", "-o"]
    markers.write_text("0 0\n50 50\n99 99\n")
    assert facewrap(*argv, tmp_path / "first") == 0
    markers.write_text("99 99\n0 0\n50 50\n")        # the same pairs: reused
    assert facewrap(*argv, tmp_path / "again") == 0
    markers.write_text("0 10\n50 60\n99 200\n300 400\n")
    capsys.readouterr()
    rc = facewrap(*argv, tmp_path / "edited")
    error_line(capsys, rc, str(cache), "made with other marker pairs (3) than those given (4)")
    assert not (tmp_path / "edited").exists()


def test_transfer_says_odd_triangles_of_its_neutrals(sample, tmp_path, capsys):
    """A third of the target's triangles with a repeated corner moved the shapes by
    millimetres (the sample's smile: up to 5.7 mm off, its largest motion 7.9 mm),
    without a word."""
    template = read_mesh(sample["template"])
    faces = [list(template.face_indices[a:b]) for a, b in
             zip(template.face_offsets[:-1], template.face_offsets[1:])]
    for f in faces[::3]:
        f[1] = f[0]
    target = tmp_path / "target.obj"
    write_mesh(target, Mesh(template.vertices, faces))
    markers = tmp_path / "markers.txt"
    markers.write_text("0 0\n50 50\n99 99\n")
    rc = facewrap("transfer", sample["template"], target, "--source-shapes",
                  sample["blendshapes/blink"].parent, "--markers", markers, "-q",
                  "-o", tmp_path / "out")
    hits = warning_lines(capsys, rc, str(target), "target neutral has",
                         "triangle(s) with a repeated vertex")
    assert len(hits) == 1


def test_a_texture_size_of_true_is_refused(sample, tmp_path):
    """True is an int to Python: a job's ``texture_size=True`` baked a 1 x 1 texture."""
    job = WrapJob(template=str(sample["template"]), scan=str(sample["scan"]),
                  template_landmarks=str(sample["template_landmarks"]),
                  scan_landmarks=str(sample["scan_landmarks"]),
                  texture=str(sample["scan_texture"]), texture_size=True,
                  output=str(tmp_path / "fit.obj"))
    with pytest.raises(InputError, match=r"texture_size .* must be an integer .* got True"):
        run_wrap_job(job, WrapSettings(model="rbf"))
    assert not list(tmp_path.iterdir())


# -- a texture named but not there -------------------------------------------------------
@pytest.mark.parametrize("make", [lambda p: None, os.mkdir, os.mkfifo],
                         ids=["missing", "folder", "fifo"])
def test_a_texture_its_material_names_but_is_not_there_is_said(sample, tmp_path, make):
    """Landmarks were found on the shaded mesh instead, without a word."""
    scan = tmp_path / "scan.obj"
    scan.write_bytes(Path(sample["scan"]).read_bytes())
    (tmp_path / "scan.mtl").write_text("newmtl skin\nmap_Kd skin.png\n")
    make(tmp_path / "skin.png")
    with pytest.warns(InputWarning, match=rf"^{re.escape(str(scan))}: its texture "
                                          r".*skin\.png: .*drawn shaded"):
        assert mesh_texture(scan, read_mesh(scan)) is None


# -- a UV layout of no area ------------------------------------------------------------
def collapsed_uvs(path, out):
    """The mesh at ``path`` with every texture coordinate at (0.5, 0.5)."""
    mesh = read_mesh(path)
    corners = mesh.corner_attributes()
    corners["uvs"] = np.full_like(mesh.uvs, 0.5)
    write_mesh(out, Mesh(mesh.vertices, (mesh.face_offsets, mesh.face_indices), **corners))
    return out


@pytest.mark.parametrize("which, problem", [("template", "nothing would be baked"),
                                            ("scan", "would be one colour")])
def test_a_bake_refuses_a_uv_layout_of_no_area(sample, tmp_path, capsys, which, problem):
    """The template's baked into an all-black image, the scan's into one flat colour,
    without a word."""
    paths = {k: sample[k] for k in ("template", "scan")}
    paths[which] = collapsed_uvs(sample[which], tmp_path / f"{which}.obj")
    out = tmp_path / "out" / "fit.obj"
    rc = facewrap("wrap", paths["template"], paths["scan"], "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks",
                  sample["scan_landmarks"], "--model", "rbf", "-q", "-o", out,
                  "--texture", sample["scan_texture"], "--texture-size", "16")
    error_line(capsys, rc, str(paths[which]), "texture coordinates have zero area", problem)
    assert not out.parent.exists()


def test_a_ground_truth_without_a_known_row_is_refused(sample, tmp_path, capsys):
    """It was measured as "correspondence mean n/a", without a word."""
    truth = tmp_path / "truth.npy"
    np.save(truth, np.full((read_mesh(sample["template"]).n_vertices, 3), np.nan))
    rc = facewrap("evaluate", sample["template"], sample["scan"], "-q",
                  "--ground-truth", truth)
    error_line(capsys, rc, str(truth), "no known position (every row is NaN)")


def test_build_rig_and_snapping_name_what_they_refuse(small):
    """build_rig built the scan's tree first ("V must be finite", naming neither
    mesh); snap_to_surface snapped to a 1e300 vertex with "invalid value" warnings."""
    template, scan = small["tpl"].mesh, small["scan"].mesh
    with pytest.raises(ValueError, match=r"^scan: vertex 5 is not finite"):
        build_rig(template, moved(scan, np.nan), small["tpl"].landmarks,
                  small["scan"].landmarks, small["tpl"].blendshapes,
                  settings=WrapSettings(model="rbf"))
    free = Landmarks.from_points(small["scan"].landmarks.positions(scan))
    far = moved(scan, 1e300)
    with pytest.raises(ValueError, match=r"^vertices: row 5 has coordinate 1e\+300"):
        snap_to_surface(free, far.vertices, far.triangles)


def test_animate_says_one_mesh_given_as_both_ends(sample, tmp_path, capsys):
    """Every frame was the same, written without a word."""
    copy_ = tmp_path / "again.obj"
    copy_.write_bytes(Path(sample["template"]).read_bytes())
    rc = facewrap("animate", sample["template"], copy_, "--frames", "3", "-o",
                  tmp_path / "frames")
    warning_lines(capsys, rc, str(copy_), "again (every vertex alike)")
