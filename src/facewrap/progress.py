"""Progress bars for long steps, and the log set-up of the command line.

:func:`progress` wraps an iterable (or a known amount of work) in a bar drawn with
`rich <https://rich.readthedocs.io>`_ on standard error, only when that is a
terminal: in pipes, files and CI logs it draws nothing and costs next to nothing,
so library code can use it freely.  Bars opened inside another bar's block share
its display (one live display at a time); inner bars vanish when done, an
outermost one leaves its final line.

:func:`configure_logging` sets the level of the ``facewrap`` logger from the
CLI's ``-v``/``-q`` count and gives it one handler on standard error (rich's
when that is a terminal, plain lines otherwise); ``-q`` also silences the bars.

Environment: ``FACEWRAP_PROGRESS=0`` hides bars, ``=1`` draws them even when
standard error is not a terminal; ``TERM=dumb`` hides them.

Examples
--------
>>> total = 0
>>> for x in progress(range(4), "adding"):   # silent here: not a terminal
...     total += x
>>> total
6
>>> with progress(3, "steps") as bar:
...     for _ in range(3):
...         bar.advance()
>>> bar.completed
3
"""

from __future__ import annotations

import importlib.util
import logging
import os
import sys
from typing import Iterable, Iterator

__all__ = ["progress", "Progress", "progress_enabled", "open_bars", "configure_logging",
           "LOGGER_NAME"]

LOGGER_NAME = "facewrap"
"""Name of the package's logger (modules log to ``facewrap.<module>``)."""

_quiet = False          # set by configure_logging(verbosity < 0)
_live = None            # the rich.progress.Progress shared by nested bars
_depth = 0              # bars open on _live
_console = None         # rich Console of the log handler, shared with the bars


def open_bars() -> int:
    """Number of progress bars drawing now (nested bars share one display; 0: none).

    >>> open_bars()
    0
    """
    return _depth


def _console_for(stream):
    """The rich Console drawing on ``stream``: the log handler's when it is the same
    stream (so log lines print above a live bar instead of through it)."""
    global _console
    if _console is None or _console.file is not stream:
        from rich.console import Console  # rich is optional: only bars need it
        _console = Console(file=stream, force_terminal=True)
    return _console


def progress_enabled(stream=None) -> bool:
    """Whether bars are drawn on ``stream`` (default ``sys.stderr``) now.

    True when ``stream`` is a terminal, rich is installed, logging is not quiet and
    neither ``FACEWRAP_PROGRESS=0`` nor ``TERM=dumb`` is set; ``FACEWRAP_PROGRESS=1``
    forces bars on any stream.
    """
    stream = sys.stderr if stream is None else stream
    forced = os.environ.get("FACEWRAP_PROGRESS", "").strip()
    if forced == "0" or stream is None:
        return False
    if importlib.util.find_spec("rich") is None:
        return False
    if forced == "1":
        return True
    if _quiet or os.environ.get("TERM") == "dumb":
        return False
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:  # closed stream
        return False


class Progress:
    """One progress bar: iterate it, or use it as a context and call :meth:`advance`.

    Use :func:`progress` to make one.

    Attributes
    ----------
    description : str
    total : int or None
        None for an unknown amount (a spinner with the elapsed time).
    completed : int
        Work done so far (counted whether or not a bar is drawn).
    enabled : bool
        Whether a bar is drawn.
    """

    def __init__(self, iterable_or_total, description: str = "", *, stream=None):
        if iterable_or_total is None or isinstance(iterable_or_total, int):
            if isinstance(iterable_or_total, bool) or (
                    iterable_or_total is not None and iterable_or_total < 0):
                raise ValueError(f"total must be a non-negative int or None, got "
                                 f"{iterable_or_total!r}")
            self._iterable, self.total = None, iterable_or_total
        else:
            if not isinstance(iterable_or_total, Iterable):
                raise ValueError("progress() takes an iterable, an int total or None, "
                                 f"not {type(iterable_or_total).__name__}")
            self._iterable = iterable_or_total
            try:
                self.total = len(iterable_or_total)
            except TypeError:
                self.total = None
        self.description = str(description)
        self.completed = 0
        self._stream = sys.stderr if stream is None else stream
        self.enabled = False
        self._task = None
        self._owner = False

    # -- display ------------------------------------------------------------
    def _start(self):
        global _live, _depth
        if self._task is not None or not progress_enabled(self._stream):
            return
        if _live is None:  # rich is optional: imported when a bar is first drawn
            from rich.progress import (BarColumn, MofNCompleteColumn, SpinnerColumn,
                                       TaskProgressColumn, TextColumn, TimeElapsedColumn,
                                       TimeRemainingColumn)
            from rich.progress import Progress as RichProgress
            console = _console_for(self._stream)
            # lines printed on standard output while a bar draws go above the bar
            # when that is the same screen; into a pipe or file they go unchanged
            _live = RichProgress(SpinnerColumn(), TextColumn("{task.description}"),
                                 BarColumn(), MofNCompleteColumn(), TaskProgressColumn(),
                                 TimeElapsedColumn(), TimeRemainingColumn(),
                                 console=console, transient=False,
                                 redirect_stdout=_isatty(sys.stdout),
                                 redirect_stderr=self._stream is sys.stderr)
            _live.start()
            self._owner = True
        self._task = _live.add_task(self.description, total=self.total,
                                    completed=self.completed)
        _depth += 1
        self.enabled = True

    def _stop(self):
        global _live, _depth
        if self._task is None:
            return
        if self._owner:
            _live.stop()
            _live = None
            _depth = 0
        else:
            _live.remove_task(self._task)
            _depth -= 1
        self._task = None

    # -- use ----------------------------------------------------------------
    def advance(self, n: int = 1) -> None:
        """Count ``n`` more units of work done."""
        self.completed += n
        if self._task is not None:
            _live.advance(self._task, n)

    def update(self, *, completed: int | None = None, total: int | None = None,
               description: str | None = None) -> None:
        """Set the work done, the total or the text."""
        if completed is not None:
            self.completed = completed
        if total is not None:
            self.total = total
        if description is not None:
            self.description = str(description)
        if self._task is not None:
            _live.update(self._task, completed=self.completed, total=self.total,
                         description=self.description)

    def __enter__(self) -> "Progress":
        self._start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop()

    def __iter__(self) -> Iterator:
        if self._iterable is None:
            raise TypeError("this progress bar counts a total; iterate over "
                            "progress(iterable, ...) instead")
        started_here = self._task is None
        self._start()
        try:
            for item in self._iterable:
                yield item
                self.advance()
        finally:
            if started_here:
                self._stop()


