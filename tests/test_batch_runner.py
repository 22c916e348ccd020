"""Running batches (facewrap.batch.runner, .engines): process pool, Dask, resume after
kill -9, determinism across engines."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from facewrap.batch import done_record_path, read_manifest, run_batch, run_one
from facewrap.batch.engines import run_in_pool
from facewrap.io import read_mesh
from batch_data import batch_command, dask_client, data, manifest, serial  # noqa: F401
from conftest import facewrap

def assert_same_result(path, reference: Path) -> None:
    """The same mesh as the serial run's: topology exactly, positions to 1e-6 (mm).

    Not byte for byte: another process may round the last bit differently (BLAS
    threads, SIMD on differently aligned arrays), and the fit's iterations carry that
    to ~4e-9 on these ~100 mm coordinates (seen with numpy 1.26's OpenBLAS)."""
    got, want = read_mesh(path), read_mesh(reference)
    np.testing.assert_array_equal(got.face_indices, want.face_indices)
    np.testing.assert_allclose(got.vertices, want.vertices, rtol=0, atol=1e-6)


# -- engines and determinism --------------------------------------------------------------------
def test_dask_cluster_runs_batch_with_one_broken_job(data, tmp_path, dask_client, serial):
    out = tmp_path / "dask"
    jobs = read_manifest(manifest(data, out, 7, broken=6), data / "shared.toml")
    result = run_batch(jobs, dask=dask_client, summary=tmp_path / "summary")
    assert [r["status"] for r in result.rows] == ["done"] * 6 + ["failed"]
    assert "missing.txt" in result.rows[6]["error"]
    assert sorted(p.name for p in out.glob("*.obj")) == [f"r{k}.obj" for k in range(6)]
    for name, reference in serial.items():  # the serial run's results
        assert_same_result(out / name, reference)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["counts"] == {"done": 6, "skipped": 0, "failed": 1, "pending": 0}
    lines = (tmp_path / "summary.csv").read_text().splitlines()
    assert len(lines) == 8 and lines[7].split(",")[2] == "failed"
    hosts = {r["host"] for r in result.rows[:6]}
    assert len(hosts) >= 1 and all(h.split(":")[1] != str(os.getpid()) for h in hosts)


def test_process_pool_gives_the_serial_results(data, tmp_path, serial, capsys):
    out = tmp_path / "pool"
    m = manifest(data, out, 7, broken=6)
    rc = facewrap("batch", m, "--job", data / "shared.toml", "--workers", 2)
    assert rc == 1  # one job failed; the others ran
    err = capsys.readouterr().err
    assert "job job6 failed" in err and "missing.txt" in err
    for name, reference in serial.items():
        assert_same_result(out / name, reference)
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


def _die_after_job_0(bj):
    """A job function whose worker dies right after finishing job 0 (its outputs and
    done-record written, its result never sent back): the race a dying neighbour
    leaves when it breaks the pool between a job's end and its report."""
    row = run_one(bj)
    if bj.index == 0 and row["status"] == "done":  # the first time only
        os._exit(9)
    return row


def test_a_job_finished_before_the_pool_broke_counts_as_done(data, tmp_path):
    jobs = read_manifest(manifest(data, tmp_path / "late", 3), data / "shared.toml")
    rows = {}
    run_in_pool(jobs, 2, lambda r: rows.__setitem__(r["index"], r), _die_after_job_0)
    # job 0 ran again alone, found its own done-record and is reported done (the
    # work was done in this run, not before it)
    assert [rows[k]["status"] for k in range(3)] == ["done"] * 3
    assert (tmp_path / "late" / "r0.obj").is_file()


_DEFAULT_SIGINT = ("import os, signal, sys; signal.signal(signal.SIGINT, signal.SIG_DFL); "
                   "signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT}); "
                   "os.execv(sys.argv[1], sys.argv[1:])")


def start_batch(cmd: list, out: Path, done: int) -> subprocess.Popen:
    """Start ``cmd`` (a batch) in a session of its own; return once ``done`` of its
    jobs have their done-records."""
    # as from a terminal: SIGINT at its default and unblocked, whatever this test
    # process inherited or was left with (an ignored or blocked SIGINT is passed on
    # through exec, and Python keeps an inherited SIG_IGN)
    proc = subprocess.Popen([sys.executable, "-c", _DEFAULT_SIGINT, *map(str, cmd)],
                            start_new_session=True, stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE)
    deadline = time.monotonic() + 60
    try:
        while len(list(out.glob("r*.done.json"))) < done:
            assert proc.poll() is None, proc.stderr.read().decode()
            assert time.monotonic() < deadline, "batch too slow to start"
            time.sleep(0.01)
    except BaseException:
        os.killpg(proc.pid, signal.SIGKILL)
        raise
    return proc


@pytest.mark.slow
def test_sigkill_mid_batch_then_resume(data, tmp_path):
    out = tmp_path / "killed"
    n = 12
    m = manifest(data, out, n)
    cmd = batch_command() + [str(m), "--job", str(data / "shared.toml"), "--workers", "2"]
    proc = start_batch(cmd, out, done=3)
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


def _group_alive(pgid: int) -> bool:
    """Whether a process of group ``pgid`` still runs (zombies, dead but not yet
    reaped by the init process, do not count)."""
    proc = Path("/proc")
    if not (proc / "self" / "stat").is_file():  # not Linux: any member counts
        try:
            os.killpg(pgid, 0)
        except ProcessLookupError:
            return False
        return True
    for d in proc.iterdir():
        try:
            fields = (d / "stat").read_text().rsplit(")", 1)[1].split()
        except (OSError, IndexError):
            continue
        if int(fields[2]) == pgid and fields[0] != "Z":
            return True
    return False


@pytest.mark.slow
@pytest.mark.parametrize("engine", ["pool", "dask"])
@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT])
def test_killing_the_batch_alone_ends_its_workers(data, tmp_path, sig, engine):
    """Only the main process is signalled (as a supervisor or `kill PID` would): its
    fork server and workers, or its local Dask cluster, must not go on running the
    queued jobs; the re-run skips what was finished."""
    if engine == "dask":
        pytest.importorskip("distributed")
    # on a loaded machine this test can be descheduled long enough for the whole
    # batch to finish before the signal is sent: then it runs again, with more jobs
    for attempt, n in enumerate((12, 36, 96)):
        out = tmp_path / f"orphans{attempt}"
        m = manifest(data, out, n)
        cmd = batch_command() + [str(m), "--job", str(data / "shared.toml"),
                                 "--workers", "2"]
        proc = start_batch(cmd + (["--dask", "local"] if engine == "dask" else []), out,
                           done=1)
        try:
            os.kill(proc.pid, sig)
            proc.wait(timeout=30)
            gone_by = time.monotonic() + 5
            while _group_alive(proc.pid) and time.monotonic() < gone_by:
                time.sleep(0.05)
            assert not _group_alive(proc.pid), "workers outlived the killed batch"
        finally:
            if _group_alive(proc.pid):
                os.killpg(proc.pid, signal.SIGKILL)
        if not (proc.returncode == 0 and len(list(out.glob("r*.done.json"))) == n):
            break
    if sig == signal.SIGINT:
        err = proc.stderr.read().decode().strip().splitlines()
        assert proc.returncode == 130 and err == ["facewrap: interrupted"], err
    finished = {p.name[:-len(".done.json")] for p in out.glob("r*.done.json")}
    assert len(finished) < n                                 # it did stop early
    time.sleep(0.5)  # nothing is left to finish more jobs behind our back
    assert {p.name[:-len(".done.json")] for p in out.glob("r*.done.json")} == finished
    rerun = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert rerun.returncode == 0, rerun.stderr
    summary = json.loads((out / "manifest.summary.json").read_text())
    status = {Path(j["output"]).name: j["status"] for j in summary["jobs"]}
    assert {f for f, st in status.items() if st == "skipped"} == finished
    for k in range(n):
        assert read_mesh(out / f"r{k}.obj").n_vertices > 0
    assert not list(out.glob(".facewrap-staged-*")) or sig == signal.SIGKILL


