"""Where outputs may go: apart from every input, writable, and complete or absent.

Every command that writes checks its outputs here before any work starts:

- :func:`check_outputs_apart`: no output (a file, a folder, or a file written inside
  an output folder), after resolving ``..`` and symbolic links, is an input or lies
  inside an input folder, and no two outputs are the same file;
- :func:`check_writable`: every output can be created where it is asked for (no
  path through a file, no folder in the way of a file or the reverse, a folder that
  can be written);
- :func:`check_output_paths`: both, in that order.

:func:`staged_outputs` then writes the outputs of one run under hidden names beside
their destinations and moves them all into place only when the run succeeded; a run
that fails removes what it staged and the folders it made, so no partial outputs are
left.  Staging (rather than writing in place and removing on failure) also keeps an
earlier run's outputs intact when a re-run fails.
"""

from __future__ import annotations

import contextlib
import errno
import os
import re
import secrets
import shutil
import signal
import stat
import threading
from pathlib import Path

from facewrap.errors import InputError

__all__ = ["real_path", "side_files", "find_overlap", "check_outputs_apart", "check_writable",
           "check_output_paths", "special_kind", "shown_path", "hidden_name",
           "new_folders_removed_on_failure", "StagedOutputs", "staged_outputs"]

#: Prefix of staged files and folders (hidden, so a listing does not show them).
STAGE_PREFIX = ".facewrap-staged-"


def real_path(path) -> str:
    """``path`` absolute, with ``..`` and symbolic links resolved (str)."""
    return os.path.realpath(os.path.abspath(os.fspath(path)))


#: How much of an OBJ is searched for ``mtllib`` (exporters write it at the top;
#: a bounded read keeps the check cheap for scans of hundreds of megabytes).
OBJ_HEAD_BYTES = 1 << 16

_MTLLIB = re.compile(rb"^[ \t]*mtllib[ \t]+([^\r\n]+)", re.M)
_MAP = re.compile(r"^[ \t]*(?:map_\w+|bump|disp|decal|refl)[ \t]+(.+?)[ \t]*$", re.M)


def _head(path, size: int) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(size)
    except OSError:
        return b""


def side_files(path) -> list[str]:
    """Files an input mesh reads along with it: its MTL files and their images.

    An OBJ's ``mtllib`` statements (searched in its first :data:`OBJ_HEAD_BYTES`)
    name material files beside it, whose ``map_Kd``... statements name texture
    images; writing over those would damage the input as surely as writing over
    the OBJ.  Other files (and unreadable ones) have none.

    Parameters
    ----------
    path : path

    Returns
    -------
    list of str
        Paths relative to the OBJ's folder, joined to it.
    """
    if not os.fspath(path).lower().endswith(".obj") or not os.path.isfile(path):
        return []
    folder = os.path.dirname(os.fspath(path))
    out = []
    for m in _MTLLIB.finditer(_head(path, OBJ_HEAD_BYTES)):
        for name in m.group(1).decode("utf-8", "replace").split():
            mtl = os.path.join(folder, name)
            out.append(mtl)
            text = _head(mtl, 1 << 20).decode("utf-8", "replace")
            # the image is the last word: options such as -s 1 1 1 come first
            out += [os.path.join(folder, os.path.dirname(name), m2.group(1).split()[-1])
                    for m2 in _MAP.finditer(text)]
    return out


def _within(path: str, folder: str) -> bool:
    """``path`` is ``folder`` or lies inside it (both real paths)."""
    return path == folder or path.startswith(folder.rstrip(os.sep) + os.sep)


def find_overlap(outputs, inputs):
    """The first output that is an input or lies inside an input folder.

    Parameters
    ----------
    outputs, inputs : iterable of path
        Files or folders; inputs that are existing folders cover everything inside,
        an input OBJ covers its :func:`side_files` too.

    Returns
    -------
    (output, relation) or None
        The output as given and how it meets the input, in words naming the
        input: ``"is also an input 'a.obj'"``, ``"lies in the input folder
        'shapes'"`` (a side file is named with the mesh it is read with).

    Examples
    --------
    >>> import tempfile, os
    >>> d = tempfile.mkdtemp()
    >>> find_overlap([os.path.join(d, "x", "..", "a.obj")], [os.path.join(d, "a.obj")])[1][:16]
    'is also an input'
    >>> find_overlap([os.path.join(d, "out.obj")], [os.path.join(d, "a.obj")]) is None
    True
    """
    named = [os.fspath(i) for i in inputs]
    # (input, what to call it): a side file is named with the mesh it belongs to
    ins = [(i, repr(i)) for i in named]
    ins += [(f, f"{f!r} (read with {i!r})") for i in named for f in side_files(i)]
    ins = [(i, label, real_path(i), _file_id(i)) for i, label in ins]
    for o in outputs:
        ro, oid = real_path(o), _file_id(o)
        for i, label, ri, iid in ins:
            # a hard link (or another spelling on a case-insensitive disk) is the
            # same file under another name: same device and inode
            same = ro == ri or (oid is not None and oid == iid)
            if same or (os.path.isdir(ri) and _within(ro, ri)):
                where = "is also an input" if same else "lies in the input folder"
                return o, f"{where} {label}"
    return None


