"""A cache of arrays on disk, keyed by the content they were computed from.

Work that depends only on an input's bytes (a folder of 53 shape OBJs parsed into
arrays, the hidden surface of a template) is done once per content and machine, not
once per process.  Entries are ``.npz`` files in one folder:

- ``$FACEWRAP_CACHE_DIR`` when set, else ``$XDG_CACHE_HOME/facewrap``, else
  ``~/.cache/facewrap``; never beside an input;
- ``FACEWRAP_CACHE=0`` turns the cache off (nothing read, nothing written).

Keys are SHA-256 digests of the content (see :func:`content_key`), never sizes or
modification times, so an edited file can never be answered from the cache.  An entry
is written atomically (a reader sees it whole or not at all) and is checked when it is
read: one that is corrupt, truncated, of another kind or another format version, or
that does not hold the arrays asked for, is ignored (and rewritten by the next
:func:`save_arrays`).  A cache folder that cannot be written is not an error: the
work is simply done again next time.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import threading
import zipfile

import numpy as np

from facewrap.io.atomic import atomic_write

__all__ = ["cache_dir", "content_key", "load_arrays", "save_arrays"]

# bump when the layout of every entry changes; each kind carries its own version too
_FORMAT = 1
#: see :func:`load_arrays`
_READING = threading.Lock()
_META = "__facewrap_cache__"


def cache_dir() -> str | None:
    """The cache folder, or None when the cache is turned off.

    Examples
    --------
    >>> import os
    >>> before = os.environ.get("FACEWRAP_CACHE")
    >>> os.environ["FACEWRAP_CACHE"] = "0"
    >>> cache_dir() is None
    True
    >>> _ = os.environ.pop("FACEWRAP_CACHE") if before is None else \\
    ...     os.environ.update(FACEWRAP_CACHE=before)
    """
    if os.environ.get("FACEWRAP_CACHE", "1").strip().lower() in ("0", "no", "off", "false"):
        return None
    folder = os.environ.get("FACEWRAP_CACHE_DIR")
    if not folder:
        base = os.environ.get("XDG_CACHE_HOME") or os.path.join(
            os.path.expanduser("~"), ".cache")
        folder = os.path.join(base, "facewrap")
    return folder


def content_key(*parts) -> str:
    """A hex digest of ``parts``: bytes, str, numbers or numpy arrays, in order.

    An array contributes its dtype, shape and bytes, so two arrays with the same bytes
    but another shape get other keys.

    Examples
    --------
    >>> import numpy as np
    >>> content_key(np.zeros(3), "graph") == content_key(np.zeros(3), "graph")
    True
    >>> content_key(np.zeros(3)) == content_key(np.zeros((3, 1)))
    False
    """
    # SHA-256 rather than BLAKE2b: the CPUs' SHA extensions make it 2.4x faster here
    # (44 MB of shape OBJs: 25 ms against 60 ms), and hashing is most of a warm read
    h = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            a = np.ascontiguousarray(part)
            h.update(f"nd:{a.dtype.str}:{a.shape}:".encode())
            h.update(a.view(np.uint8).reshape(-1) if a.size else b"")
        elif isinstance(part, (bytes, bytearray, memoryview)):
            h.update(b"b:%d:" % len(part))
            h.update(part)
        else:
            text = str(part).encode()
            h.update(b"s:%d:" % len(text))
            h.update(text)
    return h.hexdigest()


def _entry_path(folder: str, kind: str, key: str) -> str:
    return os.path.join(folder, f"{kind}-{key}.npz")


def load_arrays(kind: str, key: str, names, *, version: int = 1) -> dict | None:
    """The arrays stored under ``(kind, key)``, or None when there is no usable entry.

    Parameters
    ----------
    kind : str
        What the entry is (``"shapes"``, ``"hidden-surface"``): a word, part of the
        file name.
    key : str
        :func:`content_key` of everything the arrays depend on.
    names : iterable of str
        The arrays the caller needs; an entry missing one of them is not used.
    version : int
        The caller's layout version for this kind; an entry of another is not used.

    Returns
    -------
    dict of str to numpy.ndarray, or None

    Examples
    --------
    >>> import os, tempfile, numpy as np
    >>> before = os.environ.get("FACEWRAP_CACHE_DIR")
    >>> os.environ["FACEWRAP_CACHE_DIR"] = tempfile.mkdtemp()
    >>> key = content_key(b"some input")
    >>> load_arrays("example", key, ["x"]) is None
    True
    >>> save_arrays("example", key, {"x": np.arange(3)})
    >>> load_arrays("example", key, ["x"])["x"].tolist()
    [0, 1, 2]
    >>> _ = os.environ.pop("FACEWRAP_CACHE_DIR") if before is None else \\
    ...     os.environ.update(FACEWRAP_CACHE_DIR=before)
    """
    folder = cache_dir()
    if folder is None:
        return None
    path = _entry_path(folder, kind, key)
    try:
        # one reader at a time: np.load parses each array's header with
        # ast.literal_eval, which CPython 3.11 can fail on two threads at once
        # ("SystemError: AST constructor recursion depth mismatch", CPython
        # gh-106905); entries are small, the wait is short
        with _READING, np.load(path, allow_pickle=False) as data:
            meta = data[_META]
            if meta.tolist() != [_FORMAT, int(version)]:
                return None
            return {name: data[name] for name in names}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        # absent, unreadable, truncated, corrupt or foreign: as if there were none
        return None


def save_arrays(kind: str, key: str, arrays: dict, *, version: int = 1) -> None:
    """Store ``arrays`` under ``(kind, key)``; silently does nothing if it cannot.

    Parameters
    ----------
    kind, key, version
        As for :func:`load_arrays`.
    arrays : dict of str to numpy.ndarray
        Plain numeric or boolean arrays (no objects: entries are read without pickle).
    """
    folder = cache_dir()
    if folder is None:
        return
    with contextlib.suppress(OSError):
        os.makedirs(folder, exist_ok=True)
        payload = {name: np.asarray(a) for name, a in arrays.items()}
        payload[_META] = np.array([_FORMAT, int(version)], dtype=np.int64)
        with atomic_write(_entry_path(folder, kind, key), "wb") as f:
            np.savez(f, **payload)