def test_ctrl_c_quiets_dask_before_the_interrupt_unwinds():
    """distributed's ``sync`` schedules a cancel on its loop thread as soon as the
    interrupt reaches it, and that cancel can log a traceback from the other thread:
    the loggers must already be quiet when KeyboardInterrupt is raised."""
    import logging
    from facewrap.batch.engines import quiet_dask_on_interrupt
    loggers = [logging.getLogger(n) for n in ("distributed", "tornado")]
    # distributed's logging config gives this one a level of its own (ERROR): it
    # logged the cancelled callback's traceback in a CI run while its parent was quiet
    child = logging.getLogger("tornado.application")
    child_level = child.level
    child.setLevel(logging.ERROR)
    levels = [lg.level for lg in loggers]
    inherited = signal.getsignal(signal.SIGINT)
    # Python's own Ctrl-C handler, as in a terminal: a process started in the
    # background by a shell script inherits SIGINT ignored, and Python then
    # installs none (the context manager is then rightly a no-op)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    before = signal.getsignal(signal.SIGINT)
    seen = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with quiet_dask_on_interrupt():
                try:
                    os.kill(os.getpid(), signal.SIGINT)
                    time.sleep(5)   # the handler interrupts this
                except KeyboardInterrupt:
                    seen = [lg.level for lg in loggers]
                    raise
        assert seen == [logging.CRITICAL, logging.CRITICAL]
        assert child.level == logging.CRITICAL
        assert signal.getsignal(signal.SIGINT) is before        # handler restored
        signal.signal(signal.SIGINT, signal.SIG_IGN)            # ignored: left alone
        with quiet_dask_on_interrupt():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, inherited)
        child.setLevel(child_level)
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)
