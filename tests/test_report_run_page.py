"""The page of a wrap run agrees with itself (issue 17): the viewer's figures and the
tables over the same (fitted) vertices and in the same unit; the parts that follow
apart; landmarks; a ground-truth heatmap; the warnings first."""

from __future__ import annotations

import base64
import html as htmllib
import json
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.evaluate import VERTEX_ROLE_NAMES
from facewrap.geometry import ClosestPointTree
from facewrap.io import read_mesh
from facewrap.io.landmarks import write_vertex_indices
from facewrap.jobs import WrapJob, run_wrap_job
from facewrap.landmarks import Landmarks
from facewrap.report.page import build_report_page
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.units import format_distance
from facewrap.wrapping import WrapSettings
from conftest import facewrap


def page_data(path: Path) -> dict:
    """The viewer's JSON block of a page."""
    m = re.search(r'<script type="application/json" id="facewrap-data">(.*?)</script>',
                  path.read_text(encoding="utf-8"), re.S)
    return json.loads(m.group(1))


def table_rows(path: Path) -> dict:
    """Every key-value row of the page's tables: {card title: {key: text}}."""
    text = path.read_text(encoding="utf-8")
    cards = {}
    for title, body in re.findall(r'<section class="card[^"]*"><h4>(.*?)</h4>(.*?)</section>',
                                  text, re.S):
        rows = re.findall(r'<td class="k">(.*?)</td><td class="[^"]*">(.*?)</td>', body)
        cards[htmllib.unescape(title)] = {htmllib.unescape(k): htmllib.unescape(v)
                                          for k, v in rows}
    return cards


def number(text: str) -> float:
    """The number of a table cell such as ``'1,234.5 mm'`` (``'< 0.001 mm'`` → 0)."""
    if text.startswith("<"):
        return 0.0
    return float(text.split()[0].replace(",", ""))


def decode(b64, dtype):
    return np.frombuffer(base64.b64decode(b64), dtype=dtype)


def ranges_of(codes: np.ndarray) -> dict:
    """vertex_roles (half-open ranges per role) of per-vertex role codes."""
    cut = np.flatnonzero(np.diff(codes)) + 1
    starts, stops = np.r_[0, cut], np.r_[cut, len(codes)]
    out = {r: [] for r in VERTEX_ROLE_NAMES}
    for a, b in zip(starts, stops):
        out[VERTEX_ROLE_NAMES[codes[a]]].append([int(a), int(b)])
    return out


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> dict:
    """A finished wrap of the sample that excluded the eyeballs, with synthesised
    vertex_roles (left eyeball a part, right eyeball excluded) as the lead's wrap
    will write them."""
    d = tmp_path_factory.mktemp("run")
    tpl = make_template(24)
    scan = make_scan(tpl, resolution=24, texture_size=16)
    paths = write_sample(d / "in", tpl, scan)
    eyes = np.concatenate([tpl.parts["eyeball_left"], tpl.parts["eyeball_right"]])
    write_vertex_indices(d / "eyes.txt", Landmarks.from_vertices(eyes))
    job = WrapJob(template=str(paths["template"]), scan=str(paths["scan"]),
                  template_landmarks=str(paths["template_landmarks"]),
                  scan_landmarks=str(paths["scan_landmarks"]),
                  output=str(d / "wrapped.obj"), exclude=str(d / "eyes.txt"),
                  report=str(d / "run.json"))
    run_wrap_job(job, WrapSettings(model="rbf"))
    report = json.loads((d / "run.json").read_text())
    codes = np.zeros(tpl.mesh.n_vertices, dtype=np.int8)
    codes[tpl.parts["eyeball_left"]] = VERTEX_ROLE_NAMES.index("part")
    codes[tpl.parts["eyeball_right"]] = VERTEX_ROLE_NAMES.index("excluded")
    report["vertex_roles"] = ranges_of(codes)
    report["warnings"] = ["scan.obj: a warning <that> must be seen"]
    (d / "roles.json").write_text(json.dumps(report))
    return {"dir": d, "template": tpl, "scan": scan, "codes": codes, "report": report}


