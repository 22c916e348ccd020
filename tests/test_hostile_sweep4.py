"""Hostile inputs of a fourth sweep: one test per bug class it found.

Classes:

- text saved as UTF-16 or UTF-32 with its byte-order mark (Windows PowerShell 5's
  ``>`` and ``Out-File``, Notepad's and Excel's "Unicode") was refused as "binary
  data, not a text file" by every text reader; it now reads as the UTF-8 it
  transcodes to, and a sparse or binary file starting with such a mark is still
  refused from its ends;
- ``evaluate --run`` read the run's JSON with a reader of its own: a FIFO or
  ``/dev/zero`` hung (the latter filling the memory), a 2 GB sparse file was read
  whole, and nesting or a huge integer gave a line naming no file; it now reads it
  as ``facewrap report`` does;
- an output name the file system takes (up to 255 bytes) but longer than 215
  failed with "File name too long" after all the work: the staging and temporary
  prefixes put before it made a name it does not take.  Those names are now cut
  short (extension kept), and a name too long itself is refused before any work;
- ``animate --frames 100000`` was refused for its memory only after its 10^5
  output paths were checked (7 s); the frames' budget is now checked first;
- ``transfer --gltf-scale 1e-300`` wrote a GLB whose positions all rounded to zero
  in float32 (a point), without a word; the scale must now be in [1e-6, 1e6]
  (tested with the other refused scales in ``test_hostile_more.py``);
- ``track`` skipped the template-landmark checks ``wrap`` and ``rig`` make: a
  vertex id listed twice failed deep in the landmark warp with "two landmarks are
  at the same position" naming the scan; it is now named in its file as ``wrap``
  names it;
- vertices no face uses (an exporter's stray points) counted in a mesh's size and
  units: one far away made the template's node spacing, distances and tolerances
  wrong and its units "unknown", without a word (the sample's graph fit: 1.79 ->
  2.87 mm mean against its truth); sizes, units, the fit's frame and the
  deformation graph's nodes are now those of the surface, and the survey says how
  many there are.

Inputs are the built-in sample at its smallest.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.obj import read_obj
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, wrap_argv


def sparse(path: Path, head: bytes, size: int = 2 << 30) -> Path:
    """A file of ``size`` bytes that is ``head`` and then a hole (takes no disk)."""
    with open(path, "wb") as fh:
        fh.write(head)
        fh.truncate(size)
    return path


# -- UTF-16 and UTF-32 text ---------------------------------------------------------------
@pytest.mark.parametrize("codec", ["utf-16", "utf-16-be", "utf-32"])
def test_text_saved_as_wide_unicode_reads(sample, tmp_path, capsys, codec):
    bom = {"utf-16": b"", "utf-16-be": b"\xfe\xff", "utf-32": b""}[codec]
    wide = {}
    for key in ("scan_landmarks", "template_landmarks"):
        text = Path(sample[key]).read_text().replace("\n", "\r\n")
        wide[key] = tmp_path / f"{key}.txt"
        wide[key].write_bytes(bom + text.encode(codec))
    out = tmp_path / "o.obj"
    rc = facewrap(*wrap_argv(dict(sample, **wide), out))
    assert rc == 0, capsys.readouterr().err
    assert out.exists()


def test_a_job_file_saved_as_utf16_runs(sample, tmp_path, capsys):
    job = (f'version = 1\n[inputs]\ntemplate = "{sample["template"]}"\n'
           f'scan = "{sample["scan"]}"\n'
           f'template_landmarks = "{sample["template_landmarks"]}"\n'
           f'scan_landmarks = "{sample["scan_landmarks"]}"\n'
           f'[outputs]\noutput = "{tmp_path / "o.obj"}"\n[wrap]\nmodel = "rbf"\n')
    path = tmp_path / "job.toml"
    path.write_bytes(job.encode("utf-16"))
    assert facewrap("run", path, "-q") == 0, capsys.readouterr().err
    assert (tmp_path / "o.obj").exists()


@pytest.mark.parametrize("what", ["sparse", "bad", "mark only"])
def test_a_file_only_starting_as_utf16_is_refused(sample, tmp_path, capsys, what):
    mark = "1 2 3\n".encode("utf-16")
    path = tmp_path / "lm.txt"
    if what == "sparse":   # refused from its ends, not read whole
        sparse(path, mark)
        needle = "binary data"
    elif what == "bad":    # a lone surrogate
        path.write_bytes(mark + b"\x00\xd8\x41\x00")
        needle = "not UTF-16 text (byte 14)"
    else:
        path.write_bytes(b"\xff\xfe")
        needle = "empty file"
    rc = facewrap(*wrap_argv(dict(sample, scan_landmarks=path), tmp_path / "o.obj"))
    error_line(capsys, rc, "lm.txt", needle)
    assert not (tmp_path / "o.obj").exists()


# -- evaluate --run: the shared JSON reader -----------------------------------------------
def test_evaluate_reads_its_run_report_as_report_does(sample, tmp_path, capsys):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    big = tmp_path / "big.json"
    big.write_text('{"vertex_roles": ' + "9" * 5000 + "}")
    cases = [(tmp_path, "is a folder"),
             (deep, "nested too deeply"),
             (big, "5000 digits"),
             (sparse(tmp_path / "sparse.json", b'{"a": 1}'), "binary data")]
    for path, needle in cases:
        rc = facewrap("evaluate", sample["template"], sample["scan"], "-q", "--run", path)
        line = error_line(capsys, rc, needle, "not a JSON report")
        assert line.startswith(f"facewrap: error: {path}: "), line


# -- long output names ----------------------------------------------------------------------
def test_an_output_name_of_up_to_255_bytes_is_written(sample, tmp_path, capsys):
    stem = "é" * 122                                       # 244 bytes, 248 with ".obj"
    out = tmp_path / f"{stem}.obj"
    rc = facewrap(*wrap_argv(sample, out, "--report", tmp_path / f"{stem}.json",
                             "--texture", sample["scan_texture"]))
    assert rc == 0, capsys.readouterr().err
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == sorted(f"{stem}{ext}" for ext in (".obj", ".json", ".mtl", ".png"))


def test_an_output_name_too_long_is_refused_before_any_work(sample, tmp_path, capsys):
    out = tmp_path / "new" / ("x" * 256 + ".obj")
    rc = facewrap(*wrap_argv(sample, out))
    error_line(capsys, rc, "260 bytes long, more than the 255")
    assert list(tmp_path.iterdir()) == []


# -- a huge frame count: refused before its output paths are walked -------------------------
def test_animate_refuses_too_many_frames_before_checking_each_output(sample, tmp_path):
    """With the address space limited to 8 GiB (a budget of 4), 10^5 frames of the
    sample's 1164 vertices (5.6 GiB) are refused; the output (here a file, the
    scan) is looked at only after that (checking 10^5 paths took seconds)."""
    prelude = ("import resource\n"
               "resource.setrlimit(resource.RLIMIT_AS, (8 << 30, 8 << 30))\n"
               "import sys\nfrom facewrap.cli import main\nsys.exit(main())\n")
    r = subprocess.run([sys.executable, "-c", prelude, "animate", sample["template"],
                        sample["template"], "-o", sample["scan"], "--frames", "100000"],
                       capture_output=True, text=True, timeout=120)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert lines[0].startswith("facewrap: error: --frames: 100000 frames"), lines[0]


# -- track checks its template landmarks as wrap does ---------------------------------------
def test_track_names_a_template_vertex_id_listed_twice(sample, tmp_path, capsys):
    ids = sample["template_landmarks"].read_text().split()
    twice = tmp_path / "ids.txt"
    twice.write_text("\n".join(ids[:5] + ids[4:5] + ids[6:]) + "\n")
    frames = tmp_path / "frames"
    frames.mkdir()
    (frames / "f_0.obj").write_bytes(Path(sample["scan"]).read_bytes())
    rc = facewrap("track", sample["template"], frames, "--template-landmarks", twice,
                  "--scan-landmarks", sample["scan_landmarks"], "-o", tmp_path / "out",
                  "--model", "rbf", "-q")
    line = error_line(capsys, rc, "landmarks 4 and 5 are at the same position")
    assert line.startswith(f"facewrap: error: {twice}: "), line
    assert not (tmp_path / "out").exists()


# -- vertices no face uses ------------------------------------------------------------------
def test_stray_vertices_of_a_template_change_neither_its_size_nor_the_fit(sample, tmp_path,
                                                                          capsys):
    # an exporter's stray points (here one a long way off) were part of the
    # template's size: its node spacing, distances, tolerances and units
    stray = tmp_path / "template_with_strays.obj"
    text = Path(sample["template"]).read_text()
    stray.write_text(text + "v 1000 1000 1000\nv -3 0 0\n")
    runs = {}
    for name, template in (("clean", sample["template"]), ("stray", stray)):
        out, report = tmp_path / f"out_{name}.obj", tmp_path / f"out_{name}.json"
        argv = wrap_argv(dict(sample, template=template), out, "--report", report)
        assert facewrap(*argv) == 0
        runs[name] = (read_obj(out).vertices, json.loads(report.read_text()))
    err = capsys.readouterr().err
    assert "template_with_strays.obj: template has 2 vertices no face uses" in err
    (clean, a), (strayed, b) = runs["clean"], runs["stray"]
    assert b["units"] == a["units"] != "unknown"
    n = len(clean)
    size = np.ptp(clean, axis=0).max()
    np.testing.assert_allclose(strayed[:n], clean, atol=1e-9 * size)


def test_stray_vertices_leave_a_graph_fit_as_accurate(sample, tmp_path):
    # the deformation graph's frame and nodes were the stray point's too: the
    # sample's graph fit went from 1.79 to 2.87 mm mean against its truth
    stray = tmp_path / "template_with_strays.obj"
    stray.write_text(Path(sample["template"]).read_text() + "v 1000 1000 1000\n")
    truth = np.load(sample["ground_truth"])
    seen = np.isfinite(truth).all(axis=1)
    errors = {}
    for name, template in (("clean", sample["template"]), ("stray", stray)):
        out = tmp_path / f"out_{name}.obj"
        argv = [a if a != "rbf" else "graph" for a in wrap_argv(dict(sample, template=template),
                                                                out)]
        assert facewrap(*argv) == 0
        V = read_obj(out).vertices[:len(truth)]
        errors[name] = np.linalg.norm(V - truth, axis=1)[seen].mean()
    assert errors["stray"] < 1.05 * errors["clean"], errors