def _file_id(path) -> tuple[int, int] | None:
    """(device, inode) of an existing regular file (links followed), else None."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):       # missing, unreadable, a NUL in the name
        return None
    return (st.st_dev, st.st_ino) if stat.S_ISREG(st.st_mode) else None


def check_outputs_apart(outputs, inputs, source=None) -> None:
    """No output is or lies on an input, and no two outputs are the same file.

    Parameters
    ----------
    outputs : iterable of path
        Files and folders that will be written, including the files written inside
        an output folder when their names are known.
    inputs : iterable of path
        Files and folders that are read.
    source : path, optional
        Named in errors (job file, manifest); default the offending output.

    Raises
    ------
    InputError
        One line naming both paths.
    """
    outputs = list(outputs)
    hit = find_overlap(outputs, inputs)
    if hit is not None:
        o, label = hit
        raise InputError(f"output {os.fspath(o)!r} {label}; inputs are never overwritten",
                         source or o)
    seen = set()
    for o in outputs:
        ro = real_path(o)
        if ro in seen:
            raise InputError(f"two outputs of one job are the same file {os.fspath(o)!r}",
                             source or o)
        seen.add(ro)


def _nearest_existing(path: str) -> str:
    """``path`` or its nearest ancestor that exists (as a file or a folder)."""
    while not os.path.lexists(path):
        parent = os.path.dirname(path)
        if parent == path:
            break
        path = parent
    return path


# one or more hidden prefixes: a staged file's own temporary is ".tmp-…-.facewrap-staged-…-f"
_STAGED = re.compile(r"^(?:(?:\.facewrap-staged-|\.tmp-)[0-9a-f]{8}-)+(.+)$")


def shown_path(path) -> str:
    """``path`` as the user named it: staged and temporary names taken off.

    Outputs are written under hidden names (:class:`StagedOutputs`,
    :func:`~facewrap.io.atomic.atomic_write`); an error while writing names the
    output the user asked for.

    Examples
    --------
    >>> shown_path("out/.facewrap-staged-0a1b2c3d-seq/.tmp-89abcdef-f.obj")
    'out/seq/f.obj'
    >>> shown_path("/sys/.tmp-36fc7c14-.facewrap-staged-5bdf278c-fit.obj")
    '/sys/fit.obj'
    """
    parts = os.fspath(path).split(os.sep)
    return os.sep.join(m.group(1) if (m := _STAGED.match(p)) else p for p in parts)


def _name_max(folder) -> int:
    """Longest file name (in bytes) the file system of ``folder`` takes."""
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (OSError, ValueError, AttributeError):   # missing folder, not POSIX
        return 255


def hidden_name(prefix: str, name: str, folder) -> str:
    """``prefix + name``: the hidden name an output ``name`` is written under in
    ``folder`` first, ``name``'s stem cut short when the whole would be longer than
    the file system takes.

    A name the user may give (up to 255 bytes) would otherwise become one the file
    system refuses ("File name too long") once the staging and temporary prefixes
    (40 characters together) are put before it, after all the work was done.  The
    extension is kept: writers choose the format by it.

    Examples
    --------
    >>> hidden_name(".tmp-0a1b2c3d-", "fit.obj", "/")
    '.tmp-0a1b2c3d-fit.obj'
    >>> n = hidden_name(".tmp-0a1b2c3d-", "x" * 250 + ".obj", "/")
    >>> len(n), n[-6:]
    (255, 'xx.obj')
    """
    limit = _name_max(folder)
    stem, ext = os.path.splitext(name)
    excess = len(os.fsencode(prefix + name)) - limit
    while excess > 0 and stem:   # by characters: a multi-byte one is never split
        excess -= len(os.fsencode(stem[-1]))
        stem = stem[:-1]
    return prefix + stem + ext


def special_kind(path) -> str | None:
    """What ``path`` is when it exists but is neither a regular file nor a folder.

    Returns
    -------
    str or None
        ``"a fifo"``, ``"a character device"``, ``"a block device"``, ``"a socket"``
        or ``"a symlink loop"``; None for a file, a folder or a missing path.

    Examples
    --------
    >>> special_kind("/dev/null"), special_kind("/"), special_kind("/no/such")
    ('a character device', None, None)
    """
    try:
        mode = os.stat(path).st_mode
    except OSError as exc:
        return "a symlink loop" if exc.errno == errno.ELOOP else None
    for test, kind in ((stat.S_ISFIFO, "a fifo"), (stat.S_ISCHR, "a character device"),
                       (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")):
        if test(mode):
            return kind
    return None


def check_writable(files=(), folders=(), source=None) -> None:
    """Every output can be created: its folder exists or can be made, and is writable.

    Parameters
    ----------
    files : iterable of path
        Output files (replaced when they exist).
    folders : iterable of path
        Output folders (created when missing; files are written inside).
    source : path, optional
        Named in errors; default the output.

    Raises
    ------
    InputError
        One line naming the output and what is in its way: a file where a folder is
        needed (the path runs through a file), a folder where a file is needed, a
        folder that cannot be written, or a backslash (a Windows path) where ``/``
        separates folders.
    """
    asked = [(d, True) for d in folders] + [(f, False) for f in files]
    for path, is_folder in asked:
        if not os.fspath(path):   # "" would be the current folder: never what was meant
            raise InputError(f"the output {'folder' if is_folder else 'file'} name is "
                             "empty", source or "''")
        if os.sep == "/" and "\\" in os.fspath(path):
            # a job file or manifest written on Windows ("out\\fit.obj"): here a
            # backslash is part of a name, and one oddly named file was written
            raise InputError(f"output '{os.fspath(path)}' holds a backslash, which is no "
                             "folder separator here (a Windows path?); use '/'",
                             source or path)
        p = os.path.abspath(os.fspath(path))
        kind = special_kind(p)
        if kind:   # replacing a device or a fifo with a file is never what was meant
            raise InputError(f"output {os.fspath(path)!r} is {kind}, not a "
                             f"{'folder' if is_folder else 'file'}", source or path)
        if not is_folder and os.fspath(path).endswith((os.sep, "/")):
            # "out/r/" names a folder: writing a file called "r" is never what was meant
            raise InputError(f"output file {os.fspath(path)!r} ends in '/', which names a "
                             "folder; give a file name", source or path)
        if os.path.isdir(p) and not is_folder:
            raise InputError(f"output {os.fspath(path)!r} is a folder, not a file",
                             source or path)
        if os.path.isfile(p) and is_folder:
            raise InputError(f"output folder {os.fspath(path)!r} is a file",
                             source or path)
        home = p if is_folder and os.path.isdir(p) else os.path.dirname(p)
        existing = _nearest_existing(home)
        if not os.path.isdir(existing):
            raise InputError(f"cannot create output {os.fspath(path)!r}: {existing!r} is "
                             "a file, not a folder", source or path)
        _check_name_lengths(path, p, existing, source)
        if not os.access(existing, os.W_OK | os.X_OK):
            raise InputError(f"cannot create output {os.fspath(path)!r}: folder "
                             f"{existing!r} is not writable", source or path)


def _check_name_lengths(path, p: str, existing: str, source) -> None:
    """Each name ``p`` still has to create (below ``existing``) fits the file system
    (refused after the work by ``open`` otherwise)."""
    limit = _name_max(existing)
    for name in Path(os.path.relpath(p, existing)).parts:
        if len(os.fsencode(name)) > limit:
            raise InputError(f"cannot create output {os.fspath(path)!r}: the name "
                             f"{name[:20]!r}... is {len(os.fsencode(name))} bytes long, "
                             f"more than the {limit} the file system takes",
                             source or path)


def check_output_paths(files=(), folders=(), inputs=(), source=None) -> None:
    """:func:`check_outputs_apart` then :func:`check_writable`, before any work.

    Parameters
    ----------
    files, folders : iterable of path
        Output files (including those written inside output folders) and folders.
    inputs : iterable of path
        Input files and folders.
    source : path, optional
        Named in errors.
    """
    files, folders = list(files), list(folders)
    check_outputs_apart(files + folders, inputs, source)
    check_writable(files, folders, source)


def _move_into(staged: Path, final: Path) -> None:
    """Move every entry of folder ``staged`` into folder ``final`` (merging
    sub-folders, replacing files), then remove ``staged``."""
    final.mkdir(exist_ok=True)
    for entry in sorted(staged.iterdir()):
        target = final / entry.name
        if entry.is_dir() and target.is_dir():
            _move_into(entry, target)
        else:
            os.replace(entry, target)
    staged.rmdir()


@contextlib.contextmanager
def _signals_held():
    """Ctrl-C, SIGTERM or SIGHUP arriving in the block takes effect when it ends.

    For the moves of a commit: interrupted between two of them, a run would leave
    some of its outputs in place and none of the others.  Only signals with a Python
    handler can wait (an interrupt's, or the command's for SIGTERM); only the main
    thread may set handlers.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    held, previous = [], {}
    for name in ("SIGINT", "SIGTERM", "SIGHUP"):
        sig = getattr(signal, name, None)
        handler = None if sig is None else signal.getsignal(sig)
        if callable(handler):
            previous[sig] = handler
            signal.signal(sig, lambda signum, frame: held.append((signum, frame)))
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
        if held:
            signum, frame = held[0]
            previous[signum](signum, frame)


