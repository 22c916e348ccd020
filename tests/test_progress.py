"""Progress bars (drawn on terminals only) and the CLI's log set-up."""

from __future__ import annotations

import importlib.util
import io
import logging

import pytest

from facewrap.progress import configure_logging, open_bars, progress, progress_enabled


needs_rich = pytest.mark.skipif(importlib.util.find_spec("rich") is None,
                                reason="rich is not installed: bars are not drawn")


class Terminal(io.StringIO):
    """A text stream that says it is a terminal."""

    def isatty(self):
        return True


@pytest.fixture(autouse=True)
def clean(monkeypatch):
    monkeypatch.delenv("FACEWRAP_PROGRESS", raising=False)
    monkeypatch.setenv("TERM", "xterm-256color")
    logger = logging.getLogger("facewrap")
    saved = (logger.handlers[:], logger.level, logger.propagate)
    yield
    configure_logging(0, stream=io.StringIO())
    logger.handlers[:], logger.level, logger.propagate = saved
    assert open_bars() == 0, "a bar was left running"


def test_silent_when_not_a_terminal():
    out = io.StringIO()
    items = list(progress(range(5), "counting", stream=out))
    assert items == [0, 1, 2, 3, 4]
    with progress(3, "steps", stream=out) as bar:
        bar.advance(3)
    assert out.getvalue() == ""
    assert not bar.enabled and bar.completed == 3


@needs_rich
def test_draws_on_a_terminal():
    term = Terminal()
    bar = progress(range(3), "fitting scans", stream=term)
    assert list(bar) == [0, 1, 2]
    text = term.getvalue()
    assert bar.enabled and "fitting scans" in text and "3/3" in text


@needs_rich
def test_total_and_unknown_amounts():
    term = Terminal()
    with progress(10, "icp", stream=term) as bar:
        bar.advance(4)
        bar.update(completed=10, description="icp done")
    with progress(None, "reading", stream=term) as spin:
        spin.advance()
    assert bar.completed == 10 and spin.total is None
    assert "icp done" in term.getvalue() and "reading" in term.getvalue()


@needs_rich
def test_generator_without_len_and_early_break():
    term = Terminal()
    seen = []
    for x in progress((i * i for i in range(100)), "squares", stream=term):
        seen.append(x)
        if x > 10:
            break
    assert seen == [0, 1, 4, 9, 16]
    assert open_bars() == 0  # the bar stopped when the loop broke off


@needs_rich
def test_nested_bars_share_one_display():
    term = Terminal()
    with progress(2, "frames", stream=term) as outer:
        for _ in range(2):
            for _ in progress(range(3), "iterations", stream=term):
                pass
            assert open_bars() == 1  # the inner bar was removed when done
            outer.advance()
    assert open_bars() == 0
    assert "frames" in term.getvalue()


@needs_rich
def test_bar_stops_on_error():
    term = Terminal()
    with pytest.raises(RuntimeError):
        with progress(5, "failing", stream=term) as bar:
            bar.advance()
            raise RuntimeError("boom")
    assert open_bars() == 0


@needs_rich
def test_environment_overrides(monkeypatch):
    monkeypatch.setenv("FACEWRAP_PROGRESS", "0")
    assert not progress_enabled(Terminal())
    monkeypatch.setenv("FACEWRAP_PROGRESS", "1")
    assert progress_enabled(io.StringIO())
    monkeypatch.delenv("FACEWRAP_PROGRESS")
    monkeypatch.setenv("TERM", "dumb")
    assert not progress_enabled(Terminal())


@pytest.mark.parametrize("bad", [-1, 2.5, True, object()])
def test_bad_arguments(bad):
    with pytest.raises(ValueError):
        progress(bad, "x")


def test_iterating_a_count_is_an_error():
    with pytest.raises(TypeError, match="iterable"):
        list(progress(3, "x"))


@pytest.mark.parametrize("verbosity, level", [
    (-3, logging.CRITICAL), (-1, logging.ERROR), (0, logging.WARNING),
    (1, logging.INFO), (2, logging.DEBUG), (5, logging.DEBUG)])
def test_verbosity_levels(verbosity, level):
    logger = configure_logging(verbosity, stream=io.StringIO())
    assert logger.name == "facewrap" and logger.level == level
    assert not logger.propagate


def test_log_lines_plain_off_terminal_and_no_duplicates():
    out = io.StringIO()
    for _ in range(3):  # configuring again replaces the handler
        configure_logging(1, stream=out)
    log = logging.getLogger("facewrap.wrapping.stages")
    log.info("fitting %d vertices", 10)
    log.debug("hidden at -v")
    assert out.getvalue() == "INFO: fitting 10 vertices\n"
    configure_logging(2, stream=out)
    log.debug("shown at -vv")
    assert out.getvalue().rstrip().endswith("DEBUG facewrap.wrapping.stages: shown at -vv")


def test_foreign_handlers_are_kept():
    logger = logging.getLogger("facewrap")
    mine = logging.NullHandler()
    logger.addHandler(mine)
    configure_logging(0, stream=io.StringIO())
    configure_logging(1, stream=io.StringIO())
    ours = [h for h in logger.handlers if getattr(h, "_facewrap", False)]
    assert mine in logger.handlers and len(ours) == 1
    logger.removeHandler(mine)