@pytest.fixture(scope="module")
def page(run, tmp_path_factory) -> Path:
    return build_report_page(run["dir"] / "roles.json", tmp_path_factory.mktemp("page"),
                             ground_truth=run["scan"].ground_truth)


def test_viewer_and_tables_give_the_same_fit(run, page):
    data, tables = page_data(page), table_rows(page)
    s = next(x for x in data["scalars"] if x["name"] == "distance to scan")
    metrics = tables["Metrics"]
    for key, stat in (("fit mean", "mean"), ("fit p95", "p95"), ("fit max", "max")):
        assert metrics[key].endswith(" mm")
        # the table prints four significant digits (or the resolution)
        assert number(metrics[key]) == pytest.approx(s["stats"][stat], rel=1e-3, abs=1e-3)
        assert s["stats"][stat] == pytest.approx(run["report"]["metrics"]["fit_" + stat],
                                                 rel=1e-5, abs=1e-6)
    assert s["units"] == "mm"


def test_fit_statistics_are_over_fitted_covered_vertices_only(run, page):
    # oracle: the wrapped mesh's distances to the scan, fitted and not on the border
    result = read_mesh(run["dir"] / "wrapped.obj")
    scan = read_mesh(run["dir"] / "in" / "scan.obj")
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    cp = tree.query(result.vertices)
    counted = (run["codes"] == 0) & ~tree.boundary_triangles[cp.triangles]
    s = next(x for x in page_data(page)["scalars"] if x["name"] == "distance to scan")
    values = decode(s["values"], "<f4")
    np.testing.assert_array_equal(np.isfinite(values), counted)
    assert s["stats"]["count"] == counted.sum()
    assert s["stats"]["mean"] == pytest.approx(cp.distances[counted].mean(), rel=1e-6)
    # the colour range is robust: it ends below the worst value, or at its floor of
    # ten steps of the unit's resolution when every value is rounding noise
    floor = 10.0 ** (1 - s["decimals"])
    assert s["range"][0] == 0 and s["range"][1] <= max(s["stats"]["max"], floor)


def test_parts_that_follow_are_their_own_layers(run, page):
    data = page_data(page)
    layers = {m["name"]: m for m in data["meshes"]}
    assert list(layers) == ["template (aligned)", "scan", "result", "part (follows)",
                            "excluded (follows)"]
    tpl = run["template"]
    assert layers["part (follows)"]["n_vertices"] == len(tpl.parts["eyeball_left"])
    assert layers["excluded (follows)"]["n_vertices"] == len(tpl.parts["eyeball_right"])
    # the heatmap's layer holds fitted ones only (its vertices as the glTF splits them)
    vid = decode(layers["result"]["vertex_ids"], "<u4")
    T = decode(layers["result"]["indices"], "<u4").reshape(-1, 3)
    assert T.max() == len(vid) - 1 and (run["codes"][vid[T]] == 0).all()
    assert layers["result"]["n_vertices"] == (run["codes"] == 0).sum()
    colours = {m["color"] for m in data["meshes"]}
    assert len(colours) == len(data["meshes"])
    assert all(layers[n]["visible"] for n in ("result", "part (follows)",
                                              "excluded (follows)"))
    assert table_rows(page)["Vertex roles"] == {"fitted": "1,080", "part": "42",
                                                "excluded": "42"}


def test_landmarks_are_drawn_and_the_worst_labelled(run, page):
    data = page_data(page)
    sets = {p["name"]: decode(p["positions"], "<f4").reshape(-1, 3) for p in data["points"]}
    assert list(sets) == ["landmarks: template", "landmarks: scan", "landmarks: result"]
    errors = np.linalg.norm(sets["landmarks: result"] - sets["landmarks: scan"], axis=1)
    assert errors.mean() == pytest.approx(run["report"]["metrics"]["landmark_mean"],
                                          rel=1e-3, abs=1e-4)
    assert len(data["labels"]) == 5
    worst = np.sort(errors)[::-1][:5]
    shown = [float(re.search(r": ([\d.]+) mm$", lab["text"]).group(1))
             for lab in data["labels"]]
    np.testing.assert_allclose(shown, worst, rtol=2e-3, atol=1e-3)
    rows = re.findall(r"<td class=\"txt\">([^<]*)</td><td class=\"txt\">([\d.]+ mm)</td>",
                      page.read_text())
    assert len(rows) >= 5  # the worst landmarks' table


