"""The page of a wrap run (facewrap.report.page) and ``facewrap report``."""

from __future__ import annotations

import base64
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.jobs import WrapJob, run_wrap_job
from facewrap.report.page import build_report_page, load_run_report
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.wrapping import WrapSettings
from conftest import facewrap


def page_data(path: Path) -> dict:
    """The viewer's JSON block of a page."""
    m = re.search(r'<script type="application/json" id="facewrap-data">(.*?)</script>',
                  path.read_text(encoding="utf-8"), re.S)
    return json.loads(m.group(1))


@pytest.fixture(scope="module")
def run(tmp_path_factory) -> dict:
    """A finished wrap run (RBF model: quick) with blendshapes and a baked texture."""
    d = tmp_path_factory.mktemp("run")
    tpl = make_template(24)
    paths = write_sample(d / "in", tpl, make_scan(tpl, resolution=24, texture_size=64))
    job = WrapJob(template=str(paths["template"]), scan=str(paths["scan"]),
                  template_landmarks=str(paths["template_landmarks"]),
                  scan_landmarks=str(paths["scan_landmarks"]),
                  output=str(d / "wrapped.obj"), blendshapes=str(d / "in" / "blendshapes"),
                  texture=str(paths["scan_texture"]), texture_size=64,
                  gltf=str(d / "wrapped.glb"), report=str(d / "run.json"))
    run_wrap_job(job, WrapSettings(model="rbf"))
    return {"dir": d, "paths": paths, "shapes": len(tpl.blendshapes),
            "template_vertices": tpl.mesh.n_vertices}


def test_page_of_a_wrap_run(run, tmp_path):
    page = build_report_page(run["dir"] / "run.json", tmp_path / "html",
                             images=[run["paths"]["scan_texture"]], title="a run")
    assert page == tmp_path / "html" / "index.html"
    data = page_data(page)
    # the sample's eyeballs are parts: they follow, and are shown apart
    assert [m["name"] for m in data["meshes"]] == ["template (aligned)", "scan", "result",
                                                   "part (follows)"]
    assert [s["name"] for s in data["scalars"]] == ["distance to scan", "distance to result"]
    assert data["blendshapes"]["mesh"] == "result"
    assert len(data["blendshapes"]["shapes"]) == run["shapes"]
    text = page.read_text()
    assert "a run" in text and "fit mean" in text and "Timings" in text
    assert "Transform" in text
    # the baked texture (a picture and the viewer's) + the image
    assert text.count("data:image/png;base64,") == 3 and len(data["textures"]) == 1


def _glb_vertices(path) -> tuple[np.ndarray, np.ndarray, dict]:
    """The GLB's written vertices: (k, 3) original id, u, v (as the mesh has them);
    (k, 6) position and normal; and each triangle's image (pixels, None for none)
    by its sorted written vertices."""
    import pygltflib
    from PIL import Image
    doc = pygltflib.GLTF2().load(str(path))
    blob = doc.binary_blob()

    def read(i, dtype, width):
        acc = doc.accessors[i]
        view = doc.bufferViews[acc.bufferView]
        return np.frombuffer(blob, dtype, acc.count * width,
                             (view.byteOffset or 0) + (acc.byteOffset or 0)
                             ).reshape(acc.count, width).astype(np.float64)

    prims = doc.meshes[0].primitives
    a = prims[0].attributes
    uv = read(a.TEXCOORD_0, "<f4", 2) * [1, -1] + [0, 1]      # glTF stores 1 - v
    keys = np.column_stack([read(a._FACEWRAP_VERTEX, "<f4", 1), uv])
    values = np.column_stack([read(a.POSITION, "<f4", 3), read(a.NORMAL, "<f4", 3)])
    triangles = {}
    for prim in prims:
        info = doc.materials[prim.material].pbrMetallicRoughness.baseColorTexture
        image = None
        if info is not None:
            view = doc.bufferViews[doc.images[doc.textures[info.index].source].bufferView]
            image = np.asarray(Image.open(io.BytesIO(blob[view.byteOffset:view.byteOffset
                                                         + view.byteLength])))
        for t in read(prim.indices, "<u4", 1).astype(np.int64).reshape(-1, 3):
            triangles[tuple(sorted(t))] = image
    return keys, values, triangles


