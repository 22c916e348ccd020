"""Expression wraps refined by texture (facewrap.rig.texture_flow, facewrap.rig.flow_match),
on the built-in sample."""

from __future__ import annotations

import dataclasses
import json
import sys
import warnings

import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.normals import vertex_normals
from facewrap.mesh import Mesh
from facewrap.params import SettingsError
from facewrap.rig import (TextureFlowSettings, build_rig, flow_matches, refine_by_texture)
from facewrap.rig.flow_match import MatchRules, TexturedSurface, face_cameras
from facewrap.sample import make_scan, make_template, write_sample
from facewrap.texture.uvs import scan_uvs_at
from facewrap.wrapping import WrapSettings, wrap
from facewrap.wrapping.roles import FITTED
from conftest import facewrap

pytest.importorskip("cv2")


@pytest.fixture(scope="module")
def tpl():
    return make_template(40)


@pytest.fixture(scope="module")
def skin(tpl):
    """The sample's procedural skin (its layout is the template's UV layout)."""
    return make_scan(tpl, weights={}, resolution=30, texture_size=512).texture


def _face_surface(tpl):
    n = len(tpl.parts["face"])
    T = tpl.mesh.triangles
    return np.flatnonzero((T < n).all(axis=1))


def _slid(tpl, du: float) -> Mesh:
    """The template itself, its texture slid along the surface: each vertex shows
    the skin of the point ``du`` further along ``u``."""
    m = tpl.mesh
    return Mesh(m.vertices, m.triangles, uvs=m.uvs[m.triangle_uvs].reshape(-1, 2)
                + [du, 0.0], face_uvs=np.arange(3 * len(m.triangles)).reshape(-1, 3))


def _matches(tpl, skin, scan, image, size=384):
    face = _face_surface(tpl)
    V, T = tpl.mesh.vertices, tpl.mesh.triangles
    seen = np.unique(T[face])
    cams = face_cameras(V[seen], vertex_normals(V, T)[seen], 1, size)
    surface = TexturedSurface.of(tpl.mesh, skin, triangles=face)
    target = TexturedSurface.of(scan, image, triangles=face)
    return flow_matches(surface, target, cams, MatchRules(max_distance=0.05),
                        size=tpl.mesh.scale())


def test_a_known_slide_of_the_texture_is_recovered(tpl, skin):
    du = 0.004                                   # about 1.4 mm along the face
    scan = _slid(tpl, du)
    m = _matches(tpl, skin, scan, skin)
    assert len(m) > 500
    # oracle: the scan point matched shows the skin the template point shows
    cp = ClosestPointTree(scan.vertices, scan.triangles).query(m.targets)
    uv_target = scan_uvs_at(scan, cp.triangles, cp.barycentric)
    T = tpl.mesh.triangles
    uv_source = _source_uvs(tpl, m)
    # (the scan shows at p the skin of uv(p) + du: the skin of p is at uv - du)
    error = np.abs(uv_target - uv_source)
    assert np.median(error[:, 0]) < 0.15 * du
    # and the points moved along the surface by about the slide: du times the
    # face's length per unit of u (from its surface and UV areas)
    face = _face_surface(tpl)
    P, U = tpl.mesh.vertices[T[face]], tpl.mesh.uvs[tpl.mesh.triangle_uvs][face]
    area = np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1).sum()
    e1, e2 = U[:, 1] - U[:, 0], U[:, 2] - U[:, 0]
    uv_area = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    expected = du * np.sqrt(area / uv_area)
    moved = np.linalg.norm(m.targets - m.sources(tpl.mesh.vertices, T), axis=1)
    assert 0.5 * expected < np.median(moved) < 2.0 * expected
    assert np.all((m.confidence > 0) & (m.confidence <= 1))


def _source_uvs(tpl, m) -> np.ndarray:
    """(k, 2) template texture coordinates of each match's template point."""
    return np.einsum("kj,kjd->kd", m.barycentric,
                     tpl.mesh.uvs[tpl.mesh.triangle_uvs][m.triangle])


