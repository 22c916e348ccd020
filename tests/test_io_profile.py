"""Template profiles: ICT-FaceKit's vertex_indices.json and facewrap's own, and the
wrap options built on them (no id lists by hand; --fit-mask, --pin)."""

import json
import shutil

import numpy as np
import pytest

from conftest import DATA, facewrap, needs_data
from facewrap.errors import InputError
from facewrap.io.profile import PROFILE_FORMAT, find_template_profile, read_template_profile
from facewrap.landmarks import IBUG68_NAMES
from facewrap.sample import make_scan, make_template, write_sample

ICT = DATA / "ict-facekit" / "FaceXModel"


def write(path, data) -> str:
    path.write_text(json.dumps(data) if not isinstance(data, str) else data)
    return str(path)


@needs_data
def test_reads_icts_vertex_indices_as_published():
    prof = read_template_profile(ICT / "vertex_indices.json")
    assert len(prof.landmarks) == 68 and tuple(prof.landmarks.names) == IBUG68_NAMES
    assert len(prof.fitting) == 7801 and len(prof.rigid) == 1487
    assert prof.summary() == "68 landmarks, 7801 fitting vertices, 1487 rigid vertices"
    prof.check(26719)
    with pytest.raises(InputError, match="another mesh"):
        prof.check(9409)        # ICT's face region alone: the profile is the head's


def test_own_format_with_names_and_without(tmp_path):
    p = write(tmp_path / "a.json", {"format": PROFILE_FORMAT, "version": 1,
                                    "landmarks": list(range(68)), "rigid_vertices": [5, 2, 5]})
    prof = read_template_profile(p)
    assert tuple(prof.landmarks.names) == IBUG68_NAMES       # 68 unnamed: iBUG order
    assert prof.rigid.tolist() == [2, 5] and prof.fitting is None
    few = read_template_profile(write(tmp_path / "b.json", {
        "format": PROFILE_FORMAT, "version": 1, "landmarks": [1, 2, 3]}))
    assert few.landmarks.names is None


@pytest.mark.parametrize("content, message", [
    ("not json", "JSON"),
    ([1, 2], "JSON object"),
    ({"hello": 1}, "not a template profile"),
    ({"format": PROFILE_FORMAT, "version": 2}, "version"),
    ({"format": PROFILE_FORMAT, "version": 1, "landmarks": [1, -2]}, "negative"),
    ({"format": PROFILE_FORMAT, "version": 1, "fitting_vertices": [1, 2.5]}, "integers"),
    ({"format": PROFILE_FORMAT, "version": 1, "landmarks": [{"vertex": 1}]}, "'name'"),
    ({"format": PROFILE_FORMAT, "version": 1,
      "landmarks": [{"name": "a", "vertex": 1}, {"name": "a", "vertex": 2}]}, "repeat"),
    ({"idx_to_landmark_verts": [1, True]}, "integers"),
])
def test_bad_profiles_are_one_error_naming_the_file(tmp_path, content, message):
    p = write(tmp_path / "p.json", content)
    with pytest.raises(InputError, match=message) as exc:
        read_template_profile(p)
    assert str(p) in str(exc.value)


def test_found_beside_the_template(tmp_path):
    t = tmp_path / "head.obj"
    t.write_text("")
    assert find_template_profile(t) is None
    (tmp_path / "vertex_indices.json").write_text("{}")
    assert find_template_profile(t).name == "vertex_indices.json"
    (tmp_path / "head.profile.json").write_text("{}")
    assert find_template_profile(t).name == "head.profile.json"      # its own first


@pytest.fixture(scope="module")
def sample_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("profile_sample")
    tpl = make_template(24)
    paths = write_sample(d, tpl, make_scan(tpl, resolution=40, texture_size=16))
    ids = [int(x) for x in open(paths["template_landmarks"]).read().split()]
    profile = {"format": PROFILE_FORMAT, "version": 1, "landmarks": ids,
               "fitting_vertices": tpl.parts["face"].tolist()}
    write(d / "template.profile.json", profile)
    return d, paths, tpl


