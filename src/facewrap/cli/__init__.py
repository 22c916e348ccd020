"""The ``facewrap`` command: builds the parser and dispatches to one subcommand.

Each subcommand lives in its own module here (``info``, ``convert``, ``sample``,
``wrap``, ``animate``, ``track``, ``transfer``, ``rig``, ``evaluate``, ``report``,
``run``, ``batch``, ``demo``, ``landmarks``) with ``register(subparsers, summary)`` and a
``cmd_<name>(args)`` that parses and calls the library.  Only the chosen
command's module is imported (the others appear in ``--help`` by their summary
line), so a command pays the start-up of what it uses and nothing else.  Errors in user input
(:class:`~facewrap.errors.InputError`, missing files, values the settings refuse)
print one line ``facewrap: error: <file>:<line>: <problem>`` and exit with status
2; nothing is written in that case.
"""

from __future__ import annotations

import argparse
import atexit
import gc
import logging
import os
import signal
import sys
import warnings
from importlib import import_module

from facewrap.errors import InputError
from facewrap.progress import configure_logging
from facewrap.version import __version__

__all__ = ["main", "build_parser", "COMMANDS"]

#: Every subcommand (module ``facewrap.cli.<name>``) and its line in ``facewrap --help``,
#: in the order listed there.
COMMANDS = {
    "info": "summary of a mesh file",
    "convert": "convert a mesh between OBJ and PLY",
    "sample": "write the built-in synthetic template and scan",
    "wrap": "fit a template onto a scan (template topology kept)",
    "animate": "interpolate two fitted meshes into a sequence",
    "track": "register a sequence of scans (4D), each frame from the last",
    "transfer": "transfer poses/blendshapes onto a mesh of another topology",
    "rig": "a person's rig from their scan: neutral, their own shapes, GLB",
    "evaluate": "distances, landmark / ground-truth errors and triangle quality of a "
                "fitted mesh",
    "report": "HTML page (numbers, pictures, 3D viewer) of a wrap run",
    "run": "run a wrap, transfer or rig described by a TOML job file",
    "batch": "run many wrap, transfer or rig jobs from a manifest (CSV or TOML), resumable",
    "demo": "run the main job on the built-in sample",
    "landmarks": "detect the 68 face landmarks on a scan or template (no user input)",
}


def chosen_command(argv) -> str | None:
    """The subcommand named on a command line (the first word that is not an option)."""
    return next((a for a in argv if not a.startswith("-")), None)


