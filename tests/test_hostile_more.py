"""Hostile inputs of a campaign against every subcommand (one test per class of bug).

Each test feeds one kind of bad input found to break the rules for bad input —
inputs never written, one line naming the file or option and the problem with
exit status 2, never a traceback, nothing implausible fitted silently — and
checks the rule now holds.  Inputs are tiny (a 4 x 4 grid, the sample at its
smallest) so the file runs in seconds.
"""

from __future__ import annotations

import hashlib
import os
import warnings
from pathlib import Path

import numpy as np
import pytest

import facewrap.cli.info as info_command
from facewrap.cli import main
from facewrap.io.obj import write_obj
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template, write_sample
from conftest import facewrap, write_mirrored_obj


def grid(n: int = 4, size: float = 100.0) -> Mesh:
    """An n x n vertex grid in the z = 0 plane, two triangles per cell."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    V = np.column_stack([x.ravel(), y.ravel(), np.zeros(n * n)])
    i = np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]
    i = i.ravel()
    T = np.vstack([np.column_stack([i, i + 1, i + n]), np.column_stack([i + 1, i + n + 1, i + n])])
    return Mesh(V, T)


def one_line_error(capsys, rc: int, *needles: str) -> str:
    """The command failed with status 2 and one ``facewrap: error:`` line holding
    every needle; returns it."""
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2, err
    assert len(err) == 1 and err[0].startswith("facewrap: error: "), err
    assert "Traceback" not in err[0]
    for needle in needles:
        assert needle in err[0], err[0]
    return err[0]


def digest(folder: Path) -> dict:
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> dict:
    """The built-in sample at its smallest (template 24, scan 40), as files."""
    folder = tmp_path_factory.mktemp("sample")
    template = make_template(24)
    return write_sample(folder, template, make_scan(template, resolution=40,
                                                    texture_size=16))


def wrap_argv(p: dict, *more) -> list:
    return ["wrap", p["template"], p["scan"], "--template-landmarks", p["template_landmarks"],
            "--scan-landmarks", p["scan_landmarks"], "--model", "rbf", "-q", *more]


# -- coordinates no head has: every reader, every command --------------------------------
def huge_mesh_file(folder: Path, ext: str) -> Path:
    """A grid with one vertex at 1e30 (float32-safe, so STL can hold it too)."""
    m = grid()
    V = m.vertices.copy()
    V[5] = [1e30, 0.0, 0.0]
    path = folder / f"huge{ext}"
    if ext == ".obj":
        write_obj(path, Mesh(V, m.triangles))
    else:
        import trimesh
        trimesh.Trimesh(V, m.triangles, process=False).export(path)
    return path


@pytest.mark.parametrize("ext", [".obj", ".ply", ".stl", ".off"])
@pytest.mark.parametrize("command", ["info", "convert", "evaluate"])
def test_coordinates_beyond_any_head_are_refused_by_every_reader(ext, command, tmp_path,
                                                                 capsys):
    """1e30 passed the NaN check: info printed overflow warnings, evaluate and track
    fitted with NaN normals, transfer failed with 'SVD did not converge'."""
    bad = huge_mesh_file(tmp_path, ext)
    good = tmp_path / "good.obj"
    write_obj(good, grid())
    argv = {"info": ["info", bad], "convert": ["convert", bad, tmp_path / "out.ply"],
            "evaluate": ["evaluate", good, bad, "-q"]}[command]
    line = one_line_error(capsys, facewrap(*argv), str(bad), "too large")
    assert "1e+30" in line
    assert not (tmp_path / "out.ply").exists()


# -- the command line's door: warnings and the unforeseen --------------------------------
def test_warnings_are_one_line_and_no_exception_is_a_traceback(tmp_path, capsys,
                                                               monkeypatch):
    """A library's RuntimeWarning printed two lines of source each (twenty lines
    round a one-line error); an exception no check foresaw printed a traceback."""
    def broken(args):
        warnings.warn("overflow encountered in multiply", RuntimeWarning)
        warnings.warn("the scan looks odd", UserWarning)
        raise IndexError("index 7 is out of bounds for axis 0 with size 3")
    monkeypatch.setattr(info_command, "cmd_info", broken)
    rc = facewrap("info", tmp_path / "any.obj")
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert err == ["facewrap: warning: the scan looks odd",
                   "facewrap: error: IndexError: index 7 is out of bounds for axis 0 with "
                   "size 3 (an input no check foresaw; -vv shows where)"]
    assert warnings.showwarning.__module__ == "warnings"   # the caller's display is back


# -- outputs -------------------------------------------------------------------------------
def test_a_hard_link_to_an_input_is_that_input(tmp_path, capsys):
    """A hard link was not recognised as the input (a symbolic link was)."""
    src = tmp_path / "a.obj"
    write_obj(src, grid())
    os.link(src, tmp_path / "b.obj")
    before = digest(tmp_path)
    one_line_error(capsys, facewrap("convert", src, tmp_path / "b.obj"),
                   "is also an input")
    assert digest(tmp_path) == before


def test_an_output_file_ending_in_a_slash_is_refused(tmp_path, capsys):
    """``--json out/r/`` wrote a file called ``r``."""
    mesh = tmp_path / "a.obj"
    write_obj(mesh, grid())
    one_line_error(capsys, facewrap("evaluate", mesh, mesh, "-q", "--json",
                                    f"{tmp_path}/out/r/"), "ends in '/'")
    assert not (tmp_path / "out").exists()


def test_a_job_file_is_an_input_of_its_own_job(sample, tmp_path, capsys):
    """``report = "job.toml"`` replaced the job file with the run's report."""
    job = tmp_path / "job.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample["template"]}"\nscan = "{sample["scan"]}"\n'
                   f'template_landmarks = "{sample["template_landmarks"]}"\n'
                   f'scan_landmarks = "{sample["scan_landmarks"]}"\n'
                   '[outputs]\noutput = "out/fitted.obj"\nreport = "job.toml"\n')
    before = job.read_bytes()
    one_line_error(capsys, facewrap("run", "-q", job), "is also an input")
    assert job.read_bytes() == before and not (tmp_path / "out").exists()


