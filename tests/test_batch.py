"""Batches (facewrap.batch): manifests, process pool, Dask, resume after kill -9,
determinism across engines."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from facewrap.batch import done_record_path, read_manifest, run_batch, run_one
from facewrap.batch.engines import run_in_pool
from facewrap.errors import InputError
from facewrap.wrapping.icp.engine import Stage
from facewrap.io import read_mesh
from conftest import facewrap

N_SCANS = 3


def batch_command() -> list[str]:
    """The batch command line as a subprocess."""
    return [sys.executable, "-m", "facewrap.cli", "batch"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """Template, three scans (s0..s2) and a shared job file (RBF model: fast)."""
    from facewrap.sample.face import make_scan, make_template, write_sample
    root = tmp_path_factory.mktemp("batch")
    tpl = make_template(24)
    for i in range(N_SCANS):
        write_sample(root / f"s{i}", tpl, make_scan(tpl, resolution=40, texture_size=16,
                                                   identity_seed=i + 1, seed=i))
    (root / "shared.toml").write_text('[inputs]\ntemplate = "s0/template.obj"\n'
                                      'template_landmarks = "s0/template_landmarks.txt"\n'
                                      '[wrap]\nmodel = "rbf"\n')
    return root


def manifest(data: Path, folder: Path, jobs: int, broken: int | None = None,
             extra: str = "") -> Path:
    """A CSV manifest of ``jobs`` jobs writing into ``folder`` (job ``broken`` has a
    landmark file that does not exist)."""
    folder.mkdir(parents=True, exist_ok=True)
    rows = ["scan,scan_landmarks,output,smoothing,name"]
    for k in range(jobs):
        i = k % N_SCANS
        lm = "missing.txt" if k == broken else "scan_landmarks.txt"
        rows.append(f"{data}/s{i}/scan.obj,{data}/s{i}/{lm},{folder}/r{k}.obj,"
                    f"{0.0 if k < N_SCANS else 0.5},job{k}")
    path = folder / "manifest.csv"
    path.write_text("\n".join(rows) + "\n" + extra)
    return path


@pytest.fixture(scope="module")
def serial(data, tmp_path_factory) -> dict:
    """Reference outputs of six jobs run one after another in this process."""
    out = tmp_path_factory.mktemp("serial")
    jobs = read_manifest(manifest(data, out, 6), data / "shared.toml")
    result = run_batch(jobs, workers=1)
    assert result.ok
    return {f"r{k}.obj": (out / f"r{k}.obj").read_bytes() for k in range(6)}


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=None)
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


# -- manifests -------------------------------------------------------------------------------
def test_csv_manifest_overrides_and_paths(data, tmp_path):
    m = tmp_path / "m.csv"
    m.write_text(f"# a comment\nscan,scan_landmarks,output,wrap.smoothing,project,name\n"
                 f"{data}/s1/scan.obj,{data}/s1/scan_landmarks.txt,out/a.obj,0.25,no,A\n"
                 f"{data}/s2/scan.obj,{data}/s2/scan_landmarks.txt,out/b.ply,,,\n")
    a, b = read_manifest(m, data / "shared.toml")
    assert (a.name, a.settings.smoothing, a.settings.project) == ("A", 0.25, False)
    assert (b.settings.smoothing, b.settings.project, b.settings.model) == (0.0, True,
                                                                           "rbf")
    assert a.job.output == str(tmp_path / "out" / "a.obj")
    assert a.job.template == str(data / "s0" / "template.obj")  # from the job file
    assert b.name == os.path.join("out", "b.ply") and a.line == 3 and b.line == 4


def test_toml_manifest_with_job_key_and_stages(data, tmp_path):
    m = tmp_path / "m.toml"
    m.write_text(f'job = "{data}/shared.toml"\n'
                 f'[[jobs]]\nscan = "{data}/s1/scan.obj"\n'
                 f'scan_landmarks = "{data}/s1/scan_landmarks.txt"\noutput = "a.obj"\n'
                 f'[jobs.wrap]\nmodel = "graph"\n[[jobs.wrap.stages]]\niterations = 2\n'
                 f'[[jobs]]\nname = "second"\nscan = "{data}/s2/scan.obj"\n'
                 f'scan_landmarks = "{data}/s2/scan_landmarks.txt"\noutput = "b.obj"\n')
    a, b = read_manifest(m)
    assert a.settings.model == "graph" and a.settings.stages == [Stage(iterations=2)]
    assert b.settings.model == "rbf" and b.name == "second"


@pytest.mark.parametrize("body, match, line", [
    ("scan,scan_landmarks,output,colour\na.obj,a.txt,o.obj,red\n", "unknown column 'colour'", 1),
    ("scan,scan_landmarks,output,smoothing\na.obj,a.txt,o.obj,lots\n",
     "'smoothing' must be a number", 2),
    ("scan,scan_landmarks,output,stages\na.obj,a.txt,o.obj,3\n", "cannot be set in a CSV", 2),
    ("scan,scan_landmarks,output\na.obj,a.txt\n", "row has 2 cells", 2),
    ("scan,scan_landmarks\na.obj,a.txt\n", "missing 'output'", 2),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.obj\nb.obj,b.txt,o.obj\n",
     "both write", 3),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.obj\no.obj,b.txt,p.obj\n",
     "an input of job 2", 3),
    ("scan,scan_landmarks,output,output\na.obj,a.txt,o.obj,p.obj\n", "appears twice", 1),
    ("scan,scan_landmarks,output\n", "no jobs", None),
    ("\n\n", "empty file", None),
    ("scan,scan_landmarks,output\na.obj,a.txt,o.txt\n", "unknown mesh format", 2),
])
def test_bad_manifests_name_file_and_line(data, tmp_path, body, match, line):
    m = tmp_path / "m.csv"
    m.write_text(body)
    with pytest.raises(InputError, match=match) as err:
        read_manifest(m, data / "shared.toml")
    assert err.value.path == str(m) and err.value.line == line


# -- engines and determinism --------------------------------------------------------------------
def test_dask_cluster_runs_batch_with_one_broken_job(data, tmp_path, dask_client, serial):
    out = tmp_path / "dask"
    jobs = read_manifest(manifest(data, out, 7, broken=6), data / "shared.toml")
    result = run_batch(jobs, dask=dask_client, summary=tmp_path / "summary")
    assert [r["status"] for r in result.rows] == ["done"] * 6 + ["failed"]
    assert "missing.txt" in result.rows[6]["error"]
    assert sorted(p.name for p in out.glob("*.obj")) == [f"r{k}.obj" for k in range(6)]
    for name, reference in serial.items():  # bit-identical to the serial run
        assert (out / name).read_bytes() == reference
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"done": 6, "skipped": 0, "failed": 1, "pending": 0}
    lines = (tmp_path / "summary.csv").read_text().splitlines()
    assert len(lines) == 8 and lines[7].split(",")[2] == "failed"
    hosts = {r["host"] for r in result.rows[:6]}
    assert len(hosts) >= 1 and all(h.split(":")[1] != str(os.getpid()) for h in hosts)


def test_process_pool_is_bit_identical_to_serial(data, tmp_path, serial, capsys):
    out = tmp_path / "pool"
    m = manifest(data, out, 7, broken=6)
    rc = facewrap("batch", m, "--job", data / "shared.toml", "--workers", 2)
    assert rc == 1  # one job failed; the others ran
    err = capsys.readouterr().err
    assert "job job6 failed" in err and "missing.txt" in err
    for name, reference in serial.items():
        assert (out / name).read_bytes() == reference
    summary = json.loads((out / "manifest.summary.json").read_text())
    assert summary["engine"] == "processes"
    assert summary["counts"]["done"] == 6 and summary["counts"]["failed"] == 1


def test_rerun_skips_and_redoes_what_changed(data, tmp_path):
    out = tmp_path / "resume"
    m = manifest(data, out, 3)
    jobs = read_manifest(m, data / "shared.toml")
    assert run_batch(jobs, workers=1).count("done") == 3
    stamp = {k: os.stat(out / f"r{k}.obj").st_mtime_ns for k in range(3)}
    result = run_batch(read_manifest(m, data / "shared.toml"), workers=1)
    assert result.count("skipped") == 3
    assert result.rows[0]["metrics"]["fit_mean"] > 0  # metrics kept from the record
    assert {k: os.stat(out / f"r{k}.obj").st_mtime_ns for k in range(3)} == stamp

    (out / "r0.obj").unlink()                                   # output deleted
    Path(done_record_path(jobs[1].job)).write_text("{not json")  # record corrupted
    (out / ".tmp-abc-r2.obj").write_text("half")                 # litter of a kill
    again = read_manifest(m, data / "shared.toml")
    again[2].settings.smoothing = 0.125                          # settings changed
    result = run_batch(again, workers=1)
    assert [r["status"] for r in result.rows] == ["done"] * 3
    assert not list(out.glob(".tmp-*"))
    st = data / "s1" / "scan.obj"                                # input touched
    os.utime(st, ns=(st.stat().st_atime_ns, st.stat().st_mtime_ns + 10**9))
    result = run_batch(again, workers=1)
    assert [r["status"] for r in result.rows] == ["skipped", "done", "skipped"]


def _die_on_job_2(bj):
    """A job function whose worker dies on job 2 (as when the OOM killer strikes)."""
    if bj.index == 2:
        os._exit(9)
    return run_one(bj)


def test_a_dying_worker_fails_only_its_job(data, tmp_path):
    jobs = read_manifest(manifest(data, tmp_path / "die", 5), data / "shared.toml")
    rows = {}
    run_in_pool(jobs, 2, lambda r: rows.__setitem__(r["index"], r), _die_on_job_2)
    assert rows[2]["status"] == "failed" and "worker process died" in rows[2]["error"]
    assert [rows[k]["status"] for k in (0, 1, 3, 4)] == ["done"] * 4


@pytest.mark.slow
def test_sigkill_mid_batch_then_resume(data, tmp_path):
    out = tmp_path / "killed"
    n = 12
    m = manifest(data, out, n)
    cmd = batch_command() + [str(m), "--job", str(data / "shared.toml"), "--workers", "2"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    try:
        while len(list(out.glob("r*.done.json"))) < 3:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "batch too slow to start"
            time.sleep(0.01)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)  # the batch and its workers, at once
        proc.wait()
    finished = sorted(p.name[:-len(".done.json")] for p in out.glob("r*.done.json"))
    assert 3 <= len(finished) < n
    n_template = read_mesh(data / "s0" / "template.obj").n_vertices
    for p in out.glob("r*.obj"):  # whatever exists is complete
        assert read_mesh(p).n_vertices == n_template
    before = {f: (os.stat(out / f).st_mtime_ns, (out / f"{f}.done.json").read_bytes())
              for f in finished}

    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    summary = json.loads((out / "manifest.summary.json").read_text())
    status = {Path(j["output"]).name: j["status"] for j in summary["jobs"]}
    assert all(status[f] == "skipped" for f in finished)
    assert sum(s == "done" for s in status.values()) == n - len(finished)
    for f, (mtime, record) in before.items():  # not redone
        assert os.stat(out / f).st_mtime_ns == mtime
        assert (out / f"{f}.done.json").read_bytes() == record
    for k in range(n):
        assert read_mesh(out / f"r{k}.obj").n_vertices == n_template
        assert (out / f"r{k}.obj.done.json").is_file()
    assert not list(out.glob(".tmp-*"))


def test_cli_batch_errors_and_dry_run(data, tmp_path, capsys):
    m = manifest(data, tmp_path / "cli", 2)
    assert facewrap("batch", m, "--job", data / "shared.toml", "--dry-run") == 0
    assert capsys.readouterr().out.count("to run") == 2
    bad = tmp_path / "bad.csv"
    bad.write_text("scan,scan_landmarks,output,colour\na,b,c.obj,d\n")
    assert facewrap("batch", bad) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"facewrap: error: {bad}:1:") and "\n" not in err
    assert facewrap("batch", m, "--job", data / "shared.toml", "--workers", 1, "-q",
                    "--summary", tmp_path / "sums") == 0
    assert (tmp_path / "sums" / "manifest.summary.csv").is_file()
