"""``facewrap batch`` (facewrap.cli.batch): dry run, exit statuses, summary folder."""

from __future__ import annotations

from batch_data import data, manifest  # noqa: F401 - data is a fixture
from conftest import facewrap


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
