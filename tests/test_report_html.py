"""The HTML report: page content, input checks, the CLI, and a real browser.

The browser test opens the page in headless Chromium (Debian's ``chromium``
package) over the DevTools protocol on a pipe (``--remote-debugging-pipe``, no
extra Python package), fails on any console error or uncaught exception, checks
that the WebGL canvas shows a model (its pixels vary) and saves a screenshot.  It
skips when no Chromium binary is found (set ``FACEWRAP_CHROMIUM`` to point at one).
"""

from __future__ import annotations

import base64
import io
import json
import os
import queue
import re
import shutil
import subprocess
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from facewrap.report.html import (COLOR_RANGE_PERCENTILE, STATIC, THREE_VERSION,
                                  write_html_report)
from facewrap.sample import make_scan, make_template


# ---------------------------------------------------------------------------------
# A tiny DevTools-protocol client over --remote-debugging-pipe
# ---------------------------------------------------------------------------------
def find_chromium() -> str | None:
    """Path of a Chromium/Chrome binary, or None."""
    env = os.environ.get("FACEWRAP_CHROMIUM")
    if env:
        return env if Path(env).exists() else None
    for name in ("chromium", "chromium-browser", "google-chrome", "chrome",
                 "headless_shell"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Browser:
    """Headless Chromium driven over the DevTools protocol on fds 3 and 4.

    Collects console errors (``console.error``/``assert``), uncaught exceptions and
    browser log entries of level ``error`` into :attr:`errors`, and the URL of
    every request the page makes into :attr:`requests`.
    """

    def __init__(self, binary: str, width: int = 1400, height: int = 1000):
        self.width, self.height = width, height
        self.profile = tempfile.mkdtemp(prefix="fw-chromium-")
        to_child_r, self._to_child = os.pipe()
        self._from_child, from_child_w = os.pipe()

        def wire():  # in the child: DevTools reads fd 3 and writes fd 4
            a, b = os.dup(to_child_r), os.dup(from_child_w)  # out of 3 and 4's way
            os.dup2(a, 3)  # dup2 makes 3 and 4 inheritable; a and b close on exec
            os.dup2(b, 4)

        args = [binary, "--headless", "--remote-debugging-pipe", "--no-sandbox",
                "--no-first-run", "--no-default-browser-check", "--mute-audio",
                "--disable-extensions", "--disable-background-networking",
                "--disable-component-update", "--disable-sync",
                "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
                "--ignore-gpu-blocklist", f"--user-data-dir={self.profile}",
                f"--window-size={width},{height}", "about:blank"]
        self.proc = subprocess.Popen(args, preexec_fn=wire, close_fds=False,
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=subprocess.DEVNULL)
        os.close(to_child_r)
        os.close(from_child_w)
        self._id = 0
        self._replies: dict[int, queue.Queue] = {}
        self.events: queue.Queue = queue.Queue()
        self.errors: list[str] = []
        self._lock = threading.Lock()
        self.requests: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()
        try:
            target = self.call("Target.createTarget", url="about:blank")["targetId"]
            self.session = self.call("Target.attachToTarget", targetId=target,
                                     flatten=True)["sessionId"]
            for method in ("Runtime.enable", "Log.enable", "Page.enable",
                           "Network.enable"):
                self.call(method, session=True)
            self.call("Emulation.setDeviceMetricsOverride", session=True, width=width,
                      height=height, deviceScaleFactor=1, mobile=False)
        except BaseException:
            self.close()
            raise

    def _read(self):
        buf = b""
        with os.fdopen(self._from_child, "rb", buffering=0) as fh:
            while chunk := fh.read(1 << 16):
                buf += chunk
                *messages, buf = buf.split(b"\0")
                for raw in messages:
                    msg = json.loads(raw)
                    if "id" in msg:
                        self._replies.setdefault(msg["id"], queue.Queue()).put(msg)
                    else:
                        self._event(msg)

    def _event(self, msg):
        method, p = msg.get("method"), msg.get("params", {})
        if method == "Runtime.consoleAPICalled" and p.get("type") in ("error", "assert"):
            text = " ".join(str(a.get("value", a.get("description", "")))
                            for a in p.get("args", []))
            self.errors.append(f"console.{p['type']}: {text}")
        elif method == "Runtime.exceptionThrown":
            d = p.get("exceptionDetails", {})
            self.errors.append("exception: " + d.get("exception", {}).get(
                "description", d.get("text", "")))
        elif method == "Network.requestWillBeSent":
            self.requests.append(p.get("request", {}).get("url", ""))
        elif method == "Log.entryAdded" and p.get("entry", {}).get("level") == "error":
            self.errors.append(f"log: {p['entry'].get('text')} {p['entry'].get('url', '')}")
        self.events.put(msg)

    def call(self, method, session=False, timeout=30.0, **params):
        with self._lock:
            self._id += 1
            mid = self._id
            self._replies.setdefault(mid, queue.Queue())
        msg = {"id": mid, "method": method, "params": params}
        if session:
            msg["sessionId"] = self.session
        os.write(self._to_child, json.dumps(msg).encode() + b"\0")
        try:
            reply = self._replies[mid].get(timeout=timeout)
        except queue.Empty:
            raise TimeoutError(f"no reply to {method} in {timeout} s") from None
        if "error" in reply:
            raise RuntimeError(f"{method}: {reply['error']}")
        return reply.get("result", {})

    def evaluate(self, expression, timeout=30.0):
        r = self.call("Runtime.evaluate", session=True, timeout=timeout,
                      expression=expression, returnByValue=True, awaitPromise=True)
        if "exceptionDetails" in r:
            raise RuntimeError(f"{expression}: {r['exceptionDetails']}")
        return r["result"].get("value")

    def open(self, url: str, ready: str, timeout: float = 30.0):
        """Navigate to ``url`` and wait until the JS expression ``ready`` is true."""
        self.call("Page.navigate", session=True, url=url)
        end = time.monotonic() + timeout
        while not self.evaluate(f"Boolean({ready})"):
            if time.monotonic() > end:
                raise TimeoutError(f"{ready} not true after {timeout} s; "
                                   f"errors: {self.errors}")
            time.sleep(0.1)
        # two more animation frames so the first WebGL frame is composited
        self.evaluate("new Promise(r => requestAnimationFrame(() => "
                      "requestAnimationFrame(() => r(true))))")

    def screenshot(self, full_page: bool = False) -> bytes:
        params = {"format": "png"}
        if full_page:
            h = self.evaluate("document.documentElement.scrollHeight")
            params.update(captureBeyondViewport=True,
                          clip={"x": 0, "y": 0, "width": self.width, "height": h,
                                "scale": 1})
        return base64.b64decode(self.call("Page.captureScreenshot", session=True,
                                          **params)["data"])

    def close(self):
        """End the browser (politely, then by force) and delete its profile."""
        try:
            self.call("Browser.close", timeout=5)
        except (RuntimeError, TimeoutError, OSError):
            pass
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        os.close(self._to_child)
        shutil.rmtree(self.profile, ignore_errors=True)


# ---------------------------------------------------------------------------------
# Inputs
# ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def sample():
    """Small sample template and scan, a stand-in 'result' and its error."""
    tpl = make_template(24)
    scan = make_scan(tpl, resolution=24, texture_size=16)
    M = scan.transform
    aligned = tpl.mesh.vertices @ M[:3, :3].T + M[:3, 3]
    truth = np.where(np.isnan(scan.ground_truth), aligned, scan.ground_truth)
    rng = np.random.default_rng(0)
    result = truth + rng.normal(scale=0.3, size=truth.shape)
    error = np.linalg.norm(result - scan.ground_truth, axis=1)  # NaN on the eyeballs
    return {"template": tpl, "scan": scan, "result": tpl.mesh.with_vertices(result),
            "error": error, "transform": M}


def _png(color=(200, 40, 40), size=(8, 6)) -> bytes:
    from PIL import Image
    buf = io.BytesIO()
    Image.new("RGB", size, color).save(buf, format="PNG")
    return buf.getvalue()


def _page_data(path: Path) -> dict:
    m = re.search(r'<script type="application/json" id="facewrap-data">(.*?)</script>',
                  path.read_text(encoding="utf-8"), re.S)
    return json.loads(m.group(1))


def _decode(b64, dtype):
    return np.frombuffer(base64.b64decode(b64), dtype=dtype)


def _write_sample_page(folder, sample, **kw):
    M = sample["transform"]
    tpl = sample["template"]
    return write_html_report(
        folder, title="Sample <wrap> & report",
        summary={"vertices": 1234, "model": "graph",
                 "warnings": ["scan.obj: 3 duplicate vertices <merged>"],
                 "metrics": {"fit_mean": 0.1234567, "fit_p95": 2.5e-5,
                             "projection": {"projected": 10, "by_method": {"prism": 9}}},
                 "iterations": [{"stage": "a", "energy": 1.5}, {"stage": "b", "fit": 2}],
                 "transform": M.tolist()},
        images=[("a red picture", _png()), ("a blue picture", _png((30, 60, 200)))],
        meshes={"scan": sample["scan"].mesh, "result": sample["result"]},
        scalars={"error to truth": ("result", sample["error"], "mm")},
        blendshapes=("result", {k: sample["result"].vertices
                                + (v - tpl.mesh.vertices) @ M[:3, :3].T
                                for k, v in tpl.blendshapes.items()}),
        view_up=M[:3, :3] @ [0, 1, 0], view_front=M[:3, :3] @ [0, 0, 1], **kw)


# ---------------------------------------------------------------------------------
# Page content (no browser)
# ---------------------------------------------------------------------------------
def test_page_is_self_contained(tmp_path, sample):
    page = _write_sample_page(tmp_path / "out", sample)
    text = page.read_text(encoding="utf-8")
    assert page == tmp_path / "out" / "index.html"
    assert [p.name for p in (tmp_path / "out").iterdir()] == ["index.html"]
    # nothing fetched: no external scripts, styles, images or module imports
    assert not re.search(r'(src|href)="(?!data:)', text)
    assert "import " not in _page_tail(text) and "http://" not in _page_tail(text)
    assert text.count("data:image/png;base64,") == 2
    assert "Sample &lt;wrap&gt; &amp; report" in text       # escaped title
    assert "<wrap>" not in text
    # numbers: formatted, nested dicts flattened, records and the matrix as tables
    assert "0.1235" in text and "2.500e-05" in text and "1,234" in text
    assert "projection › by method › prism" in text
    assert text.count('<table class="matrix">') == 1
    assert "<li>scan.obj: 3 duplicate vertices &lt;merged&gt;</li>" in text


def _page_tail(text):  # facewrap's own inline script (three.js mentions URLs in comments)
    return text[text.rindex("<script>"):]


def test_mesh_data_round_trip(tmp_path, sample):
    data = _page_data(_write_sample_page(tmp_path, sample))
    by_name = {m["name"]: m for m in data["meshes"]}
    scan = sample["scan"].mesh
    V = _decode(by_name["scan"]["positions"], "<f4").reshape(-1, 3)
    T = _decode(by_name["scan"]["indices"], "<u4").reshape(-1, 3)
    np.testing.assert_allclose(V, scan.vertices, rtol=1e-6, atol=1e-4)
    np.testing.assert_array_equal(T, scan.triangles)
    assert [m["visible"] for m in data["meshes"]] == [False, True]  # heatmap mesh only
    s = data["scalars"][0]
    values = _decode(s["values"], "<f4")
    err = sample["error"]
    np.testing.assert_array_equal(np.isnan(values), np.isnan(err))
    assert s["stats"]["missing"] == int(np.isnan(err).sum()) > 0
    # a robust colour range: 0 to the 98th percentile of the values, not the max
    assert s["range"][0] == 0 and s["range"][1] == pytest.approx(
        np.nanpercentile(err, COLOR_RANGE_PERCENTILE))
    assert s["range"][1] < np.nanmax(err)
    assert s["stats"]["count"] == int(np.isfinite(err).sum())
    # blendshapes: sparse offsets reproduce the shapes
    bs = data["blendshapes"]
    assert bs["mesh"] == "result"
    base = sample["result"].vertices
    M = sample["transform"]
    tpl = sample["template"]
    for shape in bs["shapes"]:
        idx = _decode(shape["indices"], "<u4")
        D = np.zeros_like(base)
        D[idx] = _decode(shape["deltas"], "<f4").reshape(-1, 3)
        want = (tpl.blendshapes[shape["name"]] - tpl.mesh.vertices) @ M[:3, :3].T
        np.testing.assert_allclose(D, want, atol=1e-4)
        assert 0 < len(idx) < len(base)  # local shapes are stored sparsely


def test_neutral_mesh_becomes_a_layer(tmp_path):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.]])
    T = [[0, 1, 2]]
    data = _page_data(write_html_report(
        tmp_path, meshes={"scan": (V, T)},
        blendshapes=((V, T), {"up": V + [0, 0, 1]})))
    assert [m["name"] for m in data["meshes"]] == ["scan", "blendshapes"]
    assert data["blendshapes"]["mesh"] == "blendshapes"
    assert all(m["visible"] for m in data["meshes"])


