"""Units of length: the table, inference from a head's size, and one formatter.

Meshes carry no units, yet every distance facewrap prints or reports must say
its unit.  The unit of a run's data is either *given* (``--units``, the job key
``units``) or *inferred* from the size of the head it shows: a face or a head is
a few decimetres across, so the middle extent of its bounding box falls in one
decade of metres, and which decade it falls in (in mm, cm or m) says the unit.
Inches are never inferred (a head in inches and in centimetres is of the same
order); a size that fits no unit gives ``"units"``: unknown.

:func:`format_distance` is the one way a distance becomes text: a precision of
about four significant digits but never finer than the unit's resolution (a
micrometre or so), so rounding noise prints as ``< 0.001 mm``, never as
``1.589e-14``.

Examples
--------
>>> import numpy as np
>>> head_cm = np.array([[0, 0, 0], [16.0, 23.0, 14.0]])
>>> infer_units(head_cm), infer_units(head_cm * 10), infer_units(head_cm * 1e4)
('cm', 'mm', 'units')
>>> resolve_units("auto", head_cm), resolve_units("in", head_cm)
(('cm', 'inferred'), ('in', 'given'))
>>> format_distance(1.2013, "mm"), format_distance(1.589e-14, "mm")
('1.201 mm', '< 0.001 mm')
>>> format_distance(105.23, "mm"), format_distance(0.0, "cm"), format_distance(None, "mm")
('105.2 mm', '0 cm', 'n/a')
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["UNITS", "UNIT_NAMES", "UNIT_CHOICES", "UNKNOWN", "HEAD_SIZE_M",
           "metres_per_unit", "check_units_choice", "head_size", "infer_units",
           "resolve_units", "units_conflict", "describe_units", "units_note",
           "format_distance", "distance_decimals", "resolution_decimals",
           "add_units_argument", "COORDINATE_LIMIT", "first_too_large", "too_large"]

#: Metres per unit of each known unit of length.
UNITS = {"mm": 0.001, "cm": 0.01, "m": 1.0, "in": 0.0254}

#: The known units, in table order.
UNIT_NAMES = tuple(UNITS)

#: The label of data whose unit is neither given nor inferable.
UNKNOWN = "units"

#: What ``--units`` and the job key ``units`` accept ("auto": infer).
UNIT_CHOICES = ("auto",) + UNIT_NAMES

#: [low, high) of a head's middle bounding-box extent, in metres: one decade, so
#: at most one of mm, cm and m fits (a cropped face to a head with shoulders).
HEAD_SIZE_M = (0.08, 0.8)

#: Largest coordinate magnitude a mesh, shape or landmark may hold. Far beyond any
#: head in any unit (10^15 mm is a light-hour), yet small enough that the squares
#: and products of sizes that normals, areas and distances take (up to the fourth
#: power) stay finite: a 1e308 vertex would otherwise pass the NaN check and turn
#: into overflow warnings, NaN normals and a silent fit.
COORDINATE_LIMIT = 1e15

# decimals of the unit's resolution (about a micrometre); UNKNOWN gets 4
_DECIMALS = {"mm": 3, "cm": 4, "m": 6, "in": 5, UNKNOWN: 4}


def first_too_large(values) -> int | None:
    """Row of the first value beyond :data:`COORDINATE_LIMIT` in magnitude, or None.

    Parameters
    ----------
    values : (n, k) float64
        Finite coordinates, one row per vertex or point.

    Examples
    --------
    >>> first_too_large(np.array([[0.0, 1.0], [2.0, -1e308]])), first_too_large(np.ones((2, 3)))
    (1, None)
    """
    big = np.abs(values) > COORDINATE_LIMIT
    if not big.any():
        return None
    return int(np.argmax(big.reshape(len(values), -1).any(axis=1)))


def too_large(values, what: str = "vertex") -> str | None:
    """The first row of ``values`` beyond :data:`COORDINATE_LIMIT`, as the problem in
    words (for an error to name its file or argument), or None.

    Parameters
    ----------
    values : (n, k) float64
    what : str
        What a row is ("vertex", "landmark").

    Examples
    --------
    >>> too_large(np.array([[0.0, 1e30, 0.0]]))[:40]
    'vertex 0 has coordinate 1e+30, too large'
    >>> too_large(np.zeros((2, 3))) is None
    True
    """
    row = first_too_large(values)
    if row is None:
        return None
    return (f"{what} {row} has coordinate {np.abs(values[row]).max():g}, too large (more "
            f"than {COORDINATE_LIMIT:g} in magnitude in any unit: not a scan, and its "
            "sizes would overflow)")


def metres_per_unit(unit: str) -> float | None:
    """Metres in one ``unit``; None for :data:`UNKNOWN`.

    >>> metres_per_unit("cm"), metres_per_unit("units")
    (0.01, None)
    """
    if unit == UNKNOWN:
        return None
    if unit not in UNITS:
        raise ValueError(f"unknown unit {unit!r}; known: {', '.join(UNIT_NAMES)}")
    return UNITS[unit]


def check_units_choice(value, name: str = "units") -> str:
    """``value`` if it is one of :data:`UNIT_CHOICES`, else a ValueError naming ``name``.

    >>> check_units_choice("cm")
    'cm'
    >>> check_units_choice("furlong")
    Traceback (most recent call last):
    ...
    ValueError: units must be one of auto, mm, cm, m, in; got 'furlong'
    """
    if not isinstance(value, str) or value not in UNIT_CHOICES:
        raise ValueError(f"{name} must be one of {', '.join(UNIT_CHOICES)}; got {value!r}")
    return value


def head_size(points) -> float:
    """Middle extent of the bounding box of ``points`` (n, 3) float.

    The middle extent (not the largest) keeps a neck or shoulders in a scan from
    deciding the size; NaN rows are ignored; 0.0 for no finite point.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    finite = np.isfinite(P)
    if not finite.all():
        P = P[finite.all(axis=1)]
    if len(P) == 0:
        return 0.0
    # column by column: numpy reduces axis 0 of a narrow array a row at a time,
    # 25 times slower on a million-vertex scan
    return float(np.sort([c.max() - c.min() for c in P.T])[1])