class StagedOutputs:
    """Outputs of one run written under hidden names, moved into place together.

    :meth:`file` gives the name to write a file under, :meth:`folder` a hidden
    folder beside the destination to write a folder's files into; :meth:`commit`
    moves everything into place (a file replaces its destination, a folder's files
    are moved into the destination folder), :meth:`discard` removes what was staged
    and the folders made for it.  Use it through :func:`staged_outputs`.
    """

    def __init__(self):
        self._files: list[tuple[Path, Path]] = []
        self._folders: list[tuple[Path, Path]] = []
        self._made: list[Path] = []

    def _make_folder(self, folder: Path) -> None:
        missing = []
        while not folder.exists():
            missing.append(folder)
            folder = folder.parent
        for f in reversed(missing):
            try:
                f.mkdir()
            except FileExistsError:   # made meanwhile by another job of a batch
                continue
            self._made.append(f)

    def _hidden(self, final: Path) -> Path:
        return final.parent / hidden_name(f"{STAGE_PREFIX}{secrets.token_hex(4)}-",
                                          final.name, final.parent)

    def file(self, final) -> Path:
        """Where to write the output file ``final`` (same folder and extension)."""
        final = Path(os.path.abspath(os.fspath(final)))
        self._make_folder(final.parent)
        staged = self._hidden(final)
        self._files.append((staged, final))
        return staged

    def folder(self, final) -> Path:
        """A new empty folder whose files are moved into the folder ``final``."""
        final = Path(os.path.abspath(os.fspath(final)))
        self._make_folder(final.parent)
        staged = self._hidden(final)
        staged.mkdir()
        self._folders.append((staged, final))
        return staged

    def commit(self) -> None:
        """Move every staged output into place (an interrupt waits for the last move)."""
        with _signals_held():
            for staged, final in self._folders:
                _move_into(staged, final)
            for staged, final in self._files:
                if staged.exists():
                    os.replace(staged, final)
            self._files, self._folders, self._made = [], [], []

    def discard(self) -> None:
        """Remove what was staged and the folders made for it."""
        for staged, _ in self._files:
            with contextlib.suppress(OSError):
                staged.unlink()
        for staged, _ in self._folders:
            shutil.rmtree(staged, ignore_errors=True)
        for folder in reversed(self._made):
            with contextlib.suppress(OSError):
                folder.rmdir()   # only when still empty
        self._files, self._folders, self._made = [], [], []