def test_a_glTF_layer_embeds_its_textures_once(tmp_path, sample):
    from facewrap.report.html import MeshLayer
    png = _png((30, 200, 30), (16, 16))
    result = sample["result"]
    fitted = np.arange(len(result.triangles)) % 2 == 0
    data = _page_data(write_html_report(tmp_path, meshes={
        "result": MeshLayer(result, fitted, {1001: png}),
        "rest": MeshLayer(result, ~fitted, {1001: png}, np.zeros(result.n_vertices, bool))}))
    # PNG bytes go in as they are, once for both layers
    assert data["textures"] == ["data:image/png;base64," + base64.b64encode(png).decode()]
    layers = {m["name"]: m for m in data["meshes"]}
    assert [g[2] for g in layers["result"]["groups"]] == [0] == [
        g[2] for g in layers["rest"]["groups"]]
    assert sum(g[1] for g in layers["result"]["groups"]) == fitted.sum()
    assert layers["rest"]["n_vertices"] == 0          # counted by its vertices
    with pytest.raises(ValueError, match=r"meshes\['x'\].triangles"):
        write_html_report(tmp_path, meshes={"x": MeshLayer(result, fitted[:3])})


def test_page_without_meshes_has_no_viewer(tmp_path):
    text = write_html_report(tmp_path, summary={"a": 1.0}).read_text()
    assert "<script" not in text and "Overview" in text