@needs_rich
def test_quiet_silences_bars_and_terminal_logs_use_rich():
    term = Terminal()
    configure_logging(-1, stream=term)
    assert not progress_enabled(term)
    logging.getLogger("facewrap").warning("not shown at -q")
    assert term.getvalue() == ""
    configure_logging(0, stream=term)
    assert progress_enabled(term)
    from rich.logging import RichHandler
    assert any(isinstance(h, RichHandler) for h in logging.getLogger("facewrap").handlers)
    with progress(2, "working", stream=term) as bar:
        logging.getLogger("facewrap.x").warning("a warning during a bar")
        bar.advance(2)
    text = term.getvalue()
    assert "a warning during a bar" in text and "working" in text


def test_bad_verbosity():
    with pytest.raises(ValueError, match="verbosity"):
        configure_logging("2")


# -- the commands, on a pseudo-terminal and in pipes -------------------------------------------
def _env():
    import os
    env = {k: v for k, v in os.environ.items() if k != "FACEWRAP_PROGRESS"}
    env.update(TERM="xterm-256color", COLUMNS="120",
               PYTHONPATH=os.pathsep.join(filter(None, [str(SRC), env.get("PYTHONPATH")])))
    return env


SRC = __import__("pathlib").Path(__file__).resolve().parents[1] / "src"


def on_terminal(argv) -> tuple[int, str]:
    """Run ``facewrap ARGV`` with its standard streams on a pseudo-terminal;
    (exit status, everything it drew)."""
    import os
    import pty
    import subprocess
    import sys
    master, slave = pty.openpty()
    proc = subprocess.Popen([sys.executable, "-m", "facewrap.cli", *map(str, argv)],
                            stdin=slave, stdout=slave, stderr=slave, env=_env(),
                            close_fds=True)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:  # EIO: the other end is closed
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    return proc.wait(timeout=120), b"".join(chunks).decode("utf-8", "replace")


def in_pipes(argv):
    import subprocess
    import sys
    return subprocess.run([sys.executable, "-m", "facewrap.cli", *map(str, argv)],
                          capture_output=True, text=True, env=_env(), timeout=120)


@pytest.fixture(scope="module")
def sample_files(tmp_path_factory):
    from facewrap.sample import make_scan, make_template, write_sample
    tpl = make_template(24)
    return write_sample(tmp_path_factory.mktemp("sample"), tpl,
                        make_scan(tpl, resolution=40, texture_size=16))


def _wrap_argv(p, out):
    return ["wrap", p["template"], p["scan"], "-o", out, "--template-landmarks",
            p["template_landmarks"], "--scan-landmarks", p["scan_landmarks"]]


@needs_rich
@pytest.mark.slow
def test_wrap_draws_its_stages_and_iterations_on_a_terminal_only(sample_files, tmp_path):
    rc, drawn = on_terminal(_wrap_argv(sample_files, tmp_path / "a.obj"))
    assert rc == 0, drawn
    assert "fitting graph" in drawn and "ICP stage" in drawn and "\x1b[" in drawn
    assert f"wrote {tmp_path / 'a.obj'}" in drawn
    r = in_pipes(_wrap_argv(sample_files, tmp_path / "b.obj"))
    assert r.returncode == 0 and r.stderr == ""
    # the summary and the note on the inferred unit, nothing drawn
    assert [line[:7] for line in r.stdout.splitlines()] == ["wrote /", "units: "]
    assert r.stdout.startswith(f"wrote {tmp_path / 'b.obj'}: ") and "\x1b" not in r.stdout


@needs_rich
@pytest.mark.slow
def test_batch_draws_a_bar_of_jobs_and_prints_the_same_lines_in_pipes(sample_files,
                                                                      tmp_path):
    p = sample_files
    job = tmp_path / "shared.toml"
    job.write_text(f'[inputs]\ntemplate = "{p["template"]}"\ntemplate_landmarks = '
                   f'"{p["template_landmarks"]}"\n[wrap]\nmodel = "rbf"\n')

    def manifest(folder):
        folder.mkdir()
        rows = "".join(f'{p["scan"]},{p["scan_landmarks"]},{folder}/r{k}.obj\n'
                       for k in range(3))
        (folder / "m.csv").write_text("scan,scan_landmarks,output\n" + rows)
        return ["batch", folder / "m.csv", "--job", job, "--workers", "1"]

    rc, drawn = on_terminal(manifest(tmp_path / "tty"))
    import re
    assert rc == 0 and re.search(r"\bbatch \S*\s.*3/3.*100%", drawn), drawn
    r = in_pipes(manifest(tmp_path / "pipe"))
    assert r.returncode == 0 and r.stderr == ""
    lines = r.stdout.splitlines()
    assert [ln.split(" (")[0] for ln in lines[:3]] == [f"[{k}/3] done r{k - 1}.obj"
                                                       for k in (1, 2, 3)]
    assert len(lines) == 4 and lines[3].startswith("3 done, 0 skipped, 0 failed")