def test_write_template_only_to_a_toml_name(tmp_path, capsys):
    """``run scan.obj --write-template --force`` wrote TOML over a mesh."""
    mesh = tmp_path / "scan.obj"
    write_obj(mesh, grid())
    before = mesh.read_bytes()
    one_line_error(capsys, facewrap("run", mesh, "--write-template", "--force"), ".toml")
    assert mesh.read_bytes() == before


# -- job files ---------------------------------------------------------------------------
def test_a_job_file_with_a_byte_order_mark_reads(tmp_path, capsys):
    """A UTF-8 BOM (Windows editors) was 'invalid TOML: Invalid statement'."""
    job = tmp_path / "job.toml"
    facewrap("run", job, "--write-template", "-q")
    job.write_bytes(b"\xef\xbb\xbf" + job.read_bytes())
    for name in ("template.obj", "scan.obj", "scan_landmarks.txt", "template_landmarks.txt"):
        (tmp_path / name).write_text("")
    capsys.readouterr()
    assert facewrap("run", "--dry-run", job) == 0, capsys.readouterr().err


# -- options -----------------------------------------------------------------------------
@pytest.mark.parametrize("more, option", [
    (["--weight-range", "0", "1", "--no-weight-range"], "--no-weight-range"),
    (["--no-landmark-pull", "--landmark-tolerance", "0.1"], "--landmark-tolerance")])
def test_a_switch_undoing_an_option_beside_it_is_refused(more, option, capsys):
    """One of the two silently won."""
    with pytest.raises(SystemExit) as exc:
        main(["wrap", "t.obj", "s.obj", "-o", "x.obj", *more])
    err = capsys.readouterr().err.strip().splitlines()
    assert exc.value.code == 2 and len(err) == 1 and option in err[0], err


