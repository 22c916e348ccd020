"""Data shared by the batch tests: a template, three scans, a shared job file, manifests."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from facewrap.batch import read_manifest, run_batch
from facewrap.sample import make_scan, make_template, write_sample

N_SCANS = 3


def batch_command() -> list[str]:
    """The batch command line as a subprocess."""
    return [sys.executable, "-m", "facewrap.cli", "batch"]


@pytest.fixture(scope="module")
def data(tmp_path_factory) -> Path:
    """Template, three scans (s0..s2) and a shared job file (RBF model: fast)."""
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
    """Paths of the outputs of six jobs run one after another in this process."""
    out = tmp_path_factory.mktemp("serial")
    jobs = read_manifest(manifest(data, out, 6), data / "shared.toml")
    result = run_batch(jobs, workers=1)
    assert result.ok
    return {f"r{k}.obj": out / f"r{k}.obj" for k in range(6)}


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


