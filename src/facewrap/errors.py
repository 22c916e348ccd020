"""Errors that facewrap raises for bad input.

Every problem with a user's file is one :class:`InputError` whose message names the
file (and the line where there is one) and the problem, so the CLI can print it as a
single line and exit non-zero.  It derives from ``ValueError`` so library users can
catch it the usual way.  An input that is legal but odd is an :class:`InputWarning`.
"""

from __future__ import annotations

import os

__all__ = ["InputError", "InputWarning"]


class InputError(ValueError):
    """Bad input, with where it was found.

    Parameters
    ----------
    problem : str
        What is wrong, in words a user understands.
    path : str or os.PathLike, optional
        The file the problem is in.
    line : int, optional
        1-based line number inside ``path``.

    Examples
    --------
    >>> str(InputError("face index 9 out of range", path="a.obj", line=12))
    'a.obj:12: face index 9 out of range'
    """

    def __init__(self, problem: str, path: str | os.PathLike | None = None,
                 line: int | None = None):
        self.problem = problem
        self.path = None if path is None else os.fspath(path)
        self.line = line
        where = ""
        if self.path is not None:
            where = self.path + (f":{line}" if line is not None else "") + ": "
        super().__init__(where + problem)


class InputWarning(UserWarning):
    """An input that is legal but odd; the message names the file and the oddity."""