def test_matches_on_a_texture_that_differs_are_rejected(tpl, skin):
    """Where the scan's skin is other skin (a patch of unrelated texture) the
    forward-backward test and the distance test leave few matches."""
    image = skin.copy()
    h, w = image.shape[:2]
    rows, cols = (int(0.55 * h), int(0.75 * h)), (int(0.4 * w), int(0.6 * w))
    image[rows[0]:rows[1], cols[0]:cols[1]] = np.random.default_rng(3).integers(
        0, 255, (rows[1] - rows[0], cols[1] - cols[0], 3), dtype=np.uint8)

    def in_patch(m):
        uv = _source_uvs(tpl, m)
        r, c = (1 - uv[:, 1]) * h, uv[:, 0] * w
        return np.count_nonzero((r > rows[0]) & (r < rows[1]) & (c > cols[0]) & (c < cols[1]))

    scan = _slid(tpl, 0.0)
    corrupted, clean = _matches(tpl, skin, scan, image), _matches(tpl, skin, scan, skin)
    assert in_patch(clean) > 100
    assert in_patch(corrupted) < 0.3 * in_patch(clean)
    assert corrupted.rejected["consistency"] > clean.rejected["consistency"]


def _tangential(V, truth, T, mask):
    N = vertex_normals(np.nan_to_num(truth), T)
    d = V - truth
    t = d - np.einsum("ij,ij->i", d, N)[:, None] * N
    return float(np.linalg.norm(t, axis=1)[mask].mean())


@pytest.fixture(scope="module")
def brow(tpl):
    """A brow raise (the forehead's skin slides up), wrapped by geometry alone."""
    scan = make_scan(tpl, weights={"brow_raise": 1.0}, resolution=70, texture_size=512,
                     seed=2)
    w = wrap(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
             WrapSettings(model="hybrid"), blendshapes=tpl.blendshapes)
    return scan, w


def test_the_refinement_cuts_the_tangential_error(tpl, brow):
    scan, w = brow
    mask = (w.roles == FITTED) & np.isfinite(scan.ground_truth).all(axis=1) \
        & w.projection.projected
    T = tpl.mesh.triangles
    # the reference is the skin's own image in the template's layout (the sample's
    # template UVs are its parameters): the truth is what the texture shows
    r = refine_by_texture(tpl.mesh, w.vertices, scan.texture, scan.mesh, scan.texture,
                          movable=w.roles == FITTED, on_scan=w.projection.projected)
    before = _tangential(w.vertices, scan.ground_truth, T, mask)
    after = _tangential(r.vertices, scan.ground_truth, T, mask)
    assert r.rounds and r.rounds[0]["kept"]
    assert after < 0.8 * before
    assert np.array_equal(r.vertices[w.roles != FITTED], w.vertices[w.roles != FITTED])


def test_a_texture_that_says_nothing_leaves_the_wrap_as_it_is(tpl, brow):
    scan, w = brow
    other = np.random.default_rng(5).integers(0, 255, scan.texture.shape, dtype=np.uint8)
    r = refine_by_texture(tpl.mesh, w.vertices, scan.texture, scan.mesh, other,
                          movable=w.roles == FITTED)
    assert not any(x["kept"] for x in r.rounds)
    assert np.array_equal(r.vertices, w.vertices) and r.moved == 0.0


def test_settings_are_checked_at_the_door():
    assert TextureFlowSettings().enabled
    for field, value in (("rounds", 0), ("method", "lucas"), ("views", 6),
                         ("max_angle", 90.0), ("enabled", "yes"), ("min_gain", 1.0)):
        with pytest.raises(SettingsError, match=f"TextureFlowSettings.{field}"):
            TextureFlowSettings(**{field: value})
    small = make_template(24)
    with pytest.raises(ValueError, match="vertices must have shape"):
        refine_by_texture(small.mesh, np.zeros((3, 3)), None, None, None)
    bare = Mesh(small.mesh.vertices, small.mesh.triangles)
    image = np.zeros((8, 8, 3), np.uint8)
    with pytest.raises(ValueError, match="scan_image must be an"):
        refine_by_texture(small.mesh, small.mesh.vertices, image, bare, None)
    with pytest.raises(ValueError, match="scan has no texture coordinates"):
        refine_by_texture(small.mesh, small.mesh.vertices, image, bare, image)


