"""Atomic file writing: an output file is either complete or absent.

Writers open a temporary file beside the destination and rename it over the
destination only when everything was written, so a crash or ``kill -9`` never
leaves a half-written output behind.

Permissions are those a plain ``open(path, "w")`` would give: a new file gets
``0o666`` less the process umask (the temporary file is created with that mode, so
the kernel applies the umask and any default ACL of the folder, exactly as for
``open``); a file that is replaced keeps its permission bits (``0o644`` stays
``0o644``, a private ``0o600`` stays private), as it would when ``open`` truncates
it.  Set-id and sticky bits are not carried over, and the replaced file's owner
and group are not either (only root could set them).
"""

from __future__ import annotations

import contextlib
import errno
import os
import secrets
import stat

from facewrap.io.paths import hidden_name, shown_path

__all__ = ["atomic_write"]

_NEW_FILE_MODE = 0o666
# errors of a write that ran out of room (disk full, quota, ulimit -f)
_FULL = (errno.ENOSPC, errno.EFBIG, errno.EDQUOT)
_TRIES = 100


def _create_temporary(folder: str, name: str) -> tuple[int, str]:
    """Create a new, uniquely named file in ``folder``: (descriptor, path)."""
    flags = (os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0)
             | getattr(os, "O_BINARY", 0))
    for _ in range(_TRIES):
        tmp = os.path.join(folder, hidden_name(f".tmp-{secrets.token_hex(4)}-", name, folder))
        try:
            return os.open(tmp, flags, _NEW_FILE_MODE), tmp
        except FileExistsError:
            continue
    raise FileExistsError(f"no free temporary name in {folder}")  # pragma: no cover


def _kept_mode(path: str) -> int | None:
    """Permission bits of the file ``path`` replaces, None when there is none."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return stat.S_IMODE(st.st_mode) & 0o777 if stat.S_ISREG(st.st_mode) else None


@contextlib.contextmanager
def atomic_write(path, mode: str = "w", **open_kwargs):
    """Open a temporary file that replaces ``path`` when the block succeeds.

    Parameters
    ----------
    path : str or os.PathLike
        Destination.  Its folder must exist.  A new file's mode is ``0o666`` less
        the umask; an existing file's permission bits are kept.
    mode : {"w", "wb"}
        Text or binary.
    **open_kwargs
        Passed to :func:`open` (``encoding``, ``newline``...).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> d = tempfile.mkdtemp()
    >>> with atomic_write(pathlib.Path(d) / "a.txt") as f:
    ...     _ = f.write("done")
    >>> (pathlib.Path(d) / "a.txt").read_text()
    'done'
    """
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = _create_temporary(folder, os.path.basename(path))
    try:
        with os.fdopen(fd, mode, **open_kwargs) as f:  # closes fd if it fails
            kept = _kept_mode(path)
            if kept is not None:
                os.chmod(tmp, kept)
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and exc.filename is None and exc.errno in _FULL:
            # a write that ran out of room names no file: say which output it was
            raise OSError(exc.errno, exc.strerror, shown_path(path)) from None
        raise
