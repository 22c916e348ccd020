"""Public names of a package imported on first use (PEP 562).

A package's ``__init__`` lists its public names and the modules that define them;
importing the package then costs nothing more, and ``from facewrap.jobs import
WrapJob`` imports only the module that defines ``WrapJob`` (and what it needs).  So a
command pays the start-up of what it uses: ``facewrap wrap`` does not load the
transfer machinery because ``facewrap.jobs`` also names ``TransferJob``.
"""

from __future__ import annotations

import sys
import types
from importlib import import_module

__all__ = ["lazy_exports"]


class _LazyPackage(types.ModuleType):
    """A package whose public names (``_lazy_names``: name -> module) load on use."""

    def __getattr__(self, name: str):
        table = self.__dict__.get("_lazy_names", {})
        if name not in table:
            raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")
        value = getattr(import_module(table[name]), name)
        setattr(self, name, value)       # once loaded, a plain attribute
        return value

    def __setattr__(self, name: str, value) -> None:
        # Loading a submodule binds it to the package's attribute of its name; where a
        # public name is also a submodule's (``wrapping.track``, the function, in
        # ``wrapping/track.py``) the public object wins, as after an eager
        # ``from facewrap.wrapping.track import track``.
        if (isinstance(value, types.ModuleType) and name in self.__dict__.get(
                "_lazy_names", {}) and value.__name__ == f"{self.__name__}.{name}"):
            value = getattr(value, name)
        super().__setattr__(name, value)

    def __dir__(self):
        return sorted(set(self.__dict__) | set(self.__dict__.get("_lazy_names", {})))


def lazy_exports(package: str, table: dict) -> None:
    """Make the public names of ``package`` (already in ``sys.modules``: call it from
    the package's ``__init__``) load on first use.

    Parameters
    ----------
    package : str
        The package's ``__name__``.
    table : dict of str to str
        Public name -> the module (absolute name) that defines it.

    Examples
    --------
    >>> import sys, types
    >>> sys.modules["pkg"] = types.ModuleType("pkg")
    >>> lazy_exports("pkg", {"sqrt": "math"})
    >>> sys.modules["pkg"].sqrt(9.0), "sqrt" in dir(sys.modules["pkg"])
    (3.0, True)
    >>> sys.modules["pkg"].nothing
    Traceback (most recent call last):
    ...
    AttributeError: module 'pkg' has no attribute 'nothing'
    >>> del sys.modules["pkg"]
    """
    module = sys.modules[package]
    module.__dict__["_lazy_names"] = dict(table)
    module.__class__ = _LazyPackage