def test_ground_truth_heatmap_agrees_with_its_table(run, page):
    data, tables = page_data(page), table_rows(page)
    s = data["scalars"][0]
    assert s["name"] == "distance to ground truth"  # shown at start
    truth = tables["Distance to ground truth (fitted vertices)"]
    assert int(truth["vertices"].replace(",", "")) == s["stats"]["count"]
    for stat in ("mean", "p95", "max"):
        assert number(truth[stat]) == pytest.approx(s["stats"][stat], rel=1e-3, abs=1e-3)
    values = decode(s["values"], "<f4")
    assert np.isnan(values[run["codes"] != 0]).all()


def test_warnings_come_first_and_not_among_the_tables(page):
    text = page.read_text()
    box = text.index('id="fw-warnings"')
    assert box < text.index("3D view") and box < text.index("<h2>Numbers</h2>")
    assert "a warning &lt;that&gt; must be seen" in text
    assert text.count("a warning &lt;that&gt; must be seen") == 1
    assert "1 warning: check the inputs" in text


# inches given to a run in millimetres: shown as given, and warned about
@pytest.mark.filterwarnings("ignore::facewrap.errors.InputWarning")
def test_units_are_the_runs_or_given(run, tmp_path):
    report = dict(run["report"], units="cm", units_source="given")
    (run["dir"] / "cm.json").write_text(json.dumps(report))
    p = build_report_page(run["dir"] / "cm.json", tmp_path / "cm")
    assert {s["units"] for s in page_data(p)["scalars"]} == {"cm"}
    tables = table_rows(p)
    assert tables["Metrics"]["fit mean"].endswith(" cm")
    assert tables["Overview"]["units"] == "cm (given)"
    p = build_report_page(run["dir"] / "cm.json", tmp_path / "in", units="in")
    assert table_rows(p)["Metrics"]["fit p95"].endswith(" in")
    # a report of an older run, without units: inferred from the result's size
    old = {k: v for k, v in run["report"].items()
           if k not in ("units", "units_source", "vertex_roles")}
    (run["dir"] / "old.json").write_text(json.dumps(old))
    p = build_report_page(run["dir"] / "old.json", tmp_path / "old")
    assert table_rows(p)["Overview"]["units"].startswith("mm (inferred")
    # ... and its job's exclude file gives the excluded vertices
    names = [m["name"] for m in page_data(p)["meshes"]]
    assert names == ["template (aligned)", "scan", "result", "excluded (follows)"]


@pytest.mark.parametrize("roles, match", [
    ({"fitted": [[0, 10]]}, "has no role"),
    ({"fitted": [[0, 2000]]}, "start < stop"),
    ({"skin": [[0, 1164]]}, "unknown role"),
])
def test_bad_vertex_roles_are_one_line_errors(run, tmp_path, roles, match, capsys):
    report = dict(run["report"], vertex_roles=roles)
    path = run["dir"] / "bad_roles.json"
    path.write_text(json.dumps(report))
    with pytest.raises(InputError, match=match):
        build_report_page(path, tmp_path / "x")
    assert facewrap("report", path, "-o", tmp_path / "y") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "bad_roles.json" in err
    assert not (tmp_path / "y").exists()