def progress(iterable_or_total=None, description: str = "", *, stream=None) -> Progress:
    """A progress bar over an iterable or a count, drawn only on a terminal.

    Parameters
    ----------
    iterable_or_total : iterable, int or None
        What to iterate over (its ``len`` is the total when it has one), or the
        number of units of work, or None for an unknown amount (spinner).
    description : str
        Text in front of the bar.
    stream : file, optional
        Where to draw (default ``sys.stderr`` at the time of the call).

    Returns
    -------
    Progress
        Iterate it (``for x in progress(xs, "fitting")``), or use it in a ``with``
        block and call ``advance()``.

    Raises
    ------
    ValueError
        If ``iterable_or_total`` is a negative int or not iterable.
    """
    return Progress(iterable_or_total, description, stream=stream)


def configure_logging(verbosity: int = 0, *, stream=None) -> logging.Logger:
    """Set up the ``facewrap`` logger for the command line.

    Parameters
    ----------
    verbosity : int
        ``-v`` count minus ``-q`` count: ≤ -2 CRITICAL, -1 ERROR (and no progress
        bars), 0 WARNING, 1 INFO, ≥ 2 DEBUG (with logger names and times).
    stream : file, optional
        Where log lines go (default ``sys.stderr``).

    Returns
    -------
    logging.Logger
        The ``facewrap`` logger.  Calling again replaces the handler installed
        before (no duplicate lines); other handlers and the root logger are left
        alone, and records do not propagate to the root.

    Examples
    --------
    >>> import io
    >>> out = io.StringIO()
    >>> log = configure_logging(1, stream=out)
    >>> logging.getLogger("facewrap.wrapping.stages").info("fitting %d vertices", 7434)
    >>> out.getvalue()
    'INFO: fitting 7434 vertices\\n'
    >>> _ = configure_logging(0)
    """
    global _quiet
    if isinstance(verbosity, bool) or not isinstance(verbosity, int):
        raise ValueError(f"verbosity must be an int, got {verbosity!r}")
    level = {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO}.get(
        verbosity, logging.DEBUG if verbosity > 1 else logging.CRITICAL)
    _quiet = verbosity < 0
    stream = sys.stderr if stream is None else stream
    logger = logging.getLogger(LOGGER_NAME)
    for h in [h for h in logger.handlers if getattr(h, "_facewrap", False)]:
        logger.removeHandler(h)
        h.close()
    handler = None
    if _isatty(stream) and os.environ.get("TERM") != "dumb":
        try:  # rich is optional: plain log lines without it
            from rich.logging import RichHandler
        except ImportError:
            pass
        else:
            handler = RichHandler(console=_console_for(stream), show_time=verbosity > 1,
                                  show_path=False, markup=False, rich_tracebacks=False)
            handler.setFormatter(logging.Formatter(
                "%(name)s: %(message)s" if verbosity > 1 else "%(message)s"))
    if handler is None:
        handler = logging.StreamHandler(stream)
        handler.setFormatter(logging.Formatter(
            "%(asctime)s %(levelname)s %(name)s: %(message)s" if verbosity > 1
            else "%(levelname)s: %(message)s"))
    handler._facewrap = True
    logger.addHandler(handler)
    logger.setLevel(level)
    logger.propagate = False
    return logger


def _isatty(stream) -> bool:
    try:
        return bool(getattr(stream, "isatty", None) and stream.isatty())
    except ValueError:
        return False