def test_the_match_rules_have_one_home():
    """A refinement's settings are its match rules: the fields, defaults and checks
    of MatchRules, and a settings object passes as the rules themselves."""
    rules = {f.name: f.default for f in dataclasses.fields(MatchRules)}
    s = TextureFlowSettings(method="farneback", max_distance=0.05)
    assert isinstance(s, MatchRules) and (s.method, s.max_distance) == ("farneback", 0.05)
    assert {k: getattr(TextureFlowSettings(), k) for k in rules} == rules
    assert all(TextureFlowSettings.constraints[k] == c
               for k, c in MatchRules.constraints.items())
    with pytest.raises(SettingsError, match="MatchRules.max_distance"):
        MatchRules(max_distance=2.0)          # a fraction of the size, not a length
    with pytest.raises(SettingsError, match="TextureFlowSettings.step"):
        TextureFlowSettings(step=0)


@pytest.fixture(scope="module")
def person():
    tpl = make_template(24)
    neutral = make_scan(tpl, weights={}, resolution=40, texture_size=256, seed=1)
    smile = make_scan(tpl, weights={"smile": 1.0}, resolution=40, texture_size=256, seed=2)
    return tpl, neutral, smile


def _rig(person, **kw):
    tpl, neutral, smile = person
    kw.setdefault("expression_textures", [smile.texture])
    return build_rig(tpl.mesh, neutral.mesh, tpl.landmarks, neutral.landmarks,
                     tpl.blendshapes, expression_scans=[smile.mesh],
                     expression_landmarks=[smile.landmarks], texture=neutral.texture, **kw)


@pytest.mark.slow
def test_build_rig_refines_textured_expressions_unless_told_not_to(person):
    on = _rig(person)
    off = _rig(person, texture_flow=TextureFlowSettings(enabled=False))
    assert on.texture_refinements[0] is not None and "texture_flow" in on.timings
    assert off.texture_refinements == [None] and "texture_flow" not in off.timings
    with pytest.raises(ValueError, match="1 expression scans but 2 expression_textures"):
        _rig(person, expression_textures=[None, None])


def test_without_opencv_one_warning_names_the_extra(person, monkeypatch):
    monkeypatch.setitem(sys.modules, "cv2", None)      # import cv2 -> ImportError
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rig = _rig(person)
    said = [str(w.message) for w in caught if "texture refinement" in str(w.message)]
    assert len(said) == 1 and "facewrap[flow]" in said[0] and "\n" not in said[0]
    assert rig.texture_refinements == [None] and rig.examples is not None


@pytest.mark.slow
def test_the_command_line_flag_turns_it_off(tmp_path, person):
    tpl, neutral, smile = person
    n = write_sample(tmp_path / "neutral", tpl, neutral)
    x = write_sample(tmp_path / "smile", tpl, smile)
    base = ["rig", n["scan"], x["scan"], "--template", n["template"], "--blendshapes",
            tmp_path / "neutral" / "blendshapes", "--template-landmarks",
            n["template_landmarks"], "--scan-landmarks", n["scan_landmarks"],
            "--expression-landmarks", x["scan_landmarks"], "--texture", n["scan_texture"],
            "--expression-textures", x["scan_texture"], "--texture-size", 64, "-q"]
    assert facewrap(*base, "-o", tmp_path / "on") == 0
    assert facewrap(*base, "--no-texture-flow", "-o", tmp_path / "off") == 0
    on = json.loads((tmp_path / "on" / "rig.json").read_text())["examples"][0]
    off = json.loads((tmp_path / "off" / "rig.json").read_text())["examples"][0]
    assert on["texture_flow"]["seconds"] > 0 and off["texture_flow"] is None
    assert facewrap(*base, "--expression-textures", x["scan_texture"], n["scan_texture"],
                    "-o", tmp_path / "bad") == 2
    assert not (tmp_path / "bad").exists()


