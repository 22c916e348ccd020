"""The report page's tables: numbers of a run as HTML cards.

:func:`summary_html` turns a nested dict of numbers into cards of tables
(top-level values in an "Overview", each dict or list of records in its own card,
a list of strings as a bulleted list, a matrix as a grid); :func:`format_value`
is how one value prints (ints with separators, floats to four significant
digits, strings as they are: distances arrive as text with their unit, see
:func:`facewrap.units.format_distance`).
"""

from __future__ import annotations

import html
import math
from typing import Mapping

import numpy as np

__all__ = ["summary_html", "format_value"]


def _label(key) -> str:
    return str(key).replace("_", " ")


def _is_number(v) -> bool:
    return isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)


def format_value(v) -> tuple[str, str]:
    """``(text, css class)`` of one table value."""
    if v is None:
        return "–", "num"
    if isinstance(v, (bool, np.bool_)):
        return ("yes" if v else "no"), "num"
    if isinstance(v, (int, np.integer)):
        return f"{int(v):,}", "num"
    if _is_number(v):
        x = float(v)
        if not math.isfinite(x):
            return str(x), "num"
        if x != 0 and (abs(x) < 1e-3 or abs(x) >= 1e6):
            return f"{x:.3e}", "num"
        return f"{x:.4g}" if abs(x) < 1e4 else f"{x:,.1f}", "num"
    if isinstance(v, (list, tuple)) and all(_is_number(x) for x in v) and len(v) <= 6:
        return ", ".join(format_value(x)[0] for x in v), "num"
    return str(v), "txt"


def _flatten(d: Mapping, prefix: str = "") -> list[tuple[str, object]]:
    rows = []
    for k, v in d.items():
        key = f"{prefix}{_label(k)}"
        if isinstance(v, Mapping):
            rows += _flatten(v, key + " › ")
        else:
            rows.append((key, v))
    return rows


def _is_matrix(v) -> bool:
    return (isinstance(v, (list, tuple, np.ndarray)) and len(v) > 0
            and all(isinstance(r, (list, tuple, np.ndarray)) and len(r) == len(v[0])
                    and all(_is_number(x) for x in r) for r in v))


def _is_records(v) -> bool:
    return (isinstance(v, (list, tuple)) and len(v) > 0
            and all(isinstance(r, Mapping) for r in v))


def _key_value_table(rows) -> str:
    body = []
    for k, v in rows:
        if _is_matrix(v):
            cell = _matrix_table(v)
            cls = ""
        else:
            text, cls = format_value(v)
            cell = html.escape(text)
        body.append(f'<tr><td class="k">{html.escape(k)}</td>'
                    f'<td class="{cls}">{cell}</td></tr>')
    return '<table class="kv">' + "".join(body) + "</table>"


def _matrix_table(m) -> str:
    rows = "".join("<tr>" + "".join(f"<td>{html.escape(format_value(x)[0])}</td>" for x in r)
                   + "</tr>" for r in m)
    return f'<table class="matrix">{rows}</table>'


def _records_table(records) -> str:
    cols: list = []
    flat = [dict(_flatten(r)) for r in records]
    for r in flat:
        cols += [c for c in r if c not in cols]
    numeric = {c: all(_is_number(r.get(c)) or r.get(c) is None for r in flat) for c in cols}
    head = "".join(f'<th class="{"num" if numeric[c] else ""}">{html.escape(c)}</th>'
                   for c in cols)
    body = []
    for r in flat:
        cells = []
        for c in cols:
            text, cls = format_value(r.get(c))
            cells.append(f'<td class="{cls}">{html.escape(text)}</td>')
        body.append("<tr>" + "".join(cells) + "</tr>")
    return (f'<div class="scroll"><table><thead><tr>{head}</tr></thead>'
            f'<tbody>{"".join(body)}</tbody></table></div>')


def summary_html(summary: Mapping) -> str:
    """Cards of tables: top-level values in one, each dict or record list in its own."""
    loose, cards = [], []
    for key, value in summary.items():
        if isinstance(value, Mapping):
            if value:
                rows = _flatten(value)
                long_text = any(isinstance(v, str) and len(v) > 40 for _, v in rows)
                cards.append((" wide" if long_text else "", key, _key_value_table(rows)))
        elif isinstance(value, (list, tuple)) and value and all(
                isinstance(x, str) for x in value):
            items = "".join(f"<li>{html.escape(x)}</li>" for x in value)
            cards.append((" wide", key, f'<ul class="notes">{items}</ul>'))
        elif _is_records(value):
            cards.append((" wide", key, _records_table(value)))
        elif _is_matrix(value):
            cards.append(("", key, _matrix_table(value)))
        else:
            loose.append((_label(key), value))
    if loose:
        cards.insert(0, ("", "overview", _key_value_table(loose)))
    return "".join(f'<section class="card{wide}"><h4>{html.escape(_label(t)).capitalize()}'
                   f'</h4>{table}</section>' for wide, t, table in cards)