def test_pca_components_without_blendshapes_is_refused(sample, tmp_path, capsys):
    """The setting was dropped silently."""
    one_line_error(capsys, facewrap(*wrap_argv(sample, "-o", tmp_path / "f.obj",
                                               "--pca-components", "2")),
                   "--pca-components", "no blendshapes")
    assert not (tmp_path / "f.obj").exists()


@pytest.mark.parametrize("value", ["1e308", "0", "nan", "1e-300", "1e-9"])
def test_transfer_settings_name_their_option(sample, value, tmp_path, capsys):
    """A 1e308 --gltf-scale failed in the report's JSON ('Out of range float values
    are not JSON compliant'); refused values were named TransferJobSettings.x; a
    scale below 1e-6 rounded every position to zero in float32 (sweep 4)."""
    markers = tmp_path / "markers.txt"
    ids = sample["template_landmarks"].read_text().split()[:12]
    markers.write_text("".join(f"{i} {i}\n" for i in ids))
    rc = facewrap("transfer", sample["template"], sample["template"], "--markers", markers,
                  "--source-shapes", sample["blendshapes/blink"].parent, "-o",
                  tmp_path / "shapes", "--gltf", tmp_path / "x.glb", "--gltf-scale", value,
                  "-q")
    one_line_error(capsys, rc, "--gltf-scale: must be")
    assert not (tmp_path / "shapes").exists()


@pytest.mark.parametrize("up, problem", [(["0", "0", "0"], "non-zero"),
                                         (["nan", "1", "0"], "finite")])
def test_report_view_axes_name_their_option(up, problem, tmp_path, capsys):
    """``report --template-up 0 0 0`` said 'view_up must be a non-zero 3-vector,
    got array([0., 0., 0.])', naming no option."""
    one_line_error(capsys, facewrap("report", tmp_path / "run.json", "-o", tmp_path / "r",
                                    "--template-up", *up), "--template-up", problem)


def test_huge_view_axes_keep_their_direction(tmp_path, capsys):
    """``evaluate --up 1e308 1e308 0`` overflowed the norm: 'frame must be a (3, 3)
    rotation matrix'; the direction (1, 1, 0) is meant."""
    mesh = tmp_path / "a.obj"
    write_obj(mesh, grid())
    rc = facewrap("evaluate", mesh, mesh, "-q", "--heatmap", tmp_path / "h.png",
                  "--up", "1e308", "1e308", "0")
    assert rc == 0, capsys.readouterr().err
    assert (tmp_path / "h.png").is_file()


@pytest.mark.parametrize("array, problem", [
    (np.zeros((16, 3), dtype=complex), "real numbers"),
    (np.full((16, 3), np.inf), "infinite or too large")])
def test_ground_truth_of_no_real_positions_is_refused(array, problem, tmp_path, capsys):
    """A complex array was cast silently (imaginary parts dropped); an infinite one
    was measured."""
    mesh = tmp_path / "a.obj"
    write_obj(mesh, grid())
    truth = tmp_path / "truth.npy"
    np.save(truth, array)
    one_line_error(capsys, facewrap("evaluate", mesh, mesh, "-q", "--ground-truth", truth),
                   str(truth), problem)


def test_landmarks_beyond_any_head_are_refused(sample, tmp_path, capsys):
    """A 1e308 landmark passed the NaN check: the wrap said 'landmarks are all at
    one point or on one line', evaluate measured it silently."""
    rows = sample["scan_landmarks"].read_text().splitlines()
    rows[4] = "1e308 0 0"
    bad = tmp_path / "landmarks.txt"
    bad.write_text("\n".join(rows) + "\n")
    one_line_error(capsys, facewrap(*wrap_argv(sample, "-o", tmp_path / "f.obj")[:6], bad,
                                    "-q", "-o", tmp_path / "f.obj"),
                   str(bad), "landmark 4 has coordinate 1e+308, too large")
    one_line_error(capsys, facewrap("evaluate", sample["template"], sample["scan"], "-q",
                                    "--scan-landmarks", bad, "--result-landmarks",
                                    sample["template_landmarks"]), str(bad), "too large")