def infer_units(points) -> str:
    """The unit in which ``points`` (n, 3), a head or a face, has a head's size.

    Returns one of "mm", "cm", "m", or :data:`UNKNOWN` when the middle extent is
    in no unit within :data:`HEAD_SIZE_M`.
    """
    size = head_size(points)
    lo, hi = HEAD_SIZE_M
    for unit in ("mm", "cm", "m"):
        if lo <= size * UNITS[unit] < hi:
            return unit
    return UNKNOWN


def resolve_units(choice: str, points) -> tuple[str, str]:
    """``(unit, source)``: the given unit (source "given"), or for "auto" the
    inferred one from ``points`` (source "inferred")."""
    check_units_choice(choice)
    if choice != "auto":
        return choice, "given"
    return infer_units(points), "inferred"


def units_conflict(choice: str, points) -> str | None:
    """What is wrong with a *given* unit that the head's size contradicts, else None.

    A unit is given (``--units``, the job key ``units``) to say what the numbers
    are; one that makes the head of ``points`` (n, 3) a size no head has, where
    another unit gives it a head's size (``--units m`` on a scan in millimetres:
    a head 0.2 km across), is a slip, and every distance shown would be off by
    its factor.  Inches, never inferred, are judged by the same range; a head
    that fits no unit says nothing (the caller's other checks speak of it).

    Returns
    -------
    str or None
        Text naming the option, the size it gives and the unit the size says:
        the caller puts the file in front.

    Examples
    --------
    >>> head_mm = np.array([[0, 0, 0], [160.0, 230.0, 140.0]])
    >>> units_conflict("m", head_mm)
    '--units m makes the head 160 m across; its size says mm (a head is 0.08-0.8 m)'
    >>> units_conflict("mm", head_mm) is None, units_conflict("auto", head_mm) is None
    (True, True)
    """
    check_units_choice(choice)
    if choice == "auto":
        return None
    inferred = infer_units(points)
    size = head_size(points) * UNITS[choice]
    lo, hi = HEAD_SIZE_M
    if inferred == UNKNOWN or lo <= size < hi:
        return None
    return (f"--units {choice} makes the head {size:.3g} m across; its size says "
            f"{inferred} (a head is {lo:g}-{hi:g} m)")


