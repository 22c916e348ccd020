"""Units of length (facewrap.units): inference from a head's size, the formatter."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from facewrap.units import (HEAD_SIZE_M, UNIT_CHOICES, UNITS, UNKNOWN, check_units_choice,
                            format_distance, head_size, infer_units, metres_per_unit,
                            resolve_units, units_note)

DATA = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"


def head_box(width_m: float, unit: str, seed: int = 0) -> np.ndarray:
    """Random points filling a head-shaped box ``width_m`` wide, in ``unit``."""
    rng = np.random.default_rng(seed)
    size = np.array([1.0, 1.4, 0.9]) * width_m / UNITS[unit]
    return rng.uniform(-0.5, 0.5, size=(200, 3)) * size + [3.0, -2.0, 7.0]


@pytest.mark.parametrize("unit", ["mm", "cm", "m"])
@pytest.mark.parametrize("width_m", [0.12, 0.16, 0.25, 0.4])
def test_a_head_is_recognised_in_each_unit(unit, width_m):
    assert infer_units(head_box(width_m, unit)) == unit


def test_the_decades_of_the_units_do_not_overlap():
    # one decade per unit: every size matches at most one unit, and sizes
    # between the decades of no sensible head match none
    lo, hi = HEAD_SIZE_M
    assert hi / lo == pytest.approx(10.0)
    for size in np.geomspace(1e-4, 1e4, 400):
        fits = [u for u in ("mm", "cm", "m") if lo <= size * UNITS[u] < hi]
        assert len(fits) <= 1
        assert infer_units([[0, 0, 0], [size, size, size]]) == (fits[0] if fits
                                                                else UNKNOWN)


def test_sizes_that_fit_no_unit_are_unknown():
    assert infer_units(head_box(0.2, "mm") * 1e3) == UNKNOWN   # a head in micrometres
    assert infer_units(head_box(0.2, "m") / 100) == UNKNOWN
    assert infer_units(np.zeros((5, 3))) == UNKNOWN
    assert infer_units(np.full((3, 3), np.nan)) == UNKNOWN


def test_a_neck_or_shoulders_do_not_decide_the_size():
    head = head_box(0.2, "mm")
    # shoulders 80 cm apart below the chin: the widest extent is theirs, the
    # middle one still a head's
    torso = np.array([[-400.0, -250.0, 0.0], [400.0, -250.0, 0.0]])
    assert head_size(np.vstack([head, torso])) < 450
    assert infer_units(np.vstack([head, torso])) == "mm"


@pytest.mark.skipif(not DATA.is_dir(), reason="../shared/data is absent")
@pytest.mark.parametrize("path, unit", [
    ("ict-facekit/FaceXModel/generic_neutral_mesh.obj", "cm"),
    ("scans/james/james.obj", "mm"),
    ("scans/meshmonk/DemoFace_10K.obj", "mm"),   # with neck and shoulders
    ("scans/meshmonk/Template.obj", "mm"),
])
def test_real_heads_in_their_published_units(path, unit):
    from facewrap.io import read_mesh
    assert infer_units(read_mesh(DATA / path).vertices) == unit


def test_the_sample_is_in_millimetres():
    from facewrap.sample import make_template
    assert infer_units(make_template(24).mesh.vertices) == "mm"


def test_resolve_gives_given_units_as_they_are():
    cm_head = head_box(0.2, "cm")
    assert resolve_units("auto", cm_head) == ("cm", "inferred")
    for unit in UNITS:
        assert resolve_units(unit, cm_head) == (unit, "given")
    with pytest.raises(ValueError, match="units must be one of auto, mm, cm, m, in; "
                                         "got 'ft'"):
        resolve_units("ft", cm_head)


@pytest.mark.parametrize("bad", ["", "MM", "feet", None, 3])
def test_check_units_choice_names_the_option(bad):
    with pytest.raises(ValueError, match="--units must be one of"):
        check_units_choice(bad, "--units")
    assert all(check_units_choice(u) == u for u in UNIT_CHOICES)


def test_units_note_says_where_the_unit_came_from():
    assert units_note("mm", "given") == "units: mm (given)"
    assert "inferred from the head's size; --units to set" in units_note("cm", "inferred")
    assert "unknown" in units_note(UNKNOWN, "inferred")


def test_metres_per_unit():
    assert metres_per_unit("in") == 0.0254 and metres_per_unit(UNKNOWN) is None
    with pytest.raises(ValueError, match="unknown unit"):
        metres_per_unit("ft")


@pytest.mark.parametrize("value, unit, text", [
    (1.2013, "mm", "1.201 mm"),
    (4.0919, "mm", "4.092 mm"),
    (38.349, "mm", "38.35 mm"),
    (105.23, "mm", "105.2 mm"),
    (12345.6, "mm", "12,346 mm"),
    (0.0123, "mm", "0.012 mm"),
    (0.0004, "mm", "< 0.001 mm"),
    (1.589e-14, "mm", "< 0.001 mm"),
    (-1.589e-14, "mm", "< 0.001 mm"),
    (0.0, "cm", "0 cm"),
    (0.12013, "cm", "0.1201 cm"),
    (0.00002, "cm", "< 0.0001 cm"),
    (0.0012, "m", "0.001200 m"),
    (0.5, "in", "0.5000 in"),
    (2.5, UNKNOWN, "2.500 units"),
    (None, "mm", "n/a"),
    (float("nan"), "mm", "n/a"),
    (float("inf"), "mm", "n/a"),
])
def test_format_distance(value, unit, text):
    assert format_distance(value, unit) == text


def test_format_distance_never_prints_exponents_and_stays_close():
    rng = np.random.default_rng(1)
    for unit in ("mm", "cm", "m", "in", UNKNOWN):
        for v in np.concatenate([10.0 ** rng.uniform(-16, 5, 300), [0.0]]):
            text = format_distance(v, unit, with_unit=False)
            assert "e" not in text and "E" not in text, text
            if text.startswith("<"):
                assert v < float(text[2:])
            else:
                shown = float(text.replace(",", ""))
                # four significant digits, or the unit's resolution, whichever is coarser
                assert abs(shown - v) <= max(5e-4 * v, 0.51 * 10.0 ** -{
                    "mm": 3, "cm": 4, "m": 6, "in": 5}.get(unit, 4)) + 1e-12