def test_track_checks_each_scan_as_wrap_does(sample, tmp_path, capsys):
    """``track`` fitted a sphere whose landmarks (a face's) lie off it, silently;
    ``wrap`` refuses it ('landmarks are not on the scan')."""
    import trimesh
    V = np.array([float(x) for ln in sample["scan"].read_text().splitlines()
                  if ln.startswith("v ") for x in ln.split()[1:4]]).reshape(-1, 3)
    ball = trimesh.creation.icosphere(3, radius=100.0)
    sphere = tmp_path / "sphere.obj"
    write_obj(sphere, Mesh(ball.vertices + V.mean(axis=0), ball.faces))
    rc = facewrap("track", sample["template"], sphere, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rbf", "-o", tmp_path / "seq", "-q")
    one_line_error(capsys, rc, "landmarks are not on the scan")
    assert not (tmp_path / "seq").exists()


@pytest.mark.parametrize("victim", ["manifest", "job"])
def test_a_batch_never_writes_over_its_manifest_or_job_file(sample, victim, tmp_path,
                                                            capsys):
    """A row's ``report`` naming the manifest replaced it with the run's JSON."""
    job = tmp_path / "shared.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample["template"]}"\n'
                   f'template_landmarks = "{sample["template_landmarks"]}"\n'
                   '[wrap]\nmodel = "rbf"\n')
    manifest = tmp_path / "m.csv"
    target = manifest if victim == "manifest" else job
    manifest.write_text("scan,scan_landmarks,output,report\n"
                        f"{sample['scan']},{sample['scan_landmarks']},out/a.obj,{target}\n")
    before = digest(tmp_path)
    one_line_error(capsys, facewrap("batch", manifest, "--job", job, "--workers", "1", "-q"),
                   "is also an input")
    assert digest(tmp_path) == before


def test_an_unusable_dask_address_names_the_option(sample, tmp_path, capsys):
    """'missing port number in address ...' named no option."""
    job = tmp_path / "shared.toml"
    job.write_text(f'[inputs]\ntemplate = "{sample["template"]}"\n'
                   f'template_landmarks = "{sample["template_landmarks"]}"\n')
    manifest = tmp_path / "m.csv"
    manifest.write_text("scan,scan_landmarks,output\n"
                        f"{sample['scan']},{sample['scan_landmarks']},out/a.obj\n")
    pytest.importorskip("distributed")
    one_line_error(capsys, facewrap("batch", manifest, "--job", job, "--dask",
                                    "not an address", "-q"), "--dask")


def test_mixed_line_ends_read_as_lines(tmp_path):
    """LF, CRLF and lone CR in one file (pasted together): the lone CRs ran two
    lines into one ('vertex line has a value that is not a number')."""
    from facewrap.io import read_mesh
    mesh = grid()
    plain = tmp_path / "plain.obj"
    write_obj(plain, mesh)
    lines = plain.read_text().splitlines()
    mixed = tmp_path / "mixed.obj"
    mixed.write_bytes("".join(ln + ("\n", "\r\n", "\r")[k % 3]
                              for k, ln in enumerate(lines)).encode())
    got = read_mesh(mixed)
    assert np.array_equal(got.vertices, mesh.vertices)
    assert np.array_equal(got.face_indices, read_mesh(plain).face_indices)


def test_info_lengths_carry_their_unit(sample, capsys):
    """``info`` printed the bounding box and diagonal as bare numbers."""
    assert facewrap("info", sample["scan"]) == 0
    out = capsys.readouterr().out.splitlines()
    box = next(ln for ln in out if "bounding_box" in ln)
    diagonal = next(ln for ln in out if "diagonal" in ln)
    assert box.endswith(" mm") and diagonal.endswith(" mm")
    assert out[-1].startswith("units: mm (inferred")


def test_a_nul_in_a_job_file_path_names_the_key(tmp_path, capsys):
    """'embedded null byte', naming no file or key."""
    job = tmp_path / "job.toml"
    job.write_text('[inputs]\ntemplate = "t.obj"\nscan = "s.obj"\n'
                   '[outputs]\noutput = "out/a\\u0000b.obj"\n')
    one_line_error(capsys, facewrap("run", job), f"{job}:5", "'output' holds a NUL")