def test_a_job_file_turns_it_off_in_outputs(tmp_path):
    from facewrap.errors import InputError
    from facewrap.jobs.jobfile import load_job
    text = ('[inputs]\ntemplate = "t.obj"\nscan = "s.obj"\nblendshapes = "b"\n'
            'expression_scans = ["x.obj"]\nexpression_textures = ["x.png"]\n'
            '[outputs]\noutput = "out"\ntexture_flow = {}\n[rig]\nmodel = "hybrid"\n')
    path = tmp_path / "rig.toml"
    path.write_text(text.format("false"))
    job, _ = load_job(path)
    assert job.texture_flow is False and job.expression_textures == [str(tmp_path / "x.png")]
    path.write_text(text.format('"no"'))
    with pytest.raises(InputError, match="texture_flow"):
        load_job(path)


@pytest.mark.slow
def test_refinements_beside_the_wraps_give_the_rig_they_give_one_after_another(
        person, monkeypatch):
    """Two textured expressions: the bake and the refinements run on a thread beside
    the wraps, or here with one usable thread; the rig is the same either way."""
    import facewrap.rig.build as build
    tpl, neutral, smile = person
    kw = dict(expression_scans=[smile.mesh, smile.mesh],
              expression_landmarks=[smile.landmarks, smile.landmarks],
              expression_textures=[smile.texture, smile.texture], texture=neutral.texture)
    args = (tpl.mesh, neutral.mesh, tpl.landmarks, neutral.landmarks, tpl.blendshapes)
    beside = build_rig(*args, **kw)
    monkeypatch.setattr(build, "usable_threads", lambda: 1)
    alone = build_rig(*args, **kw)
    assert all(r is not None for r in beside.texture_refinements)
    for a, b in zip(beside.expression_wraps, alone.expression_wraps):
        np.testing.assert_allclose(a.vertices, b.vertices, rtol=0, atol=1e-9)
    np.testing.assert_allclose(beside.neutral.vertices, alone.neutral.vertices, atol=1e-9)
    for name in beside.shapes:
        np.testing.assert_allclose(beside.shapes[name], alone.shapes[name], atol=1e-9)
    assert {"texture", "texture_flow"} <= set(beside.timings)

    def broken(*a, **k):
        raise ValueError("no bake")
    monkeypatch.setattr(build, "usable_threads", lambda: 2)
    monkeypatch.setattr(build, "bake_tiles", broken)
    with pytest.raises(ValueError, match="no bake"):
        build_rig(*args, **kw)


def test_an_interrupt_during_the_expression_wraps_leaves_no_thread_running(
        person, monkeypatch):
    """Ctrl-C while an expression wraps and a refinement runs beside it: the
    interrupt reaches the caller and no thread of the rig is left running (the
    refinements not begun are dropped)."""
    import threading

    import facewrap.rig.build as build
    tpl, neutral, smile = person
    monkeypatch.setattr(build, "usable_threads", lambda: 2)
    real_wrap = build.wrap_following
    calls = []

    def interrupted(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:        # the first expression's refinement is under way
            raise KeyboardInterrupt
        return real_wrap(*args, **kwargs)
    monkeypatch.setattr(build, "wrap_following", interrupted)
    with pytest.raises(KeyboardInterrupt):
        build_rig(tpl.mesh, neutral.mesh, tpl.landmarks, neutral.landmarks,
                  tpl.blendshapes, expression_scans=[smile.mesh] * 3,
                  expression_landmarks=[smile.landmarks] * 3,
                  expression_textures=[smile.texture] * 3, texture=neutral.texture)
    assert len(calls) == 2
    assert not [t for t in threading.enumerate() if t.name.startswith("facewrap-beside")]