@contextlib.contextmanager
def new_folders_removed_on_failure(folder):
    """Folders up to ``folder`` that the block creates are removed if it fails.

    For writers that create their destination folder themselves: a failed run
    leaves no empty folder behind (a folder that received other files stays).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> try:
    ...     with new_folders_removed_on_failure(d / "a" / "b"):
    ...         (d / "a" / "b").mkdir(parents=True)
    ...         raise OSError("disk full")
    ... except OSError:
    ...     pass
    >>> list(d.iterdir())
    []
    """
    here, missing = Path(os.path.abspath(os.fspath(folder))), []
    while not os.path.lexists(here) and here.parent != here:
        missing.append(here)
        here = here.parent
    try:
        yield
    except BaseException:
        for made in missing:   # deepest first
            with contextlib.suppress(OSError):
                made.rmdir()   # only when still empty
        raise


@contextlib.contextmanager
def staged_outputs():
    """A :class:`StagedOutputs` committed when the block succeeds, else discarded.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> with staged_outputs() as stage:
    ...     _ = stage.file(d / "a.txt").write_text("done")
    >>> sorted(p.name for p in d.iterdir())
    ['a.txt']
    >>> try:
    ...     with staged_outputs() as stage:
    ...         _ = stage.file(d / "sub" / "b.txt").write_text("half")
    ...         raise RuntimeError("failed")
    ... except RuntimeError:
    ...     pass
    >>> sorted(p.name for p in d.iterdir())
    ['a.txt']
    """
    stage = StagedOutputs()
    try:
        yield stage
        stage.commit()
    except BaseException:   # in the block, or a move that failed: nothing staged stays
        stage.discard()
        raise
