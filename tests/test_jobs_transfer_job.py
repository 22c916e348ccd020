"""Transfer jobs (facewrap.jobs.transfer_job): the library call, job files, batches."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from facewrap.batch import read_manifest, run_batch
from facewrap.errors import InputError
from facewrap.io import read_mesh, write_obj
from facewrap.jobs import (TransferJob, TransferJobSettings, job_to_toml, load_job,
                           run_transfer_job)
from facewrap.transfer import DeformationTransfer, find_correspondence
from conftest import facewrap
from transfer_cases import face_scan_markers


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict:
    """A template face and a scan of another topology, two source shapes, markers."""
    tpl, face, vmap, scan, markers = face_scan_markers(24, 32)
    d = tmp_path_factory.mktemp("transfer_job")
    write_obj(d / "src.obj", face)
    write_obj(d / "tgt.obj", scan.mesh)
    (d / "shapes").mkdir()
    for k in ("jaw_open", "smile"):
        write_obj(d / "shapes" / f"{k}.obj", face.with_vertices(tpl.blendshapes[k][vmap]))
    (d / "m.txt").write_text(f"{len(markers[0])}\n" + "".join(
        f"{a} {b}\n" for a, b in zip(*markers)))
    return {"dir": d, "face": face, "scan": scan.mesh, "markers": markers}


def job_in(files, out: Path, **kw) -> TransferJob:
    d = files["dir"]
    return TransferJob(source_neutral=str(d / "src.obj"), target_neutral=str(d / "tgt.obj"),
                       markers=str(d / "m.txt"), source_shapes=[str(d / "shapes")],
                       out=str(out / "shapes"), **kw)


def test_run_transfer_job_writes_shapes_and_a_wrap_like_report(files, tmp_path):
    job = job_in(files, tmp_path, report=str(tmp_path / "r.json"))
    report = run_transfer_job(job)
    for key in ("job", "settings", "timings", "metrics", "warnings"):  # as a wrap's
        assert key in report
    assert report["timings"]["total"] > 0 and report["shapes"] == 2
    assert json.loads((tmp_path / "r.json").read_text()) == json.loads(json.dumps(report))
    out = read_mesh(tmp_path / "shapes" / "smile.obj")
    np.testing.assert_array_equal(out.face_indices, files["scan"].face_indices)
    # the job is the library's deformation transfer, files to files
    corr = find_correspondence(files["face"], files["scan"], files["markers"])
    model = DeformationTransfer(anchor="markers").fit(files["face"], files["scan"], corr)
    smile = read_mesh(files["dir"] / "shapes" / "smile.obj").vertices
    np.testing.assert_allclose(out.vertices, model.transfer(smile[None])[0], atol=1e-5)


def test_output_that_is_an_input_is_refused_before_any_work(files, tmp_path):
    job = job_in(files, tmp_path, report=str(files["dir"] / "m.txt"))
    with pytest.raises(InputError, match="also an input"):
        run_transfer_job(job)
    with pytest.raises(ValueError, match="TransferJobSettings.gltf_scale"):
        TransferJobSettings(gltf_scale=0.0)


def test_job_file_round_trips_and_runs(files, tmp_path, capsys):
    job = job_in(files, tmp_path, correspondence=str(tmp_path / "c.npz"),
                 settings=TransferJobSettings(fix_flips=False, gltf_scale=0.5))
    p = tmp_path / "transfer.toml"
    p.write_text(job_to_toml(job, relative_to=tmp_path))
    assert "[transfer]" in p.read_text() and "[wrap]" not in p.read_text()
    loaded, settings = load_job(p)
    assert loaded == job and settings == job.settings
    assert facewrap("run", p, "--dry-run") == 0
    assert not (tmp_path / "shapes").exists()
    assert facewrap("run", p) == 0
    assert "wrote 2 shapes" in capsys.readouterr().out
    assert (tmp_path / "shapes" / "jaw_open.obj").is_file() and (tmp_path / "c.npz").is_file()


@pytest.mark.parametrize("text, match, line", [
    ("[transfer]\nanchor = -1\n", r"\[transfer\] TransferJobSettings.anchor must be", 2),
    ("[transfer]\nfix_flip = false\n", "unknown key 'fix_flip' in \\[transfer\\]", 2),
    ("[transfer]\n[wrap]\n", "one settings table", 2),
    ("[inputs]\nsource_neutral = 's.obj'\n[transfer]\n",
     "missing 'target_neutral' in \\[inputs\\]", None),
])
def test_bad_transfer_job_files_name_file_line_and_key(tmp_path, text, match, line):
    p = tmp_path / "job.toml"
    p.write_text(text)
    with pytest.raises(InputError, match=match) as err:
        load_job(p)
    assert err.value.path == str(p) and err.value.line == line


def test_a_batch_of_transfers_runs_and_resumes(files, tmp_path):
    d = files["dir"]
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\nsource_neutral = "{d / "src.obj"}"\ntarget_neutral = "{d / "tgt.obj"}"'
        f'\nmarkers = "{d / "m.txt"}"\n[transfer]\nfix_flips = false\n')
    (tmp_path / "m.toml").write_text(
        'job = "shared.toml"\n'
        f'[[jobs]]\nsource_shapes = ["{d / "shapes" / "smile.obj"}"]\nout = "a"\n'
        f'[[jobs]]\nsource_shapes = ["{d / "shapes"}"]\nout = "b"\n'
        '[jobs.transfer]\nambiguity = true\n')
    jobs = read_manifest(tmp_path / "m.toml")
    assert [bj.kind.name for bj in jobs] == ["transfer", "transfer"]
    assert jobs[1].settings == TransferJobSettings(fix_flips=False, ambiguity=True)
    result = run_batch(jobs, workers=1)
    assert result.ok and result.count("done") == 2, result.rows
    assert sorted(p.name for p in (tmp_path / "b").iterdir()) == ["jaw_open.obj",
                                                                  "smile.obj"]
    again = run_batch(read_manifest(tmp_path / "m.toml"), workers=1)
    assert again.count("skipped") == 2
    changed = read_manifest(tmp_path / "m.toml")
    changed[0] = replace(changed[0], settings=TransferJobSettings(fix_flips=True))
    assert [r["status"] for r in run_batch(changed, workers=1).rows] == ["done",
                                                                        "skipped"]


def test_cli_batch_lists_and_runs_transfer_jobs(files, tmp_path, capsys):
    d = files["dir"]
    (tmp_path / "shared.toml").write_text(
        f'[inputs]\nsource_neutral = "{d / "src.obj"}"\ntarget_neutral = "{d / "tgt.obj"}"'
        f'\nmarkers = "{d / "m.txt"}"\n[transfer]\n')
    m = tmp_path / "m.csv"
    m.write_text("out,gltf_scale\nx,0.5\n")
    assert facewrap("batch", m, "--job", tmp_path / "shared.toml") == 2  # no shapes: CSV
    assert "missing 'source_shapes'" in capsys.readouterr().err
    (tmp_path / "m.toml").write_text(
        f'[[jobs]]\nsource_shapes = ["{d / "shapes"}"]\nout = "x"\n'
        '[jobs.transfer]\ngltf_scale = 0.5\n')
    assert facewrap("batch", tmp_path / "m.toml", "--job", tmp_path / "shared.toml",
                    "--dry-run") == 0
    assert f"to run   x: {d / 'shapes'} -> {tmp_path / 'x'}" in capsys.readouterr().out
    assert facewrap("batch", tmp_path / "m.toml", "--job", tmp_path / "shared.toml",
                    "-q", "--workers", 1) == 0
    assert (tmp_path / "x" / "smile.obj").is_file()


def test_a_target_without_faces_is_refused_naming_it(files, tmp_path):
    from facewrap.errors import InputError
    from facewrap.io.ply import write_ply
    from facewrap.mesh import Mesh
    cloud = tmp_path / "cloud.ply"
    write_ply(cloud, Mesh(files["scan"].vertices, np.zeros((0, 3), np.int64)))
    job = job_in(files, tmp_path)
    job.target_neutral = str(cloud)
    with pytest.raises(InputError, match="has no faces") as exc:
        run_transfer_job(job)
    assert str(cloud) in str(exc.value) and not (tmp_path / "shapes").exists()