def test_cli_report_with_ground_truth_and_units(run, tmp_path, capsys):
    gt = tmp_path / "gt.npy"
    np.save(gt, run["scan"].ground_truth)
    assert facewrap("report", run["dir"] / "roles.json", "-o", tmp_path / "p",
                    "--ground-truth", gt, "--units", "cm") == 0
    p = Path(capsys.readouterr().out.strip())
    data = page_data(p)
    assert data["scalars"][0]["name"] == "distance to ground truth"
    assert data["scalars"][0]["units"] == "cm"
    np.save(gt, run["scan"].ground_truth[:10])
    assert facewrap("report", run["dir"] / "roles.json", "-o", tmp_path / "q",
                    "--ground-truth", gt) == 2
    err = capsys.readouterr().err
    assert "gt.npy" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as exc:  # argparse: one usage line, status 2
        facewrap("report", run["dir"] / "roles.json", "-o", tmp_path / "r",
                 "--units", "furlong")
    assert exc.value.code == 2 and "--units" in capsys.readouterr().err


def test_table_distances_carry_units(page):
    tables = table_rows(page)
    for key, text in tables["Metrics"].items():
        if key.startswith(("fit mean", "fit p95", "fit max", "landmark mean",
                           "landmark max")):
            assert text.endswith(" mm"), (key, text)
    assert format_distance(1.589e-14, "mm") == "< 0.001 mm"
    assert "e-1" not in " ".join(tables["Metrics"].values())


# ---------------------------------------------------------------------------------
# The same agreement in a real browser: what the colour bar prints
# ---------------------------------------------------------------------------------
from test_report_html import CHROMIUM, Browser, needs_chromium  # noqa: E402


def colour_bar_numbers(text: str) -> dict:
    """{"mean", "p95", "max", "count"} of the colour bar's line
    ``mean 1.209 mm · p95 4.099 mm · max 105.2 mm over 9805 vertices · ...``."""
    m = re.match(r"mean (.+?) (\w+) · p95 (.+?) \w+ · max (.+?) \w+ over (\d+) vertices",
                 text)
    assert m, text
    return {"mean": number(m.group(1)), "p95": number(m.group(3)),
            "max": number(m.group(4)), "count": int(m.group(5)), "unit": m.group(2)}


@needs_chromium
def test_viewer_numbers_in_headless_chromium_agree_with_the_tables(page):
    tables = table_rows(page)
    browser = Browser(CHROMIUM)
    try:
        browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        state = browser.evaluate("window.facewrapViewer")
        shown = {}
        for k, s in enumerate(page_data(page)["scalars"]):
            shown[s["name"]] = browser.evaluate(
                "(() => { const s = document.getElementById('fw-heatmap');"
                f" s.value = '{k}'; s.dispatchEvent(new Event('change'));"
                " return document.getElementById('fw-colorbar-stats').textContent; })()")
        toggled = browser.evaluate(
            "(() => { const b = document.querySelector('[data-fw-points=\"2\"]');"
            " b.checked = false; b.dispatchEvent(new Event('change'));"
            " return new Promise(r => requestAnimationFrame(() => r(Array.from("
            "document.querySelectorAll('#fw-labels .fw-label')).map(l => l.hidden))))"
            "})()")
    finally:
        browser.close()
    assert browser.errors == []
    assert state["error"] is None and state["points"] == 3 and state["labels"] == 5
    assert state["meshes"] == 5
    fit = colour_bar_numbers(shown["distance to scan"])
    assert fit["unit"] == "mm"
    for key, stat in (("fit mean", "mean"), ("fit p95", "p95"), ("fit max", "max")):
        assert fit[stat] == pytest.approx(number(tables["Metrics"][key]), rel=1e-3,
                                          abs=1e-3)
    truth = colour_bar_numbers(shown["distance to ground truth"])
    table = tables["Distance to ground truth (fitted vertices)"]
    assert truth["count"] == int(table["vertices"].replace(",", ""))
    for stat in ("mean", "p95", "max"):
        assert truth[stat] == pytest.approx(number(table[stat]), rel=1e-3, abs=1e-3)
    assert all(toggled)  # the labels go with their landmark set