def describe_units(unit: str, source: str) -> str:
    """The unit and where it came from, for a table.

    >>> describe_units("mm", "given"), describe_units("cm", "inferred")
    ('mm (given)', "cm (inferred from the head's size)")
    """
    if source == "given":
        return f"{unit} (given)"
    if unit == UNKNOWN:
        return "unknown (the head's size fits none of mm, cm, m)"
    return f"{unit} (inferred from the head's size)"


def units_note(unit: str, source: str) -> str:
    """One line that states the unit and where it came from (and, when inferred,
    how to set it).

    >>> units_note("cm", "inferred")
    "units: cm (inferred from the head's size; --units to set)"
    >>> units_note("units", "inferred")
    "units: unknown (the head's size fits none of mm, cm, m; --units to set)"
    """
    text = describe_units(unit, source)
    return f"units: {text}" if source == "given" else f"units: {text[:-1]}; --units to set)"


def resolution_decimals(unit: str) -> int:
    """Decimals of ``unit``'s resolution (about a micrometre): 3 for mm.

    >>> resolution_decimals("mm"), resolution_decimals("cm"), resolution_decimals("units")
    (3, 4, 4)
    """
    return _DECIMALS.get(unit, _DECIMALS[UNKNOWN])


def distance_decimals(value: float, unit: str) -> int:
    """Decimals for ``value``: about four significant digits, at most the unit's
    resolution (:data:`UNKNOWN` and unknown labels: 4)."""
    most = resolution_decimals(unit)
    a = abs(float(value))
    if a == 0 or not math.isfinite(a):
        return most
    return int(max(0, min(most, 3 - math.floor(math.log10(a)))))


def format_distance(value, unit: str, *, with_unit: bool = True) -> str:
    """A distance as text with its unit: ``"1.201 mm"``.

    Parameters
    ----------
    value : float or None
        None and NaN print as "n/a"; exactly 0 as ``0``; a non-zero value below
        the unit's resolution as ``< 0.001`` (for mm), so rounding noise never
        shows as ``1.589e-14``.
    unit : str
        One of :data:`UNIT_NAMES` or :data:`UNKNOWN` (any other label is used as
        it is, with four decimals at most).
    with_unit : bool
        Append ``" " + unit`` (tables whose header carries the unit say False).
    """
    tail = f" {unit}" if with_unit and unit else ""
    if value is None or not math.isfinite(float(value)):
        return "n/a"
    v = float(value)
    most = resolution_decimals(unit)
    if v == 0:
        return "0" + tail
    if abs(v) < 0.5 * 10.0 ** -most:
        return f"< {10.0 ** -most:.{most}f}{tail}"
    d = distance_decimals(v, unit)
    text = f"{v:,.{d}f}" if abs(v) >= 1e4 else f"{v:.{d}f}"
    return text + tail


def add_units_argument(parser, default: str = "auto") -> None:
    """Add ``--units {auto,mm,cm,m,in}`` to an argparse ``parser`` (wrap, track,
    evaluate, report: one option, one help, one table of choices)."""
    parser.add_argument("--units", default=default, choices=list(UNIT_CHOICES),
                        help="unit of the data's coordinates, and so of every distance "
                             "shown (default %(default)s: inferred from the head's "
                             "size, and stated)")