@pytest.mark.parametrize("kwargs, match", [
    ({"meshes": {"m": np.zeros((3, 2))}}, "Mesh or a"),
    ({"meshes": {"m": (np.zeros((3, 2)), [[0, 1, 2]])}}, r"m'\] vertices must be"),
    ({"meshes": {"m": (np.eye(3), [[0, 1, 3]])}}, "index outside"),
    ({"meshes": {"m": (np.eye(3), [[0, 1, 2]])}, "scalars": {"e": ("x", [1, 2, 3], "")}},
     "names mesh 'x'"),
    ({"meshes": {"m": (np.eye(3), [[0, 1, 2]])}, "scalars": {"e": ("m", [1, 2], "")}},
     r"one value per vertex"),
    ({"meshes": {"m": (np.eye(3), [[0, 1, 2]])},
      "blendshapes": ("m", {"s": np.zeros((2, 3))})}, r"blendshapes\['s'\]"),
    ({"meshes": {"m": (np.eye(3), [[0, 1, 2]])}, "visible": ["n"]}, "unknown meshes"),
    ({"images": [("x", b"GIF89a...")]}, r"images\[0\] is not a PNG"),
    ({"view_up": (0, 0, 1), "view_front": (0, 0, 2)}, "parallel"),
])
def test_bad_inputs_name_the_argument(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        write_html_report(tmp_path / "x", **kwargs)
    assert not (tmp_path / "x" / "index.html").exists()


def test_vendored_files_present():
    for name in ("three-viewer.min.js", "viewer.js", "report.css", "LICENSE-three.txt",
                 "README.md"):
        assert (STATIC / name).is_file(), name
    head = (STATIC / "three-viewer.min.js").read_text()[:40]
    assert head.startswith("var FWTHREE=")
    assert f"three@{THREE_VERSION}" in (STATIC / "README.md").read_text()


# ---------------------------------------------------------------------------------
# Real browser
# ---------------------------------------------------------------------------------
CHROMIUM = find_chromium()
needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="no chromium binary on PATH (Debian: apt-get install "
                             "chromium; or set FACEWRAP_CHROMIUM): browser test skipped")