def glb_matches(glb_path, data: dict, names) -> dict:
    """How the page's layers ``names`` compare with the GLB: the largest position
    (in the GLB's metres: ``scale``) and normal differences of the same written
    vertex (same original id and UV), triangles showing another image than in the
    GLB, and the GLB triangles no layer draws or draws twice."""
    from scipy.spatial import cKDTree
    from PIL import Image
    keys, values, triangles = _glb_vertices(glb_path)
    # a vertex with two UV indices of one value is written twice: count it once
    keys, first, canon = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    values = values[first]
    triangles = {tuple(sorted(canon.reshape(-1)[list(t)])): im for t, im in triangles.items()}
    tree = cKDTree(keys * [100, 1, 1])      # ids apart, UVs (tiles < 100) within
    images = [np.asarray(Image.open(io.BytesIO(base64.b64decode(uri.split(",")[1]))))
              for uri in data["textures"]]
    out = {"position": 0.0, "normal": 0.0, "uv": 0.0, "other_image": 0, "drawn": []}
    for m in data["meshes"]:
        if m["name"] not in names:
            continue
        dec = (lambda key, dtype, w: np.frombuffer(base64.b64decode(m[key]), dtype)
               .reshape(-1, w).astype(np.float64))
        here = np.column_stack([dec("vertex_ids", "<u4", 1), dec("uvs", "<f4", 2)])
        gap, j = tree.query(here * [100, 1, 1])
        out["uv"] = max(out["uv"], gap.max())
        out["position"] = max(out["position"], np.abs(
            dec("positions", "<f4", 3) * data["scale"] - values[j, :3]).max())
        out["normal"] = max(out["normal"], np.abs(dec("normals", "<f4", 3)
                                                  - values[j, 3:]).max())
        T = j[dec("indices", "<u4", 3).astype(np.int64)]
        for start, count, k in m["groups"]:
            for t in T[start:start + count]:
                key = tuple(sorted(t))
                want = triangles.get(key, "missing")
                out["other_image"] += not ((want is None and k < 0) or (
                    k >= 0 and isinstance(want, np.ndarray)
                    and np.array_equal(images[k], want)))
                out["drawn"].append(key)
    out["undrawn"] = len(set(triangles) - set(out["drawn"]))
    out["twice"] = len(out["drawn"]) - len(set(out["drawn"]))
    out["glb_vertices"] = len(keys)
    return out


def test_the_viewer_draws_what_the_runs_glb_holds(run, tmp_path):
    page = build_report_page(run["dir"] / "run.json", tmp_path / "html")
    data = page_data(page)
    data["scale"] = json.loads((run["dir"] / "run.json").read_text())["gltf"]["scale"]
    seen = glb_matches(run["dir"] / "wrapped.glb", data, ("result", "part (follows)"))
    assert seen["uv"] < 1e-5                    # the same vertices, split the same
    assert seen["position"] < 1e-6 and seen["normal"] < 1e-5
    assert seen["other_image"] == 0             # each triangle shows the GLB's image
    assert seen["undrawn"] == 0 and seen["twice"] == 0
    assert seen["glb_vertices"] > run["template_vertices"]   # split at the UV seams


def test_cli_report_prints_the_page(run, tmp_path, capsys):
    assert facewrap("report", run["dir"] / "run.json", "-o", tmp_path / "html") == 0
    assert capsys.readouterr().out.strip() == str(tmp_path / "html" / "index.html")


@pytest.mark.parametrize("content, match", [
    ({"job": {"template": "nope.obj", "scan": "nope.obj", "output": "nope.obj"},
      "metrics": {}}, "nope.obj"),
    ({"metrics": {}}, "not a facewrap wrap report"),
    ("{not json", "not a JSON report"),
])
def test_bad_run_reports_are_input_errors(tmp_path, content, match):
    report = tmp_path / "run.json"
    report.write_text(content if isinstance(content, str) else json.dumps(content))
    with pytest.raises(InputError, match=match):
        build_report_page(report, tmp_path / "html")
    assert not (tmp_path / "html").exists()
    assert facewrap("report", report, "-o", tmp_path / "html") == 2


def test_load_run_report_reads_what_a_wrap_job_writes(run):
    rep = load_run_report(run["dir"] / "run.json")
    assert {"job", "settings", "metrics", "timings", "transform"} <= set(rep)



def test_a_broken_baked_image_is_refused_before_any_work(run, tmp_path, capsys):
    report = json.loads((run["dir"] / "run.json").read_text())
    good = Path(report["texture"]["image"])
    good = good if good.is_absolute() else run["dir"] / good
    broken = tmp_path / "broken.1002.png"
    broken.write_bytes(good.read_bytes()[:200])
    report["texture"]["images"].append({"image": str(broken), "tile": 1002,
                                        "materials": []})
    bad = tmp_path / "run.json"
    bad.write_text(json.dumps(dict(report, job={
        k: (str(run["dir"] / v) if k in ("template", "scan", "output") else v)
        for k, v in report["job"].items()})))
    assert facewrap("report", bad, "-o", tmp_path / "html") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "broken.1002.png" in err
    assert not (tmp_path / "html").exists()