def test_evaluate_warns_of_a_scan_in_other_units(sample, tmp_path, capsys):
    """A scan in metres measured against a millimetre result gave '99.18 mm' as if
    it were a fit."""
    lines = sample["scan"].read_text().splitlines(keepends=True)
    metres = tmp_path / "scan_m.obj"
    metres.write_text("".join(
        "v " + " ".join(repr(float(t) / 1000) for t in ln.split()[1:4]) + "\n"
        if ln.startswith("v ") else ln for ln in lines))
    assert facewrap("evaluate", sample["template"], metres, "-q") == 0
    warned = capsys.readouterr().err.strip().splitlines()
    assert len(warned) == 1 and warned[0].startswith(f"facewrap: warning: {metres}:")
    assert "m)" in warned[0] and "mm," in warned[0] and "other units" in warned[0]


def test_a_failed_track_is_one_line(sample, tmp_path, capsys):
    """A frame's check warnings were printed before the run, so a track that then
    failed (mirrored landmarks) ended with two lines."""
    P = np.loadtxt(sample["scan_landmarks"])
    P[:, 0] *= -1.0      # left and right swapped, the scan unchanged
    mirrored = tmp_path / "mirrored.txt"
    np.savetxt(mirrored, P)
    rc = facewrap("track", sample["template"], sample["scan"], "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", mirrored,
                  "--model", "rbf", "-o", tmp_path / "seq", "-q")
    # the line names the landmark file, as wrap's does ("scan landmarks: ..." before)
    line = one_line_error(capsys, rc, "mirror image", f"{mirrored}: ")
    assert "scan landmarks:" not in line


def test_evaluate_names_the_landmark_file_that_disagrees(sample, tmp_path, capsys):
    """'landmark counts differ: 68 vs 3' named neither file; landmarks in metres
    on a millimetre scan were measured without a word."""
    P = np.loadtxt(sample["scan_landmarks"])
    three = tmp_path / "three.txt"
    np.savetxt(three, P[:3])
    argv = ["evaluate", sample["template"], sample["scan"], "-q", "--result-landmarks",
            sample["template_landmarks"], "--scan-landmarks"]
    one_line_error(capsys, facewrap(*argv, three), f"{three}: has 3 landmarks")
    metres = tmp_path / "metres.txt"
    np.savetxt(metres, P / 1000.0)
    assert facewrap(*argv, metres) == 0
    warned = capsys.readouterr().err.strip().splitlines()
    assert len(warned) == 1 and f"{metres}: the landmarks lie off the scan" in warned[0]
    assert " mm" in warned[0]


def test_track_warns_of_landmarks_off_a_frame_as_wrap_does(sample, tmp_path, capsys):
    """A mirrored scan under unmirrored landmarks: wrap warned that 51 landmarks lie
    off the scan, track fitted it without a word."""
    mirrored = write_mirrored_obj(sample["scan"], tmp_path / "mirrored.obj")
    rc = facewrap("track", sample["template"], mirrored, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rbf", "-o", tmp_path / "seq", "-q")
    warned = capsys.readouterr().err.strip().splitlines()
    assert rc == 0
    assert any(ln.startswith(f"facewrap: warning: frame 0 ({mirrored}): ")
               and "lie off the scan surface" in ln for ln in warned), warned


@pytest.mark.parametrize("bare, needle", [(b"f\n", ":5: face needs at least 3 corners"),
                                          (b"f\r\n", ":5: face needs at least 3 corners"),
                                          (b"v", ":5: vertex line needs 3 numbers")])
def test_a_keyword_with_nothing_after_it_is_named_not_skipped(bare, needle, tmp_path,
                                                              capsys):
    mesh = tmp_path / "bare.obj"
    mesh.write_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n" + bare)
    one_line_error(capsys, facewrap("info", mesh), f"{mesh}{needle}")