@needs_chromium
def test_page_renders_in_headless_chromium(tmp_path, sample):
    from PIL import Image
    page = _write_sample_page(tmp_path / "page", sample)
    browser = Browser(CHROMIUM)
    try:
        browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        state = browser.evaluate("window.facewrapViewer")
        rect = browser.evaluate("(() => { const r = document.querySelector("
                                "'#fw-canvas-host canvas').getBoundingClientRect();"
                                " return [r.x, r.y, r.width, r.height]; })()")
        png = browser.screenshot()
        # move a blendshape slider and switch the heatmap off: still no errors
        browser.evaluate("(() => { const r = document.querySelector('[data-fw-shape]');"
                         " r.value = '1'; r.dispatchEvent(new Event('input'));"
                         " const s = document.getElementById('fw-heatmap');"
                         " s.value = '-1'; s.dispatchEvent(new Event('change'));"
                         " return true; })()")
        browser.evaluate("new Promise(r => requestAnimationFrame(() => r(true)))")
        png2 = browser.screenshot()
        # awkward names and a heatmap without any value must not break the page
        odd = 'scan "raw" </script><b>'
        V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]])
        T = [[0, 1, 2], [1, 3, 2]]
        page2 = write_html_report(
            tmp_path / "odd", title="</script><script>alert(1)</script>",
            meshes={odd: (V, T)}, scalars={'e "1"': (odd, [np.nan] * 4, "<mm>")},
            blendshapes=(odd, {"s'1": V + [0, 0, 1]}))
        browser.open(page2.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        browser.evaluate("(() => { const r = document.querySelector('[data-fw-shape]');"
                         " r.value = '0.5'; r.dispatchEvent(new Event('input'));"
                         " return true; })()")
        state2 = browser.evaluate("window.facewrapViewer")
    finally:
        browser.close()
    shots = tmp_path / "screenshots"
    shots.mkdir()
    (shots / "report.png").write_bytes(png)
    (shots / "report-posed.png").write_bytes(png2)
    assert browser.errors == []
    assert browser.requests and all(u.startswith(("file:", "data:")) for u in
                                    browser.requests), browser.requests  # offline
    assert state["webgl"] and state["error"] is None and state["meshes"] == 2
    assert state2["error"] is None and state2["meshes"] == 1
    x, y, w, h = (int(round(v)) for v in rect)
    assert w > 300 and h > 300
    for shot in (png, png2):
        canvas = np.asarray(Image.open(io.BytesIO(shot)).convert("RGB"))[y:y + h, x:x + w]
        # a blank canvas is one colour; a drawn head has many, and a real spread
        assert canvas.reshape(-1, 3).std(axis=0).max() > 10
        assert len(np.unique(canvas.reshape(-1, 3) // 8, axis=0)) > 50
    assert not np.array_equal(png, png2)


# ---------------------------------------------------------------------------------
# Layers drawn as their glTF: texture and smooth shading, read back from the canvas
# ---------------------------------------------------------------------------------
def _checker(size=64, cells=8) -> np.ndarray:
    """(size, size, 3) uint8: green and blue squares, colours no plain layer has."""
    yy, xx = np.mgrid[:size, :size] * cells // size
    img = np.empty((size, size, 3), np.uint8)
    img[(xx + yy) % 2 == 0] = (30, 200, 30)
    img[(xx + yy) % 2 == 1] = (30, 30, 220)
    return img


def _canvas_pixels(browser, page) -> tuple[np.ndarray, dict]:
    """(h, w, 3) float: the viewer's canvas of ``page`` as the screen shows it, and
    the viewer's state."""
    from PIL import Image
    browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
    x, y, w, h = (int(round(v)) for v in browser.evaluate(
        "(() => { const r = document.querySelector('#fw-canvas-host canvas')"
        ".getBoundingClientRect(); return [r.x, r.y, r.width, r.height]; })()"))
    shot = np.asarray(Image.open(io.BytesIO(browser.screenshot())).convert("RGB"))
    return shot[y:y + h, x:x + w].astype(np.float64), browser.evaluate("window.facewrapViewer")


def _shade_steps(canvas: np.ndarray) -> np.ndarray:
    """Luminance steps between neighbouring pixels inside the drawn head (two pixels
    in from its outline, so the silhouette against the background is not counted)."""
    from scipy import ndimage
    L = canvas @ [0.299, 0.587, 0.114]
    head = ndimage.binary_erosion(np.abs(canvas - canvas[2, 2]).max(axis=2) > 12,
                                  iterations=3)
    dx = np.abs(np.diff(L, axis=1))[head[:, 1:] & head[:, :-1]]
    dy = np.abs(np.diff(L, axis=0))[head[1:] & head[:-1]]
    return np.concatenate([dx, dy])


@needs_chromium
def test_glTF_layers_render_textured_and_smooth(tmp_path, sample):
    from facewrap.report.html import MeshLayer
    result = sample["result"]
    V, T = result.vertices, result.triangles
    M = sample["transform"]
    view = dict(view_up=M[:3, :3] @ [0, 1, 0], view_front=M[:3, :3] @ [0, 0, 1])
    pages = {
        "textured": write_html_report(tmp_path / "t", meshes={
            "result": MeshLayer(result, textures={1001: _checker()})}, **view),
        "plain": write_html_report(tmp_path / "p", meshes={"result": MeshLayer(result)},
                                   **view),
        # the control: every triangle its own vertices, so its normals are the faces'
        "faceted": write_html_report(tmp_path / "f", meshes={"result": (
            V[T].reshape(-1, 3), np.arange(3 * len(T)).reshape(-1, 3))}, **view)}
    browser = Browser(CHROMIUM)
    try:
        shown = {k: _canvas_pixels(browser, p) for k, p in pages.items()}
    finally:
        browser.close()
    canvas = {k: c for k, (c, _) in shown.items()}
    assert browser.errors == [] and all(s["error"] is None for _, s in shown.values())
    assert shown["textured"][1]["textures"] == 1 and shown["plain"][1]["textures"] == 0
    r, g, b = (canvas["textured"][..., c] for c in range(3))
    green = ((g > r + 60) & (g > b + 60)).mean()
    blue = ((b > r + 60) & (b > g + 60)).mean()
    assert green > 0.02 and blue > 0.02            # the checker's two colours show
    r, g, b = (canvas["plain"][..., c] for c in range(3))
    assert ((g > r + 60) | (b > r + 60)).mean() < 1e-3   # not without the texture
    assert np.abs(canvas["textured"] - canvas["plain"]).max(axis=2).mean() > 5
    # smooth: neighbouring pixels close in shade, where the faceted control jumps at
    # its triangles' edges (the few steps left are the eyelids' creases)
    smooth, faceted = _shade_steps(canvas["plain"]), _shade_steps(canvas["faceted"])
    assert len(smooth) > 10_000 and len(faceted) > 10_000
    assert np.percentile(smooth, 99) < 0.5 * np.percentile(faceted, 99)
    assert np.percentile(smooth, 90) < 0.75 * np.percentile(faceted, 90)
    assert (smooth > 8).mean() < 0.35 * (faceted > 8).mean()


def _with_a_seam(mesh):
    """``mesh`` with its faces of x > mean on UV tile 1002: a seam through the face."""
    from facewrap.mesh import Mesh
    right = mesh.vertices[mesh.triangles].mean(axis=1)[:, 0] > mesh.vertices[:, 0].mean()
    faces = np.asarray(mesh.triangles)
    face_uvs = faces + np.where(right, len(mesh.vertices), 0)[:, None]
    uvs = np.concatenate([mesh.vertices[:, :2], mesh.vertices[:, :2] + [1, 0]])
    uvs = (uvs - uvs.min(axis=0)) / np.ptp(uvs, axis=0) * [1.99, 0.99]
    return Mesh(mesh.vertices, faces, uvs=uvs, face_uvs=face_uvs)


@needs_chromium
def test_a_blendshape_keeps_a_textured_layer_smooth_across_its_seams(tmp_path, sample):
    from facewrap.geometry.normals import vertex_normals
    from facewrap.report.html import MeshLayer
    mesh = _with_a_seam(sample["result"])
    M, tpl = sample["transform"], sample["template"]
    name = "blink" if "blink" in tpl.blendshapes else next(iter(tpl.blendshapes))
    posed = mesh.vertices + (tpl.blendshapes[name] - tpl.mesh.vertices) @ M[:3, :3].T
    page = write_html_report(tmp_path, meshes={"result": MeshLayer(
        mesh, textures={1001: _checker(), 1002: _checker()[::-1]})},
        blendshapes=("result", {name: posed}),
        scalars={"error to truth": ("result", sample["error"], "mm")})
    layer = _page_data(page)["meshes"][0]
    vid = _decode(layer["vertex_ids"], "<u4")
    T = _decode(layer["indices"], "<u4").reshape(-1, 3)
    assert len(np.unique(vid)) < len(vid) and len(layer["groups"]) == 2  # a seam
    read = ("Array.from(window.facewrapViewer.layerOf('result').geom"
            ".getAttribute('normal').array)")
    browser = Browser(CHROMIUM)
    try:
        browser.open(page.as_uri(), "window.facewrapViewer && window.facewrapViewer.ready")
        browser.evaluate("(() => { const r = document.querySelector('[data-fw-shape]');"
                         " r.value = '1'; r.dispatchEvent(new Event('input'));"
                         " return true; })()")
        moved = np.array(browser.evaluate(read)).reshape(-1, 3)
        browser.evaluate("(() => { document.getElementById('fw-shapes-reset').click();"
                         " return true; })()")
        neutral = np.array(browser.evaluate(read)).reshape(-1, 3)
        # the heatmap replaces the textures; without it they come back
        maps = "window.facewrapViewer.layerOf('result').mats.map(m => m.map !== null)"
        looks = [browser.evaluate(maps)]
        browser.evaluate("(() => { const s = document.getElementById('fw-heatmap');"
                         " s.value = '-1'; s.dispatchEvent(new Event('change'));"
                         " return true; })()")
        looks.append(browser.evaluate(maps))
    finally:
        browser.close()
    assert browser.errors == []
    assert looks == [[False, False], [True, True]]
    # the oracle: smooth (angle-weighted) normals of the posed mesh, one per original
    # vertex, so both sides of the seam get the same
    want = vertex_normals(posed, vid[T].astype(np.int64))[vid]
    np.testing.assert_allclose(moved, want, atol=2e-4)
    assert np.abs(moved - neutral).max() > 0.05            # the shape moved them
    # back at rest: the glTF's normals again
    np.testing.assert_allclose(neutral, _decode(layer["normals"], "<f4").reshape(-1, 3),
                               atol=1e-7)
    np.testing.assert_allclose(neutral, vertex_normals(mesh.vertices, mesh.triangles)[vid],
                               atol=1e-6)
