"""Done-records (facewrap.batch.records): what makes a finished job count as finished."""

from __future__ import annotations

import os

from facewrap.batch import done_record_path, fingerprint, read_done_record, record_matches
from facewrap.batch.records import path_stat, remove_stale, write_done_record
from facewrap.jobs import TransferJob, TransferJobSettings, WrapJob
from facewrap.wrapping import WrapSettings


def wrap_job(d) -> WrapJob:
    for name in ("t.obj", "s.obj", "t.txt", "s.txt"):
        (d / name).write_text(name)
    return WrapJob(str(d / "t.obj"), str(d / "s.obj"), scan_landmarks=str(d / "s.txt"),
                   output=str(d / "out" / "a.obj"), template_landmarks=str(d / "t.txt"))


def finish(job, settings, report=None) -> dict:
    """Write the outputs of a job (as a run would) and its done-record."""
    for out in (job.output,) if isinstance(job, WrapJob) else (job.out,):
        os.makedirs(os.path.dirname(out), exist_ok=True)
        if isinstance(job, WrapJob):
            open(out, "w").write("mesh")
        else:
            os.makedirs(out, exist_ok=True)
            open(os.path.join(out, "smile.obj"), "w").write("mesh")
    fp = fingerprint(job, settings)
    write_done_record(job, fp, report or {"metrics": {"fit_mean": 0.5, "x": [1]}}, 1.0)
    return fp


def test_a_record_matches_until_anything_it_depends_on_changes(tmp_path):
    job = wrap_job(tmp_path)
    settings = WrapSettings(model="rbf")
    fp = finish(job, settings)
    rec = read_done_record(job)
    assert rec["metrics"] == {"fit_mean": 0.5} and record_matches(rec, fp)
    assert not record_matches(rec, fingerprint(job, WrapSettings(model="graph")))
    st = os.stat(tmp_path / "s.obj")
    os.utime(tmp_path / "s.obj", ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    assert not record_matches(rec, fingerprint(job, settings))     # input touched
    fp = finish(job, settings)
    open(job.output, "a").write(" edited")
    assert not record_matches(read_done_record(job), fp)           # output changed
    assert not record_matches(None, fp)


def test_folder_outputs_are_recorded_file_by_file(tmp_path):
    for name in ("s.obj", "t.obj", "m.txt", "smile.obj"):
        (tmp_path / name).write_text(name)
    job = TransferJob(str(tmp_path / "s.obj"), str(tmp_path / "t.obj"),
                      str(tmp_path / "m.txt"), [str(tmp_path / "smile.obj")],
                      str(tmp_path / "shapes"))
    fp = finish(job, TransferJobSettings())
    assert done_record_path(job) == str(tmp_path / "shapes.done.json")
    assert record_matches(read_done_record(job), fp)
    open(tmp_path / "shapes" / "frown.obj", "w").write("new")     # a file added
    assert not record_matches(read_done_record(job), fp)
    assert set(path_stat(tmp_path / "shapes")) == {"smile.obj", "frown.obj"}


def test_remove_stale_deletes_the_record_and_temporary_files(tmp_path):
    job = wrap_job(tmp_path)
    finish(job, WrapSettings())
    litter = tmp_path / "out" / ".tmp-123-a.obj"
    litter.write_text("half")
    # staged by a worker stopped before moving it into place (a batch's Ctrl-C)
    staged = tmp_path / "out" / ".facewrap-staged-0a1b2c3d-a.obj"
    staged.write_text("whole, never committed")
    other = tmp_path / "out" / ".facewrap-staged-0a1b2c3d-xa.obj"   # another output's
    other.write_text("kept")
    remove_stale(job)
    assert read_done_record(job) is None and not litter.exists()
    assert not staged.exists() and other.exists()
    assert os.path.exists(job.output)                               # outputs stay
    assert path_stat(tmp_path / "missing") == {"missing": True}
