"""Hostile inputs of a sixth sweep: the commands other than ``wrap``.

Classes:

- ``--units`` (or a job's ``units``) that the data contradict by a decade or more
  (``--units m`` on a scan in millimetres: a head 0.16 km across) was taken as
  given by every command, and every distance shown was off by that factor without
  a word; ``wrap``, ``run``, ``batch``, ``rig``, ``track``, ``info``,
  ``evaluate``, ``report`` and ``landmarks`` now say so in one line naming the
  file (:func:`facewrap.units.units_conflict`);
- a batch summary's distances (``fit_mean`` ... ``landmark_max``) carried no unit,
  and the jobs of one batch may be in different units; each row now says its
  ``units`` (CSV and JSON, and a resumed job's from its done-record);
- a batch whose jobs nest one output inside another's output folder (a rig's
  ``OUT`` set to another rig's ``OUT/shapes``) ran both: the shapes folder held the
  other person's neutral, GLB and report, and the first job's done-record stopped
  matching its folder, so every resumed run redid it; the manifest is now refused
  naming both jobs, before any runs;
- ``rig``'s expression scans were fitted whatever they showed: one in other units
  (ten times the neutral's size) failed after the neutral's fit with "no template
  vertex found a valid scan point" naming no file (in metres: fitted into garbage
  after a warning about the template's scale); it is now refused before any fit,
  naming the scan (:func:`~facewrap.jobs.input_checks.check_scan_sizes`);
- an expression scan of another person, or one that shows no expression (the
  neutral again, moved or re-exported), made a rig without a word; each is now one
  warning line naming the scan, judged on its wrap by geometry stabilised on the
  skull (:func:`~facewrap.rig.stabilise.unlike_neutral`); the fit is unchanged;
- a scan given twice (the neutral again among a rig's expressions, an expression
  twice, a sequence's frame written twice for ``track``) was fitted as new data
  silently; it is now one warning line naming it and the scan it repeats
  (:func:`~facewrap.jobs.input_checks.repeated_scans`), and a ``track`` frame in
  other units than the first is refused naming it, before any fit, and so is the
  template itself among a track's frames (kept in the scans' folder, it was
  tracked as a frame) or among a rig's expression scans;
- a ``track`` frame of another person (scanned in the sequence's frame) was tracked
  as if it were an expression, silently; with shapes to tell the skull from the
  face, it is now one warning line naming the frame
  (:func:`~facewrap.jobs.input_checks.frames_of_another_head`, the rig's measure);
- ``transfer`` markers mirrored for only some pairs (the left eye's paired with the
  right eye's, the rest right) passed the whole-file mirror test and made a
  correspondence that pairs one eye with the other, silently; markers that fit far
  better exchanged are now one warning naming the marker file (the wrap's
  :func:`~facewrap.wrapping.plausibility.swapped_pairs`; none on Sumner's
  horse-camel and cat-lion markers or Onizuka's avatars);
- a refusal of an expression scan's wrap (its landmark file mirrored, a scan the
  fit finds nothing of) named no file ("facewrap: error: scan landmarks: they match
  a mirror image ..."): the rig could not tell which scan it was about; each
  expression's wrap now says which (:class:`~facewrap.wrapping.track.FrameError`,
  as a track's frames do) and the line names its file;
- a rig of a head in no known unit (its size fits none of mm, cm, m) wrote
  ``rig.glb``, metres by glTF's rule, with the coordinates unscaled (a head
  kilometres across) without a word, and so did a wrap job's ``gltf`` (``run``,
  ``batch``); each is now one warning naming the glTF file;
- ``report`` of a rig's ``rig.json`` failed with "the run's output 'OUT' is
  missing" although the folder was there (it looked for a mesh); it now says it is a
  rig's report and where its page is;
- ``demo --out DIR`` replaced whatever DIR held under the demo's names (a
  project's ``input/scan.obj``, ``report.json``, ``wrapped.obj``) without a word;
  a folder holding such a name that no demo wrote is now refused before any work
  (a re-run into the demo's own folder still replaces its files);
- ``convert`` of an OBJ with materials or groups (a template's parts, a scan's
  textured material) to PLY dropped them without a word; what is left out is now
  one warning line naming the output (the mesh is written whole).

Inputs are the built-in sample at its smallest.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.dispatch import read_mesh, write_mesh
from facewrap.sample.files import write_sample
from facewrap.sample.scan import make_scan
from facewrap.sample.template import make_template
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line, warning_lines, wrap_argv


# -- a given unit the data contradict -------------------------------------------------------
@pytest.mark.parametrize("unit", ["m", "cm", "in"])
def test_wrap_says_a_given_unit_the_head_contradicts(sample, tmp_path, capsys, unit):
    argv = wrap_argv(sample, tmp_path / "fit.obj", "--units", unit)
    warning_lines(capsys, facewrap(*argv), str(sample["scan"]), f"--units {unit} makes",
                  "its size says mm")


def test_a_given_unit_that_fits_is_not_said(sample, tmp_path, capsys):
    assert facewrap(*wrap_argv(sample, tmp_path / "fit.obj", "--units", "mm")) == 0
    assert "--units" not in capsys.readouterr().err


def test_info_evaluate_report_say_a_given_unit_the_head_contradicts(sample, tmp_path,
                                                                    capsys):
    warning_lines(capsys, facewrap("info", sample["scan"], "--units", "m"),
                  str(sample["scan"]), "--units m makes the head")
    fit, run = tmp_path / "fit.obj", tmp_path / "run.json"
    assert facewrap(*wrap_argv(sample, fit, "--report", run)) == 0
    capsys.readouterr()
    warning_lines(capsys, facewrap("evaluate", fit, sample["scan"], "--units", "cm"),
                  str(fit), "--units cm makes the head")
    rc = facewrap("report", run, "-o", tmp_path / "page", "--units", "m")
    warning_lines(capsys, rc, str(fit), "--units m makes the head")
    assert "--units m makes the head" in (tmp_path / "page" / "index.html").read_text()


def test_landmarks_says_a_given_unit_the_head_contradicts(sample, tmp_path, capsys):
    pytest.importorskip("dlib", reason="the optional extra facewrap[landmarks] is absent")
    rc = facewrap("landmarks", sample["scan"], "-o", tmp_path / "lm.json", "--units", "cm")
    hits = warning_lines(capsys, rc, str(sample["scan"]), "--units cm makes the head")
    assert len(hits) == 1


def test_track_says_a_given_unit_once(sample, tmp_path, capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    for k in range(2):
        (seq / f"f{k}.obj").write_bytes(Path(sample["scan"]).read_bytes())
    rc = facewrap("track", sample["template"], seq, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rigid", "-q", "-o", tmp_path / "out", "--units", "m")
    hits = warning_lines(capsys, rc, "--units m makes the head")
    assert len(hits) == 1 and "f0.obj" in hits[0]


# -- a batch summary's units ---------------------------------------------------------------
def test_a_batch_summary_says_each_jobs_units(sample, tmp_path, capsys):
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\ntemplate = "{sample["template"]}"\n'
        f'template_landmarks = "{sample["template_landmarks"]}"\n[wrap]\nmodel = "rbf"\n')
    (tmp_path / "m.csv").write_text(
        "scan,scan_landmarks,output,units\n"
        f"{sample['scan']},{sample['scan_landmarks']},a.obj,\n"
        f"{sample['scan']},{sample['scan_landmarks']},b.obj,cm\n")
    argv = ("batch", tmp_path / "m.csv", "--job", tmp_path / "shared.toml", "--workers", 1,
            "-q")
    for status in ("done", "skipped"):      # a resumed job's unit from its record
        assert facewrap(*argv) == 0
        rows = list(csv.DictReader((tmp_path / "m.summary.csv").open()))
        assert [(r["status"], r["units"]) for r in rows] == [(status, "mm"),
                                                             (status, "cm")]
        assert int(rows[1]["warnings"]) == 1      # the given unit contradicted
        jobs = json.loads((tmp_path / "m.summary.json").read_text())["jobs"]
        assert [j["units"] for j in jobs] == ["mm", "cm"]
    capsys.readouterr()


# -- a rig's expression scans: other units, another person, no expression, repeated -------
def moved_copy(scan: Path, landmarks: Path, folder: Path, scale: float = 1.0,
               angle: float = 0.0) -> tuple[Path, Path]:
    """``scan`` and its landmark points turned by ``angle`` degrees about y, scaled
    by ``scale`` and shifted: one more file of the same surface."""
    a = np.radians(angle)
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    move = lambda P: scale * (np.asarray(P) @ R.T) + [3.0, -2.0, 1.0]   # noqa: E731
    folder.mkdir(parents=True, exist_ok=True)
    m = read_mesh(scan)
    write_mesh(folder / "scan.obj", m.with_vertices(move(m.vertices)))
    np.savetxt(folder / "scan_landmarks.txt", move(np.loadtxt(landmarks)))
    return folder / "scan.obj", folder / "scan_landmarks.txt"


@pytest.fixture(scope="module")
def person(tmp_path_factory) -> dict:
    """A person's neutral scan, a scan of their smile, a smile of another person
    (each in a head pose of its own) and the neutral again, turned and moved."""
    tpl = make_template(24)
    d = tmp_path_factory.mktemp("sweep6_person")
    scans = {name: write_sample(d / name, tpl, make_scan(
        tpl, weights=w, identity_seed=who, resolution=40, texture_size=16, seed=seed))
        for name, w, who, seed in [("neutral", {}, 1, 1), ("smile", {"smile": 1.0}, 1, 2),
                                   ("other", {"smile": 1.0}, 7, 4)]}
    n = scans["neutral"]
    scans["again"] = dict(zip(("scan", "scan_landmarks"), moved_copy(
        n["scan"], n["scan_landmarks"], d / "again", angle=12.0)))
    return scans


def rig_argv(person: dict, out: Path, names, *more) -> list:
    n = person["neutral"]
    return ["rig", n["scan"], *(person[k]["scan"] for k in names), "--template",
            n["template"], "--blendshapes", n["blendshapes/smile"].parent,
            "--template-landmarks", n["template_landmarks"], "--scan-landmarks",
            n["scan_landmarks"],
            *(["--expression-landmarks", *(person[k]["scan_landmarks"] for k in names)]
              if names else []), "-q", "-o", out, *more]


def test_rig_refuses_an_expression_scan_in_other_units(person, tmp_path, capsys):
    s = person["smile"]
    for scale in (10.0, 0.001):
        person["tenfold"] = dict(zip(("scan", "scan_landmarks"), moved_copy(
            s["scan"], s["scan_landmarks"], tmp_path / f"x{scale:g}", scale=scale)))
        rc = facewrap(*rig_argv(person, tmp_path / "rig", ["smile", "tenfold"]))
        error_line(capsys, rc, str(person["tenfold"]["scan"]), "times the size of the one "
                   f"in the neutral scan", "another unit?")
        assert not (tmp_path / "rig").exists()


def test_rig_says_expression_scans_that_cannot_teach_it(person, tmp_path, capsys):
    rc = facewrap(*rig_argv(person, tmp_path / "rig", ["smile", "other", "again", "smile"]))
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 0, err
    said = {k: [ln for ln in err if str(person[k]["scan"]) in ln]
            for k in ("smile", "other", "again")}
    assert len(said["other"]) == 1 and "another person's scan?" in said["other"][0]
    assert len(said["again"]) == 1 and "shows no expression" in said["again"][0]
    # the smile's own scan is fine: only its second listing is said
    assert len(said["smile"]) == 1 and said["smile"][0].startswith(
        f"facewrap: warning: expression scan 4 ({person['smile']['scan']}): the same scan "
        f"as expression scan 1")
    report = json.loads((tmp_path / "rig" / "rig.json").read_text())
    assert len(report["warnings"]) == 3


def test_rig_says_the_neutral_given_again_as_an_expression(person, tmp_path, capsys):
    person["copy"] = person["neutral"]
    rc = facewrap(*rig_argv(person, tmp_path / "rig", ["copy"]))
    hits = warning_lines(capsys, rc, str(person["neutral"]["scan"]))
    assert any("the same scan as the neutral scan" in h for h in hits), hits
    assert any("shows no expression" in h for h in hits), hits


def test_track_says_a_repeated_frame_and_refuses_one_in_other_units(sample, tmp_path,
                                                                    capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    for k in range(3):
        (seq / f"f{k}.obj").write_bytes(Path(sample["scan"]).read_bytes())
    argv = ["track", sample["template"], seq, "--template-landmarks",
            sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
            "--model", "rigid", "-q"]
    hits = warning_lines(capsys, facewrap(*argv, "-o", tmp_path / "a"), "the same scan as")
    assert [h.split(": ")[2] for h in hits] == ["frame 1 (" + str(seq / "f1.obj") + ")",
                                              "frame 2 (" + str(seq / "f2.obj") + ")"]
    moved_copy(sample["scan"], sample["scan_landmarks"], tmp_path / "m", scale=10.0)
    (seq / "f2.obj").write_bytes((tmp_path / "m" / "scan.obj").read_bytes())
    error_line(capsys, facewrap(*argv, "-o", tmp_path / "b"), str(seq / "f2.obj"),
               "the head is 10 times the size of the one in frame 0")
    assert not (tmp_path / "b").exists()


def test_track_says_a_frame_of_another_person(tmp_path, capsys):
    tpl = make_template(24)
    frames = [write_sample(tmp_path / f"f{k}", tpl, make_scan(
        tpl, weights=w, identity_seed=who, resolution=40, texture_size=16, seed=20 + k,
        transform=False))                       # one sequence: one frame of reference
        for k, (w, who) in enumerate([({}, 1), ({"smile": 0.5}, 1), ({"smile": 1.0}, 7),
                                      ({"smile": 1.0}, 1)])]
    f0 = frames[0]
    rc = facewrap("track", f0["template"], *(f["scan"] for f in frames),
                  "--template-landmarks", f0["template_landmarks"], "--scan-landmarks",
                  f0["scan_landmarks"], "--blendshapes", f0["blendshapes/smile"].parent,
                  "-q", "-o", tmp_path / "out")
    hits = warning_lines(capsys, rc, "another person's scan?")
    assert len(hits) == 1 and f"frame 2 ({frames[2]['scan']}): " in hits[0], hits
    report = json.loads((tmp_path / "out" / "track.json").read_text())
    assert any("another person" in w for w in report["warnings"])


#: iBUG-68 indices of the two eyes, right and left, in mirror order
EYES = ((36, 45), (37, 44), (38, 43), (39, 42), (40, 47), (41, 46))


def test_transfer_says_markers_of_one_eye_paired_with_the_other(sample, tmp_path, capsys):
    fit = tmp_path / "fit.obj"
    assert facewrap(*wrap_argv(sample, fit)) == 0
    ids = [int(t) for t in Path(sample["template_landmarks"]).read_text().split()]
    partner = list(range(len(ids)))
    for a, b in EYES:
        partner[a], partner[b] = b, a
    markers = {"right": tmp_path / "right.txt", "eyes": tmp_path / "eyes.txt"}
    markers["right"].write_text("".join(f"{i} {i}\n" for i in ids))
    markers["eyes"].write_text("".join(f"{ids[k]} {ids[partner[k]]}\n"
                                       for k in range(len(ids))))
    capsys.readouterr()
    for name, path in markers.items():
        rc = facewrap("transfer", sample["template"], fit, "--source-shapes",
                      Path(sample["blendshapes/smile"]).parent, "--markers", path,
                      "-o", tmp_path / name, "-q")
        if name == "right":
            assert rc == 0 and "exchanged" not in capsys.readouterr().err
        else:
            hits = warning_lines(capsys, rc, str(path), "12 markers fit far better with "
                                 "their targets exchanged")
            assert len(hits) == 1


def test_convert_to_ply_says_the_materials_and_groups_it_drops(sample, tmp_path, capsys):
    out = tmp_path / "template.ply"
    hits = warning_lines(capsys, facewrap("convert", sample["template"], out), str(out),
                         "PLY keeps no materials or groups", "3 groups ('face'")
    assert len(hits) == 1 and out.is_file()
    hits = warning_lines(capsys, facewrap("convert", sample["scan"], tmp_path / "s.ply"),
                         "1 material ('skin')")
    # nothing to drop: nothing said
    assert facewrap("convert", out, tmp_path / "again.ply") == 0
    assert capsys.readouterr().err == ""


def test_rig_names_the_expression_landmark_file_its_wrap_refuses(person, tmp_path, capsys):
    mirrored = tmp_path / "mirrored.txt"
    L = np.loadtxt(person["smile"]["scan_landmarks"])
    order = list(range(68))
    for a, b in [(k, 16 - k) for k in range(8)] + [(17 + k, 26 - k) for k in range(5)] + [
            (31, 35), (32, 34), *EYES, (48, 54), (49, 53), (50, 52), (55, 59), (56, 58),
            (60, 64), (61, 63), (65, 67)]:
        order[a], order[b] = b, a
    np.savetxt(mirrored, L[order])
    person["mirrored"] = {"scan": person["smile"]["scan"], "scan_landmarks": mirrored}
    rc = facewrap(*rig_argv(person, tmp_path / "rig", ["smile", "mirrored"]))
    error_line(capsys, rc, f"facewrap: error: {mirrored}: they match a mirror image")
    assert not (tmp_path / "rig").exists()


def test_a_batch_refuses_an_output_inside_another_jobs_output_folder(sample, tmp_path,
                                                                     capsys):
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\ntemplate = "{sample["template"]}"\n'
        f'template_landmarks = "{sample["template_landmarks"]}"\n'
        f'blendshapes = "{Path(sample["blendshapes/smile"]).parent}"\n[rig]\n')
    row = f"{sample['scan']},{sample['scan_landmarks']}"
    (tmp_path / "m.csv").write_text(f"scan,scan_landmarks,output\n{row},people/anna\n"
                                    f"{row},people/anna/shapes\n")
    rc = facewrap("batch", tmp_path / "m.csv", "--job", tmp_path / "shared.toml",
                  "--workers", 1, "-q")
    error_line(capsys, rc, "m.csv:3: job 2 writes", "an output folder of job 1 (line 2)")
    assert not (tmp_path / "people").exists()


def test_report_of_a_rig_says_where_its_page_is(person, tmp_path, capsys):
    out = tmp_path / "rig"
    assert facewrap(*rig_argv(person, out, [])) == 0
    rc = facewrap("report", out / "rig.json", "-o", tmp_path / "page")
    error_line(capsys, rc, str(out / "rig.json"), "a rig's report, not a wrap run's: its "
               "page is rig.html beside it")
    assert (out / "rig.html").is_file() and not (tmp_path / "page").exists()


def test_track_refuses_the_template_among_its_frames(sample, tmp_path, capsys):
    seq = tmp_path / "seq"
    seq.mkdir()
    (seq / "a.obj").write_bytes(Path(sample["scan"]).read_bytes())
    template = seq / "template.obj"          # kept beside the scans
    template.write_bytes(Path(sample["template"]).read_bytes())
    rc = facewrap("track", template, seq, "--template-landmarks",
                  sample["template_landmarks"], "--scan-landmarks", sample["scan_landmarks"],
                  "--model", "rigid", "-q", "-o", tmp_path / "out")
    error_line(capsys, rc, f"{template}: is the template itself, not a scan")
    assert not (tmp_path / "out").exists()


def test_demo_refuses_a_folder_whose_files_it_would_replace(tmp_path, capsys):
    (tmp_path / "input").mkdir()
    mine = {tmp_path / "input" / "scan.obj": "v 0 0 0\n", tmp_path / "report.json": "{}"}
    for path, text in mine.items():
        path.write_text(text)
    error_line(capsys, facewrap("demo", "--out", tmp_path, "-q"), str(tmp_path),
               "holds 'input', a name the demo writes, and no demo wrote it")
    assert all(p.read_text() == text for p, text in mine.items())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["input", "report.json"]


def test_rig_says_its_glb_is_unscaled_when_the_unit_is_unknown(person, tmp_path, capsys):
    n, big = person["neutral"], tmp_path / "big"
    (big / "shapes").mkdir(parents=True)
    files = {n["template"]: big / "template.obj", n["scan"]: big / "scan.obj"}
    files.update({p: big / "shapes" / p.name for p in n["blendshapes/smile"].parent.iterdir()})
    for src, dst in files.items():            # ten thousand times: no head's size
        m = read_mesh(src)
        write_mesh(dst, m.with_vertices(1e4 * m.vertices))
    np.savetxt(big / "lm.txt", 1e4 * np.loadtxt(n["scan_landmarks"]))
    out = tmp_path / "rig"
    rc = facewrap("rig", big / "scan.obj", "--template", big / "template.obj",
                  "--blendshapes", big / "shapes", "--template-landmarks",
                  n["template_landmarks"], "--scan-landmarks", big / "lm.txt", "-q", "-o", out)
    hits = warning_lines(capsys, rc, str(out / "rig.glb"), "unit is unknown", "unscaled")
    assert len(hits) == 1
    assert hits[0][len("facewrap: warning: "):] in json.loads(
        (out / "rig.json").read_text())["warnings"]
    glb = tmp_path / "fit.glb"
    rc = facewrap("wrap", big / "template.obj", big / "scan.obj", "--template-landmarks",
                  n["template_landmarks"], "--scan-landmarks", big / "lm.txt", "--model",
                  "rbf", "-q", "-o", tmp_path / "fit.obj", "--gltf", glb)
    assert len(warning_lines(capsys, rc, str(glb), "unit is unknown", "unscaled")) == 1


def test_rig_refuses_the_template_among_its_expression_scans(person, tmp_path, capsys):
    n = person["neutral"]
    ids = [int(t) for t in Path(n["template_landmarks"]).read_text().split()]
    np.savetxt(tmp_path / "points.txt", read_mesh(n["template"]).vertices[ids])
    person["tpl"] = {"scan": n["template"], "scan_landmarks": tmp_path / "points.txt"}
    rc = facewrap(*rig_argv(person, tmp_path / "rig", ["smile", "tpl"]))
    error_line(capsys, rc, f"{n['template']}: is the template itself, not a scan")
    assert not (tmp_path / "rig").exists()