@needs_chromium
def test_the_viewers_formatter_is_the_twin_of_format_distance(page):
    rng = np.random.default_rng(7)
    values = np.concatenate([10.0 ** rng.uniform(-16, 6, 200), [0.0, 1.589e-14, 0.0005,
                                                                 12345.678, -2.5]])
    browser = Browser(CHROMIUM)
    try:
        browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        shown = browser.evaluate(
            f"(() => {{ const f = window.facewrapViewer.formatDistance;"
            f" return {json.dumps(values.tolist())}.flatMap(v =>"
            f" [3, 4, 6].map(d => f(v, d))); }})()")
    finally:
        browser.close()
    want = [format_distance(v, u, with_unit=False) for v in values
            for u in ("mm", "cm", "m")]
    assert shown == want


ROLE_OF_LAYER = {"result": "fitted", "part (follows)": "part",
                 "cavity (follows)": "cavity", "excluded (follows)": "excluded",
                 "pinned (held)": "pinned"}


def viewer_and_table_counts(browser, page) -> tuple[dict, dict, dict]:
    """What the open page shows: vertices per layer in the layer list and in the 3D
    view's heading, and the "Vertex roles" table, each read from the page's DOM."""
    layers = browser.evaluate(
        "Object.fromEntries(Array.from(document.querySelectorAll('[data-fw-count]'))"
        ".map(e => [e.dataset.fwCount, e.textContent]))")
    heading = browser.evaluate(
        "Array.from(document.querySelectorAll('h2')).find(h => h.textContent"
        ".startsWith('3D view')).textContent")
    table = browser.evaluate(
        "(() => { const card = Array.from(document.querySelectorAll('section.card'))"
        ".find(c => c.querySelector('h4') && c.querySelector('h4').textContent === "
        "'Vertex roles'); return Object.fromEntries(Array.from(card.querySelectorAll("
        "'tr')).map(r => [r.cells[0].textContent, r.cells[1].textContent])); })()")
    listed = {ROLE_OF_LAYER[k]: int(v.replace(",", ""))
              for k, v in layers.items() if k in ROLE_OF_LAYER}
    headed = {ROLE_OF_LAYER[name]: int(n.replace(",", "")) for name, n in re.findall(
        r"(?:^|· |— )([a-z ()]+?) ([\d,]+) vertices", heading) if name in ROLE_OF_LAYER}
    return listed, headed, {k: int(v.replace(",", "")) for k, v in table.items()}


@needs_chromium
def test_viewer_layers_count_the_vertices_the_roles_table_counts(run, page, tmp_path):
    # besides the run's eyeballs (pieces apart), a cavity inside the skin: its layer
    # draws the triangles around it, fitted vertices of its rim included
    V = run["template"].mesh.vertices
    codes = run["codes"].copy()
    centre = np.flatnonzero(codes == 0)[np.argmin(np.linalg.norm(
        V[codes == 0] - V[codes == 0].mean(axis=0), axis=1))]
    codes[np.argsort(np.linalg.norm(V - V[centre], axis=1))[:60]] = \
        VERTEX_ROLE_NAMES.index("cavity")
    (run["dir"] / "cavity.json").write_text(json.dumps(dict(
        run["report"], vertex_roles=ranges_of(codes))))
    cavity_page = build_report_page(run["dir"] / "cavity.json", tmp_path / "cavity")
    drawn = decode(next(m for m in page_data(cavity_page)["meshes"]
                        if m["name"] == "cavity (follows)")["vertex_ids"], "<u4")
    assert (codes[drawn] == 0).any()          # the rim the old count included
    browser = Browser(CHROMIUM)
    try:
        shown = []
        for p in (page, cavity_page):
            browser.open(p.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
            shown.append(viewer_and_table_counts(browser, p))
    finally:
        browser.close()
    assert browser.errors == []
    # the oracle: the report's vertex_roles
    for (listed, headed, table), c in zip(shown, (run["codes"], codes)):
        want = {VERTEX_ROLE_NAMES[k]: int((c == k).sum()) for k in np.unique(c)}
        assert table == want and listed == want and headed == want
    assert shown[1][0]["cavity"] == 60
