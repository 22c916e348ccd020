"""Rig jobs (facewrap.jobs.rig_job): the library call, outputs, job files, batches."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from facewrap.batch import read_manifest, run_batch
from facewrap.errors import InputError
from facewrap.io import read_mesh
from facewrap.io.gltf import read_gltf_morphs
from facewrap.jobs import JOB_KINDS, RIG, RigJob, load_job, run_rig_job
from facewrap.rig import Rig
from facewrap.sample import make_scan, make_template, write_sample

#: a rig report's timings that ran beside others (their seconds are in those), and
#: the total
BESIDE = {"texture", "texture_flow", "stabilise", "total"}


@pytest.fixture(scope="module")
def sample(tmp_path_factory) -> dict:
    """The built-in sample, small: template, blendshapes, textured scan, landmarks."""
    tpl = make_template(24)
    folder = tmp_path_factory.mktemp("rig_sample")
    paths = write_sample(folder, tpl, make_scan(tpl, resolution=40, texture_size=32))
    return {"dir": folder, "paths": paths, "template": tpl}


def rig_job(sample, out, **kw) -> RigJob:
    p = sample["paths"]
    return RigJob(template=str(p["template"]), scan=str(p["scan"]),
                  blendshapes=str(sample["dir"] / "blendshapes"), output=str(out),
                  scan_landmarks=str(p["scan_landmarks"]),
                  template_landmarks=str(p["template_landmarks"]), **kw)


@pytest.fixture(scope="module")
def textured(sample, tmp_path_factory):
    """One textured rig run: (job, report)."""
    out = tmp_path_factory.mktemp("rig_out") / "anna"
    job = rig_job(sample, out, texture=str(sample["paths"]["scan_texture"]),
                  texture_size=32)
    return job, run_rig_job(job)


def test_outputs_are_the_neutral_its_shapes_a_glb_and_a_report(sample, textured):
    job, report = textured
    out = Path(job.output)
    names = sorted(sample["template"].blendshapes)
    assert sorted(p.stem for p in (out / "shapes").iterdir()) == names
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["neutral.obj", "neutral.mtl", "neutral.png", "shapes", "rig.glb", "rig.json",
         "rig.html"])
    # the page: the rig with a slider per shape, its texture
    from test_report_page import page_data
    data = page_data(out / "rig.html")
    assert data["blendshapes"]["mesh"] == "rig" and len(data["textures"]) == 1
    assert len(data["blendshapes"]["shapes"]) == len(names)
    assert report["outputs"]["page"] == str(out / "rig.html")
    # nothing staged is left beside the folder
    assert [p.name for p in out.parent.iterdir()] == ["anna"]
    template = read_mesh(sample["paths"]["template"])
    neutral = read_mesh(out / "neutral.obj")
    np.testing.assert_array_equal(neutral.face_indices, template.face_indices)
    np.testing.assert_array_equal(neutral.face_offsets, template.face_offsets)
    assert neutral.uvs is not None and neutral.mtllib == ("neutral.mtl",)
    assert "map_Kd neutral.png" in (out / "neutral.mtl").read_text()
    smile = read_mesh(out / "shapes" / "smile.obj")
    np.testing.assert_array_equal(smile.face_indices, template.face_indices)
    assert smile.mtllib == ("../neutral.mtl",)
    assert json.loads((out / "rig.json").read_text()) == json.loads(json.dumps(report))


def test_the_glb_holds_the_neutral_and_every_shape_in_metres(sample, textured):
    job, report = textured
    out = Path(job.output)
    assert report["units"] == "mm"   # the sample head is millimetre-sized
    glb = read_gltf_morphs(out / "rig.glb")
    names = sorted(p.stem for p in (out / "shapes").iterdir())
    assert sorted(glb.shapes) == names
    neutral = read_mesh(out / "neutral.obj")
    # float32 in the file: metres to a micrometre
    np.testing.assert_allclose(glb.vertices, neutral.vertices * 1e-3, atol=1e-6)
    for name in names:
        shape = read_mesh(out / "shapes" / f"{name}.obj").vertices
        np.testing.assert_allclose(glb.shapes[name], shape * 1e-3, atol=1e-6)
    import pygltflib
    doc = pygltflib.GLTF2().load(str(out / "rig.glb"))
    assert len(doc.images) == 1 and doc.materials[0].pbrMetallicRoughness.baseColorTexture
    assert report["outputs"]["gltf"] == {"path": str(out / "rig.glb"), "scale": 0.001,
                                         "units": "m"}


def test_the_report_says_units_timings_fit_method_and_shapes(sample, textured):
    job, report = textured
    assert report["method"] == "deformation"
    assert report["shapes"] == sorted(sample["template"].blendshapes)
    t = report["timings"]
    assert set(t) >= {"read", "wrap", "shapes", "texture", "writing", "total"}
    assert all(v >= 0 for v in t.values()) and t["texture"] > 0
    # the bake runs beside the shapes: the total holds the longer of the two
    parts = t["read"] + t["wrap"] + t["writing"]
    assert parts + max(t["shapes"], t["texture"]) <= t["total"] + 1e-6
    assert t["total"] <= parts + t["shapes"] + t["texture"] + 1e-6
    m = report["metrics"]
    assert 0 <= m["fit_mean"] <= m["fit_max"] and m["landmark_mean"] >= 0
    assert report["texture"]["image"] == str(Path(job.output) / "neutral.png")
    assert report["outputs"]["shapes"]["smile"] == str(
        Path(job.output) / "shapes" / "smile.obj")


def test_delta_shapes_are_the_template_displacements_in_the_scan_frame(sample, tmp_path):
    report = run_rig_job(rig_job(sample, tmp_path / "d", method="delta"))
    assert report["method"] == "delta" and "texture" not in report
    M = np.asarray(report["transform"])[:3, :3]   # scale times rotation
    tpl = sample["template"]
    neutral = read_mesh(tmp_path / "d" / "neutral.obj").vertices
    for name, V in tpl.blendshapes.items():
        shape = read_mesh(tmp_path / "d" / "shapes" / f"{name}.obj").vertices
        np.testing.assert_allclose(shape - neutral, (V - tpl.mesh.vertices) @ M.T,
                                   atol=1e-6)
    # no texture: no image, no material library, the GLB plain
    assert not (tmp_path / "d" / "neutral.png").exists()


def test_a_rig_job_file_runs(sample, tmp_path):
    p = sample["paths"]
    job_file = tmp_path / "rig.toml"
    job_file.write_text(
        f'[inputs]\ntemplate = "{p["template"]}"\nscan = "{p["scan"]}"\n'
        f'scan_landmarks = "{p["scan_landmarks"]}"\n'
        f'template_landmarks = "{p["template_landmarks"]}"\n'
        f'blendshapes = "{sample["dir"] / "blendshapes"}"\n'
        '[outputs]\noutput = "people/anna"\nmethod = "delta"\n'
        '[rig]\nnode_spacing = 0.05\n')
    job, settings = load_job(job_file)
    assert isinstance(job, RigJob) and JOB_KINDS["rig"] is RIG
    assert job.output == str(tmp_path / "people" / "anna") and job.method == "delta"
    assert settings.node_spacing == 0.05
    report = RIG.run(job, settings)
    assert report["settings"]["node_spacing"] == 0.05
    assert (tmp_path / "people" / "anna" / "rig.glb").is_file()
    bad = tmp_path / "bad.toml"
    bad.write_text(job_file.read_text().replace('"delta"', '"wobble"'))
    with pytest.raises(InputError, match="method must be one of deformation, delta"):
        load_job(bad)


def test_a_batch_of_two_people_runs_and_resumes(sample, tmp_path):
    p = sample["paths"]
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\ntemplate = "{p["template"]}"\n'
        f'template_landmarks = "{p["template_landmarks"]}"\n'
        f'blendshapes = "{sample["dir"] / "blendshapes"}"\n[rig]\n')
    rows = "".join(f'[[jobs]]\nscan = "{p["scan"]}"\nscan_landmarks = '
                   f'"{p["scan_landmarks"]}"\noutput = "people/{who}"\n'
                   for who in ("anna", "ben"))
    manifest = tmp_path / "people.toml"
    manifest.write_text('job = "shared.toml"\n' + rows)
    jobs = read_manifest(manifest)
    assert [bj.kind for bj in jobs] == [RIG, RIG]
    result = run_batch(jobs, workers=1)
    assert [r["status"] for r in result.rows] == ["done", "done"], result.rows
    for who in ("anna", "ben"):
        assert (tmp_path / "people" / who / "rig.json").is_file()
    again = run_batch(read_manifest(manifest), workers=1)
    assert [r["status"] for r in again.rows] == ["skipped", "skipped"]
    # two people written to one folder are refused before anything runs
    manifest.write_text('job = "shared.toml"\n' + rows.replace("people/ben", "people/anna"))
    with pytest.raises(InputError, match="both write"):
        read_manifest(manifest)


def test_an_output_folder_inside_an_input_is_refused(sample, tmp_path):
    inside = sample["dir"] / "blendshapes" / "rig"
    with pytest.raises(InputError, match="lies in the input folder"):
        run_rig_job(rig_job(sample, inside))
    assert not inside.exists()
    with pytest.raises(InputError, match="is also an input"):
        # a scan named like the rig's own neutral, inside the output folder
        run_rig_job(replace(rig_job(sample, sample["dir"]),
                            scan=str(sample["dir"] / "neutral.obj")))


def test_bad_input_names_the_file_and_writes_nothing(sample, tmp_path):
    bad = tmp_path / "bad_landmarks.txt"
    bad.write_text("1 2\n")
    out = tmp_path / "out"
    with pytest.raises(InputError) as exc:
        run_rig_job(replace(rig_job(sample, out), scan_landmarks=str(bad)))
    assert str(bad) in str(exc.value)
    with pytest.raises(InputError, match="no such file|not a folder"):
        run_rig_job(replace(rig_job(sample, out), blendshapes=str(tmp_path / "none")))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad_landmarks.txt"]


def test_a_failure_while_writing_leaves_nothing(sample, tmp_path, monkeypatch):
    def full_disk(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(Rig, "write_gltf", full_disk)
    with pytest.raises(OSError):
        run_rig_job(rig_job(sample, tmp_path / "people" / "anna"))
    assert list(tmp_path.iterdir()) == []


# -- expression scans ------------------------------------------------------------------
#: the expressions scanned: one shape each, at full and partial strength
EXPRESSIONS = ({"smile": 1.0}, {"jaw_open": 0.7})


@pytest.fixture(scope="module")
def person(tmp_path_factory) -> dict:
    """A neutral scan and scans of two of the same face's expressions (each in a head
    pose of its own), with landmarks; the template and its shapes."""
    tpl = make_template(24)
    d = tmp_path_factory.mktemp("rig_person")
    neutral = write_sample(d / "neutral", tpl, make_scan(
        tpl, weights={}, resolution=40, texture_size=16, seed=1))
    scans = [write_sample(d / f"x{k}", tpl, make_scan(
        tpl, weights=w, resolution=40, texture_size=16, seed=2 + k))
        for k, w in enumerate(EXPRESSIONS)]
    return {"dir": d, "neutral": neutral, "scans": scans}


def person_job(person, out, **kw) -> RigJob:
    n = person["neutral"]
    return RigJob(template=str(n["template"]), scan=str(n["scan"]),
                  blendshapes=str(person["dir"] / "neutral" / "blendshapes"),
                  output=str(out), scan_landmarks=str(n["scan_landmarks"]),
                  template_landmarks=str(n["template_landmarks"]),
                  expression_scans=[str(s["scan"]) for s in person["scans"]],
                  expression_landmarks=[str(s["scan_landmarks"]) for s in person["scans"]],
                  **kw)


def test_expression_scans_correct_the_shapes_and_are_reported(person, tmp_path):
    report = run_rig_job(person_job(person, tmp_path / "rig"))
    examples = report["examples"]
    assert [e["scan"] for e in examples] == [str(s["scan"]) for s in person["scans"]]
    for meant, e in zip(EXPRESSIONS, examples):
        (name, strength), = meant.items()
        w = e["weights"]
        assert set(w) == set(report["shapes"]) and all(0 <= v <= 1 for v in w.values())
        # the scanned expression is found at about its strength, the others stay small
        assert w[name] == pytest.approx(strength, abs=0.1)
        assert max(v for k, v in w.items() if k != name) < 0.2
        # the corrected rig reproduces its example better than the neutral-only one
        assert e["error"]["mean"] < e["neutral_only_error"]["mean"]
        assert e["error"]["mean"] <= e["error"]["p95"]
        pose = np.asarray(e["pose"])
        assert pose.shape == (4, 4)
        np.testing.assert_allclose(pose[:3, :3] @ pose[:3, :3].T, np.eye(3), atol=1e-9)
    t = report["timings"]
    assert {"expressions", "stabilise", "examples"} <= set(t)
    # the bake ran beside the shapes and the wraps, the stabilisations and the
    # refinements (when the scans' textures refined them) beside the wraps: part
    # of "shapes" and "expressions", not added to them
    assert t["total"] == pytest.approx(sum(v for k, v in t.items() if k not in BESIDE))
    # the shapes written are the corrected ones, and the GLB's targets are they
    glb = read_gltf_morphs(tmp_path / "rig" / "rig.glb")
    smile = read_mesh(tmp_path / "rig" / "shapes" / "smile.obj").vertices
    np.testing.assert_allclose(glb.shapes["smile"], smile * 1e-3, atol=1e-6)


def test_expression_scans_in_a_job_file_are_a_list_of_paths(person, tmp_path):
    job = person_job(person, "out")
    (tmp_path / "rig.toml").write_text(
        "[inputs]\n" + "".join(f'{k} = "{getattr(job, k)}"\n' for k in (
            "template", "scan", "blendshapes", "scan_landmarks", "template_landmarks"))
        + f"expression_scans = {json.dumps(job.expression_scans)}\n"
        + f"expression_landmarks = {json.dumps(job.expression_landmarks)}\n"
        + '[outputs]\noutput = "rig"\n[rig]\n')
    loaded, _ = load_job(tmp_path / "rig.toml")
    assert loaded.expression_scans == job.expression_scans
    assert loaded.expression_landmarks == job.expression_landmarks
    assert loaded.output == str(tmp_path / "rig")
    # one landmark file for two scans is refused before anything runs
    with pytest.raises(InputError, match="1 expression landmark file.* for 2 expression"):
        run_rig_job(replace(loaded, expression_landmarks=loaded.expression_landmarks[:1]))
    assert not (tmp_path / "rig").exists()
    # an expression scan where a shape would be written is never overwritten
    kept = tmp_path / "rig" / "shapes" / "smile.obj"
    kept.parent.mkdir(parents=True)
    kept.write_bytes(Path(job.expression_scans[0]).read_bytes())
    with pytest.raises(InputError, match="is also an input"):
        run_rig_job(replace(loaded,
                            expression_scans=[str(kept)] + job.expression_scans[1:]))
    assert kept.read_bytes() == Path(job.expression_scans[0]).read_bytes()
    assert sorted(p.name for p in (tmp_path / "rig").iterdir()) == ["shapes"]


# the low-resolution sample's detection leaves a jaw point off: warned about, fitted anyway
@pytest.mark.filterwarnings("ignore::facewrap.jobs.wrap_job.InputWarning")
def test_expression_scans_without_landmark_files_are_detected(person, tmp_path):
    pytest.importorskip("dlib", reason="the optional extra facewrap[landmarks] is absent")
    job = replace(person_job(person, tmp_path / "rig"), expression_landmarks=[],
                  expression_scans=person_job(person, "x").expression_scans[:1])
    report = run_rig_job(job)
    (example,) = report["examples"]
    assert example["scan_landmarks_source"] == "detected"
    # the neutral's landmarks come from a file
    assert set(report["detected_landmarks"]) == {"expression scan 1"}
    # the template's 68 unnamed landmarks pair with the detected ones in iBUG order: the
    # rig still improves on the neutral-only one for that scan
    assert example["error"]["mean"] < example["neutral_only_error"]["mean"]


def test_a_textured_rig_bakes_the_neutral_and_builds_each_scan_tree_once(person, tmp_path,
                                                                         monkeypatch):
    """The texture refinement's bake of the neutral is the texture the job writes, and
    every scan's closest-point tree is built once (its reading's), however many steps
    (reading, wrap, bake, refinement, stabilisation) use it."""
    pytest.importorskip("cv2", reason="the optional extra facewrap[flow] is absent")
    import facewrap.geometry.closest as closest
    import facewrap.texture.bake as bake
    import facewrap.texture.tiles as tiles

    bakes, trees = [], {}
    real_bake, real_init = bake.bake_texture, closest.ClosestPointTree.__init__

    def counted_bake(*args, **kwargs):
        bakes.append(kwargs.get("tile"))
        return real_bake(*args, **kwargs)

    def counted_init(self, V, *args, **kwargs):
        key = np.ascontiguousarray(V, dtype=np.float64).tobytes()
        trees[key] = trees.get(key, 0) + 1
        real_init(self, V, *args, **kwargs)

    # every bake goes through bake_texture, by whichever module's name it is called
    monkeypatch.setattr(bake, "bake_texture", counted_bake)
    monkeypatch.setattr(tiles, "bake_texture", counted_bake)
    monkeypatch.setattr(closest.ClosestPointTree, "__init__", counted_init)
    n, scans = person["neutral"], person["scans"]
    job = person_job(person, tmp_path / "rig", texture=str(n["scan_texture"]),
                     expression_textures=[str(s["scan_texture"]) for s in scans],
                     texture_size=32)
    report = run_rig_job(job)
    assert all(e["texture_flow"] is not None for e in report["examples"])
    assert len(bakes) == 1 and (tmp_path / "rig" / "neutral.png").is_file()
    # the bake and the refinements ran beside the wraps: the total does not add them
    t = report["timings"]
    assert 0 < t["texture"] + t["texture_flow"] and t["total"] == pytest.approx(sum(
        v for k, v in t.items() if k not in BESIDE))
    for path in [n["scan"]] + [s["scan"] for s in scans]:
        V = read_mesh(path).vertices
        assert trees[np.ascontiguousarray(V, dtype=np.float64).tobytes()] == 1, path


def test_an_expression_texture_too_small_for_the_refinement_is_named(person, tmp_path):
    from PIL import Image
    from facewrap.errors import InputError
    n, scans = person["neutral"], person["scans"]
    thin = tmp_path / "thin.png"
    Image.new("RGB", (100000, 1), (200, 150, 120)).save(thin)
    textures = [str(s["scan_texture"]) for s in scans]
    textures[0] = str(thin)
    job = person_job(person, tmp_path / "rig", texture=str(n["scan_texture"]),
                     expression_textures=textures, texture_size=32)
    with pytest.raises(InputError) as err:
        run_rig_job(job)
    assert str(thin) in str(err.value) and "too small for the texture refinement" in \
        str(err.value)
    assert not (tmp_path / "rig").exists()