class _OneLineParser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage block), status 2."""

    def error(self, message):
        self.exit(2, f"facewrap: error: {message} (see '{self.prog} --help')\n")


def build_parser(command: str | None = None, *, every: bool = True
                 ) -> argparse.ArgumentParser:
    """The ``facewrap`` argument parser.

    Parameters
    ----------
    command : str, optional
        Load this subcommand's module and its options.
    every : bool
        Load every subcommand (when no ``command`` is given); otherwise the others
        are listed by their summary line only.
    """
    parser = _OneLineParser(   # its subcommands' parsers are of its class too
        prog="facewrap",
        description="Wrap a template head onto face scans, transfer deformations, "
                    "make avatar blendshapes.")
    parser.add_argument("--version", action="version", version=f"facewrap {__version__}")
    parser.add_argument("-v", "--verbose", dest="log_verbose", action="count", default=0,
                        help="more log lines (-v info, -vv debug) on standard error")
    parser.add_argument("--silent", dest="log_quiet", action="count", default=0,
                        help="only errors in the log, no progress bars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name, summary in COMMANDS.items():
        if name == command or (command is None and every):
            import_module(f"facewrap.cli.{name}").register(sub, summary)
        else:
            sub.add_parser(name, help=summary)
    return parser


#: glibc malloc options (mallopt(3), and the environment variables a child process
#: reads at start), each with the values to try in turn: blocks up to 256 MiB come
#: from the heap (glibc's documented ceiling is 32 MiB; 2.36 takes more, and 256
#: saved another 40k page faults), and up to 1 GiB of freed memory stays there for
#: the next array (see :func:`_memory_for_a_command`)
_MALLOC_OPTIONS = {"MALLOC_MMAP_THRESHOLD_": (-3, (256 << 20, 32 << 20)),
                   "MALLOC_TRIM_THRESHOLD_": (-1, (1 << 30,))}


def _memory_for_a_command() -> None:
    """Memory settings for a command's process, unless the user chose otherwise.

    A command makes and drops many arrays of tens of MB, and each page a new one
    touches first is a page fault, cleared by the kernel: a 951k-triangle
    ``facewrap wrap`` on our 2-core CI machine spent 0.6-1.0 s of its 3.6 s in the
    kernel.  Two defaults made that cost (measured there, whole processes,
    in alternating pairs):

    * numpy backs every large array with 2 MiB transparent huge pages
      (``NUMPY_MADVISE_HUGEPAGE``), each cleared (and, under the kernel's default
      ``defrag=madvise``, compacted) in full when first touched: off, kernel time
      0.98 -> 0.59 s, wall ratio 1.07.  It must be set before numpy is first
      imported, which :func:`build_parser` does.
    * glibc gives blocks over 128 KiB-32 MiB their own mappings, returned to the
      system when freed, so the next array faults its pages in again: with the
      options of ``_MALLOC_OPTIONS`` page faults 285k -> 153k, kernel time
      0.6 -> 0.4 s, wall ratio 1.10, peak memory 538 against 532 MiB (the
      freed blocks kept; ``bench_memory``'s 1M-triangle wrap 0.60 -> 0.63 GB).

    Both together against neither: the 951k-triangle wrap 3.45 against 4.17 s,
    the 59k-triangle one 1.46 against 1.71 s (medians of 10 pairs).  Children
    (a batch's workers) inherit both through the environment.
    """
    if "numpy" not in sys.modules:
        os.environ.setdefault("NUMPY_MADVISE_HUGEPAGE", "0")
    if sys.platform != "linux" or any(name in os.environ for name in _MALLOC_OPTIONS):
        return
    try:
        glibc = os.confstr("CS_GNU_LIBC_VERSION")   # None or an error elsewhere (musl)
    except (ValueError, OSError):
        return
    if not glibc:
        return
    import ctypes
    libc = ctypes.CDLL(None)
    for name, (option, values) in _MALLOC_OPTIONS.items():
        taken = next((v for v in values if libc.mallopt(option, v) == 1), None)
        if taken is not None:
            os.environ[name] = str(taken)


def _spare_the_collector() -> None:
    """Keep the cyclic garbage collector off the objects the imports made.

    The imports leave a few hundred thousand long-lived objects (modules, functions,
    classes) that every full collection walks again, and the interpreter's exit
    walks them once more (an ICT ``facewrap wrap`` spent 0.07-0.2 s from the end of
    :func:`main` to its exit; 0.03 s frozen).  Frozen, they are skipped; objects are still freed by reference counting, and
    exit handlers still run.  Only for a process's own command line: a caller
    that runs :func:`main` many times would keep its frozen cycles.
    """
    gc.freeze()
    atexit.register(gc.freeze)      # what the command made is not walked at exit


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP (``kill``, ``timeout``, a scheduler, a closed terminal) as
    an interrupt: what a Ctrl-C undoes (staged outputs, a batch's workers) is
    undone for it too, instead of the process ending where it stands."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _end_like_an_interrupt() -> None:
    """SIGTERM and SIGHUP raise :class:`Terminated` in the main thread.

    Left at their default, they end the process at once: a run's staged outputs
    (hidden ``.facewrap-staged-*`` files) stay behind in the output folder.  A
    signal the process was started ignoring (``nohup``) stays ignored.
    """
    def terminated(signum, frame):
        raise Terminated(signum)

    for name in ("SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        if sig is not None and signal.getsignal(sig) is signal.SIG_DFL:
            signal.signal(sig, terminated)


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Python warnings on the command line, never a two-line ``file:line: Warning``.

    A facewrap warning (``UserWarning`` and its kin, ``InputWarning`` among them)
    is one ``facewrap: warning:`` line; a numerical one from inside a library
    (``RuntimeWarning: overflow encountered in multiply``) says nothing a user can
    act on, and would turn a one-line error into twenty lines: it goes to the
    debug log (``-vv``).
    """
    text = " ".join(str(message).split())
    if issubclass(category, UserWarning):
        print(f"facewrap: warning: {text}", file=sys.stderr)
    else:
        logging.getLogger("facewrap").debug("%s: %s (%s:%s)", category.__name__, text,
                                            filename, lineno)


def main(argv=None) -> int:
    """Entry point of the ``facewrap`` console script; returns the exit status."""
    entry = argv is None        # the process's own command line: it ends after this
    argv = sys.argv[1:] if argv is None else list(argv)
    if entry:
        _memory_for_a_command()
    parser = build_parser(chosen_command(argv), every=False)
    args = parser.parse_args(argv)
    if entry:
        _spare_the_collector()
        _end_like_an_interrupt()
    # progress bars draw only on a terminal; logs go to standard error
    configure_logging(args.log_verbose - args.log_quiet
                      - (1 if getattr(args, "quiet", False) else 0))
    with warnings.catch_warnings():   # restores the caller's warning display after
        warnings.showwarning = _one_line_warning
        status = _run(args)
    if entry and status:
        # a failure can leave a cycle (a future's exception, its traceback's frames)
        # holding a library's objects: freed now, or nanobind lists them as leaked
        # on standard error at exit (gc.freeze would keep them from any collection)
        gc.collect()
    return status


def _run(args) -> int:
    """The chosen command, its failures on bad input as one line and exit status 2."""
    try:
        return int(args.func(args) or 0)
    except InputError as exc:
        print(f"facewrap: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except FileNotFoundError as exc:
        print(f"facewrap: error: {exc.filename}: no such file", file=sys.stderr)
        return 2
    except BrokenPipeError:   # `facewrap info x.obj | head`: the reader left, quietly
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())   # nor a complaint when Python flushes
        return 141                              # the shell's status for SIGPIPE
    except OSError as exc:  # a write that fails mid-run (disk full...): nothing is left
        from facewrap.io.paths import shown_path   # staged names taken off
        where = f"{shown_path(exc.filename)}: " if exc.filename else ""
        print(f"facewrap: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except Terminated as exc:   # kill, timeout: one line, the shell's status for it
        print(f"facewrap: terminated ({signal.Signals(exc.signum).name})", file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:  # Ctrl-C: one line, the shell's status for SIGINT
        print("facewrap: interrupted", file=sys.stderr)
        return 130
    except ValueError as exc:  # inconsistent inputs found past the readers
        print(f"facewrap: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except MemoryError:
        print("facewrap: error: out of memory (the inputs need more than this machine "
              "has)", file=sys.stderr)
        return 2
    except RecursionError:
        print("facewrap: error: an input is nested too deeply to read", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 -- the last net: never a traceback
        # Whatever got past the checks at the door came from an input no check
        # foresaw: one line naming the failure, the traceback in the debug log.
        logging.getLogger("facewrap").debug("traceback", exc_info=True)
        print(f"facewrap: error: {type(exc).__name__}: {_one_line(exc)} (an input no "
              "check foresaw; -vv shows where)", file=sys.stderr)
        return 2


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line: a line break (in a library's message, or
    in a file name) is written as ``\\n``."""
    text = str(exc).strip().replace("\r", "\\r").replace("\n", "\\n")
    return text or type(exc).__name__


if __name__ == "__main__":
    sys.exit(main())