def test_wrap_takes_landmarks_and_fitting_vertices_from_the_profile(sample_dir, tmp_path):
    d, p, tpl = sample_dir
    out, rep = tmp_path / "a.obj", tmp_path / "a.json"
    assert facewrap("wrap", p["template"], p["scan"], "--scan-landmarks",
                    p["scan_landmarks"], "-o", out, "--report", rep, "-q") == 0
    report = json.loads(rep.read_text())
    assert report["template_profile"]["path"].endswith("template.profile.json")
    roles = report["vertex_roles"]
    n = tpl.mesh.n_vertices
    covered = sorted((a, b, k) for k, rs in roles.items() for a, b in rs)
    assert covered[0][0] == 0 and covered[-1][1] == n
    assert all(x[1] == y[0] for x, y in zip(covered, covered[1:]))   # a partition
    eyes = np.concatenate([tpl.parts["eyeball_left"], tpl.parts["eyeball_right"]])
    part = np.zeros(n, bool)
    for a, b in roles["part"]:
        part[a:b] = True
    assert part[eyes].all()


def test_no_profile_and_no_landmarks_is_one_line(sample_dir, tmp_path, capsys):
    d, p, _ = sample_dir
    code = facewrap("wrap", p["template"], p["scan"], "--scan-landmarks",
                    p["scan_landmarks"], "-o", tmp_path / "b.obj",
                    "--template-profile", "none")
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "no template landmarks" in err[0]
    assert not (tmp_path / "b.obj").exists()


def test_a_profile_for_another_mesh_is_refused(sample_dir, tmp_path, capsys):
    d, p, tpl = sample_dir
    bad = write(tmp_path / "big.json", {"format": PROFILE_FORMAT, "version": 1,
                                        "landmarks": [0, 1, 10 ** 6]})
    code = facewrap("wrap", p["template"], p["scan"], "--scan-landmarks",
                    p["scan_landmarks"], "-o", tmp_path / "c.obj",
                    "--template-profile", bad)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "another mesh" in err[0] and bad in err[0]


def test_fit_mask_and_pins_from_the_command_line(sample_dir, tmp_path):
    d, p, tpl = sample_dir
    face = tpl.parts["face"]
    mask = write(tmp_path / "mask.txt", " ".join(map(str, face[::2])))
    pins = write(tmp_path / "pins.txt", " ".join(map(str, face[:30])))
    rep = tmp_path / "m.json"
    assert facewrap("wrap", p["template"], p["scan"], "--scan-landmarks",
                    p["scan_landmarks"], "-o", tmp_path / "m.obj", "--fit-mask", mask,
                    "--pin", pins, "--report", rep, "-q") == 0
    roles = json.loads(rep.read_text())["vertex_roles"]
    count = {k: sum(b - a for a, b in rs) for k, rs in roles.items()}
    # the mask's vertices are pulled (the sample's cavities among them); the
    # eyeballs outside it still follow the skin as parts
    eyes = len(tpl.parts["eyeball_left"]) + len(tpl.parts["eyeball_right"])
    assert count["pinned"] == 30 and count["part"] == eyes > 0
    assert count["fitted"] == len(face[::2]) - len(set(face[::2]) & set(face[:30]))
    shutil.rmtree(tmp_path)


def test_report_page_draws_the_profiles_landmarks(sample_dir, tmp_path, caplog):
    from facewrap.report.page import build_report_page
    d, p, _ = sample_dir
    rep = tmp_path / "run.json"
    assert facewrap("wrap", p["template"], p["scan"], "--scan-landmarks",
                    p["scan_landmarks"], "-o", tmp_path / "r.obj", "--report", rep,
                    "-q") == 0
    page = build_report_page(rep, tmp_path / "page")
    html = page.read_text()
    assert "landmarks: result" in html and "landmarks: template" in html
    assert "landmarks not shown" not in caplog.text
