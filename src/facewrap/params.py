"""Allowed values of settings, declared once per settings class and checked at the door.

Every settings dataclass (``WrapSettings``, ``Stage``, the transfer and avatar
settings) carries a class attribute ``constraints``: a mapping from field name to
one constraint (or a tuple of alternatives, any of which may hold).  Its
``__post_init__`` calls :func:`validate`, so a wrong value raises at construction,
naming the field, what is allowed and what was given — the way scikit-learn's
parameter constraints do.  The CLI and the job-file reader take their choices and
ranges from the same table (:func:`choices_of`), so the library never needs the CLI.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass
... class Knob:
...     kind: str = "a"
...     level: float = 1.0
...     constraints = {"kind": Options("a", "b"), "level": Interval(float, 0, None)}
...     def __post_init__(self):
...         validate(self)
>>> Knob(kind="b").kind
'b'
>>> Knob(kind="c")
Traceback (most recent call last):
...
facewrap.params.SettingsError: Knob.kind must be one of 'a', 'b'; got 'c'
>>> Knob(level=-1.0)
Traceback (most recent call last):
...
facewrap.params.SettingsError: Knob.level must be a real number in [0, inf); got -1.0
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from numbers import Integral, Real

import numpy as np

__all__ = ["Constraint", "Options", "Interval", "Flag", "NoneAllowed", "Empty", "Pair",
           "Instances", "SettingsError", "validate", "choices_of", "invalid_examples",
           "expect_instance", "not_one_string"]


class SettingsError(ValueError):
    """A settings field whose value is not allowed.

    ``str()`` names the class and the field (``WrapSettings.node_spacing must be
    ...``), as a job file's key would be named; a command line names its option
    instead, from :attr:`field` and :attr:`problem`.

    Attributes
    ----------
    owner : str
        The settings class.
    field : str
        The field's name.
    problem : str
        What is allowed and what was given (``must be ...; got ...``).
    """

    def __init__(self, owner: str, field: str, problem: str):
        self.owner, self.field, self.problem = owner, field, problem
        super().__init__(f"{owner}.{field} {problem}")


class Constraint:
    """One rule a value must follow; ``describe()`` says it in words."""

    def holds(self, value) -> bool:  # pragma: no cover - every subclass defines it
        raise NotImplementedError

    def describe(self) -> str:  # pragma: no cover
        raise NotImplementedError

    def invalid(self) -> list:
        """Values that break this rule (for the generated test of every constraint)."""
        return []


@dataclass(frozen=True)
class Options(Constraint):
    """One of a fixed set of values (strings or integers).

    >>> Options("welsch", "huber").holds("huber"), Options(1, 2).holds(7)
    (True, False)
    >>> Options("welsch", "huber").holds(np.str_("huber")), Options(1, 2).holds(1.0)
    (True, False)
    """

    values: tuple

    def __init__(self, *values):
        object.__setattr__(self, "values", tuple(values))

    def holds(self, value) -> bool:
        if isinstance(value, bool) and not any(isinstance(v, bool) for v in self.values):
            return False
        # numpy's scalars count as what they hold (np.str_("rbf") read from an
        # array is "rbf"); 1.0 is still not the option 1
        return any(type(value) is type(v) or (isinstance(v, Integral)
                                               and isinstance(value, Integral))
                   or (isinstance(v, str) and isinstance(value, str))
                   for v in self.values) and value in self.values

    def describe(self) -> str:
        return "one of " + ", ".join(repr(v) for v in self.values)

    def invalid(self) -> list:
        if all(isinstance(v, str) for v in self.values):
            return ["".join(self.values[0][::-1]) + "?", 3]
        return [max(self.values) + 1, "x"]


@dataclass(frozen=True)
class Interval(Constraint):
    """A finite real (``float``) or integer (``int``) number in a range.

    ``closed`` says which ends belong to it: "both", "left", "right" or "neither".
    ``None`` for an end means unbounded on that side.  Booleans, NaN and infinities
    are never numbers here.

    >>> Interval(float, 0, 1, closed="neither").holds(0.0)
    False
    >>> Interval(int, 1, None).holds(3), Interval(int, 1, None).holds(3.0)
    (True, False)
    """

    kind: type
    low: float | None
    high: float | None
    closed: str = "both"

    def holds(self, value) -> bool:
        if isinstance(value, bool):
            return False
        if self.kind is int:
            if not isinstance(value, Integral):
                return False
        elif not isinstance(value, Real) or not math.isfinite(value):
            return False
        left = self.closed in ("both", "left")
        right = self.closed in ("both", "right")
        if self.low is not None and (value < self.low or (value == self.low and not left)):
            return False
        if self.high is not None and (value > self.high
                                      or (value == self.high and not right)):
            return False
        return True

    def describe(self) -> str:
        word = "an integer" if self.kind is int else "a real number"
        lo = "-inf" if self.low is None else f"{self.low:g}"
        hi = "inf" if self.high is None else f"{self.high:g}"
        left = "[" if self.closed in ("both", "left") and self.low is not None else "("
        right = "]" if self.closed in ("both", "right") and self.high is not None else ")"
        return f"{word} in {left}{lo}, {hi}{right}"

    def invalid(self) -> list:
        bad = [float("nan"), "1"] if self.kind is float else [1.5, "1"]
        if self.low is not None:
            bad.append(self.kind(self.low - 1))
            if self.closed not in ("both", "left"):
                bad.append(self.kind(self.low))
        if self.high is not None:
            bad.append(self.kind(self.high + 1))
            if self.closed not in ("both", "right"):
                bad.append(self.kind(self.high))
        return bad


@dataclass(frozen=True)
class Flag(Constraint):
    """``True`` or ``False`` (not 0 or 1).

    >>> Flag().holds(True), Flag().holds(1)
    (True, False)
    """

    def holds(self, value) -> bool:
        return isinstance(value, (bool, np.bool_))

    def describe(self) -> str:
        return "True or False"

    def invalid(self) -> list:
        return [1, "yes"]


@dataclass(frozen=True)
class NoneAllowed(Constraint):
    """``None`` (combine with another constraint in a tuple: ``(NoneAllowed(), X)``)."""

    def holds(self, value) -> bool:
        return value is None

    def describe(self) -> str:
        return "None"


@dataclass(frozen=True)
class Empty(Constraint):
    """An empty tuple or list (e.g. "no bounds" where ``None`` means "the default")."""

    def holds(self, value) -> bool:
        return isinstance(value, (tuple, list)) and len(value) == 0

    def describe(self) -> str:
        return "empty"


@dataclass(frozen=True)
class Pair(Constraint):
    """Two numbers ``(low, high)`` with ``low < high``, each following ``item``.

    >>> Pair(Interval(float, None, None)).holds((0.0, 1.0))
    True
    >>> Pair(Interval(float, None, None)).holds((1.0, 0.0))
    False
    """

    item: Constraint

    def holds(self, value) -> bool:
        if not isinstance(value, (tuple, list)) or len(value) != 2:
            return False
        return all(self.item.holds(v) for v in value) and value[0] < value[1]

    def describe(self) -> str:
        return f"a pair (low, high), low < high, each {self.item.describe()}"

    def invalid(self) -> list:
        return [(1.0, 0.0), (0.0,), "0 1"]


@dataclass(frozen=True)
class Instances(Constraint):
    """A list (or tuple) whose items are instances of ``kind``; ``nonempty`` by default."""

    kind: type
    nonempty: bool = True

    def holds(self, value) -> bool:
        if not isinstance(value, (list, tuple)) or (self.nonempty and not value):
            return False
        return all(isinstance(v, self.kind) for v in value)

    def describe(self) -> str:
        many = "a non-empty list" if self.nonempty else "a list"
        return f"{many} of {self.kind.__name__}"

    def invalid(self) -> list:
        return ([[]] if self.nonempty else []) + [[object()], "x"]


def _alternatives(rule) -> tuple:
    return rule if isinstance(rule, tuple) else (rule,)


def validate(settings) -> None:
    """Check every field of a settings dataclass against its class's ``constraints``.

    Parameters
    ----------
    settings : dataclass instance
        Its class has ``constraints: dict[str, Constraint | tuple[Constraint, ...]]``.

    Raises
    ------
    SettingsError
        A ``ValueError`` for the first field whose value follows none of its
        alternatives: names the class and field, what is allowed and what was given.
    """
    cls = type(settings)
    table = getattr(cls, "constraints", {})
    names = {f.name for f in fields(settings)}
    unknown = set(table) - names
    if unknown:  # a table naming a field that does not exist is a bug of ours
        raise TypeError(f"{cls.__name__}.constraints names no field: {sorted(unknown)}")
    for name, rule in table.items():
        value = getattr(settings, name)
        alts = _alternatives(rule)
        if not any(c.holds(value) for c in alts):
            allowed = " or ".join(c.describe() for c in alts)
            raise SettingsError(cls.__name__, name, f"must be {allowed}; got {value!r}")


def choices_of(cls, name: str) -> tuple | None:
    """The allowed values of a field constrained by :class:`Options`, else None.

    >>> from dataclasses import dataclass
    >>> @dataclass
    ... class K:
    ...     kind: str = "a"
    ...     constraints = {"kind": Options("a", "b")}
    >>> choices_of(K, "kind")
    ('a', 'b')
    """
    for c in _alternatives(getattr(cls, "constraints", {}).get(name, ())):
        if isinstance(c, Options):
            return c.values
    return None


def invalid_examples(cls) -> list[tuple[str, object]]:
    """``(field, value)`` pairs that each constraint of ``cls`` must refuse.

    A value is kept only when no alternative of the field accepts it (so ``None`` is
    not offered for a field that also allows None).
    """
    out = []
    for name, rule in getattr(cls, "constraints", {}).items():
        alts = _alternatives(rule)
        for c in alts:
            for value in c.invalid():
                if not any(a.holds(value) for a in alts):
                    out.append((name, value))
    return out


def expect_instance(value, kind: type, name: str, *, optional: bool = False):
    """``value`` when it is a ``kind`` (or None, when ``optional``), else a
    ``TypeError`` naming the argument: a dict or a string where a settings object
    or a mesh belongs fails here, not as an ``AttributeError`` deep inside.

    Parameters
    ----------
    value : object
    kind : type
    name : str
        The argument's name, for the message.
    optional : bool
        Whether None is allowed.

    Returns
    -------
    object
        ``value`` itself.

    Examples
    --------
    >>> expect_instance(None, dict, "settings", optional=True) is None
    True
    >>> expect_instance("graph", dict, "settings")
    Traceback (most recent call last):
    ...
    TypeError: settings must be a dict, got str ('graph')
    """
    if isinstance(value, kind) or (optional and value is None):
        return value
    shown = repr(value)
    shown = shown if len(shown) <= 40 else shown[:37] + "..."
    allowed = f"a {kind.__name__}" + (" or None" if optional else "")
    raise TypeError(f"{name} must be {allowed}, got {type(value).__name__} ({shown})")


def not_one_string(value, name: str):
    """``value`` unless it is one string where a sequence of names belongs (``"skin"``
    would be read as the four names s, k, i, n), else a ``TypeError`` naming it.

    Examples
    --------
    >>> not_one_string(["skin", "lips"], "materials")
    ['skin', 'lips']
    >>> not_one_string("skin", "materials")
    Traceback (most recent call last):
    ...
    TypeError: materials must be a sequence of strings, got one string 'skin'
    """
    if isinstance(value, (str, bytes)):
        raise TypeError(f"{name} must be a sequence of strings, got one string {value!r}")
    return value
