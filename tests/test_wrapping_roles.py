"""What a scanner sees of a template, the roles of its vertices, and how parts follow."""

import json

import numpy as np
import pytest

from conftest import DATA, needs_data
from facewrap.geometry import flipped_triangles, sphere_directions
from facewrap.geometry.visibility import outside_views
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh
from facewrap.sample import make_scan, make_template
from facewrap.wrapping import WrapSettings, wrap
from facewrap.wrapping.follow import follow_skin, side_changes
from facewrap.geometry import folded_in
from facewrap.wrapping.unfold import relax_flips
from facewrap.wrapping import roles
from facewrap.wrapping.roles import (CAVITY, EXCLUDED, FITTED, PART, PINNED, VERTEX_ROLES,
                                     cached_hidden_surface, find_hidden_surface,
                                     role_counts, role_ranges, vertex_roles)

ICT = DATA / "ict-facekit" / "FaceXModel"


def _ball(radius: float = 1.0, center=(0.0, 0.0, 0.0), subdivisions: int = 3):
    """A closed, outward-facing icosphere (vertices, triangles)."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return np.asarray(m.vertices) + np.asarray(center), np.asarray(m.faces, np.int64)


def _with(*pieces):
    """Pieces (V, T) as one mesh."""
    V = np.vstack([p[0] for p in pieces])
    offsets = np.cumsum([0] + [len(p[0]) for p in pieces[:-1]])
    return V, np.vstack([p[1] + o for p, o in zip(pieces, offsets)])


def test_sphere_directions_cover_the_sphere_evenly():
    D = sphere_directions(256)
    # every direction of a finer set has a close neighbour: no side is left out
    fine = sphere_directions(4000)
    assert np.degrees(np.arccos(np.clip((fine @ D.T).max(axis=1), -1, 1))).max() < 12


def test_outside_views_a_ball_is_seen_a_ball_inside_it_is_not():
    V1, T1 = _ball()
    V2, T2 = _ball(0.3, subdivisions=2)
    V, T = _with((V1, T1), (V2, T2))
    seen = outside_views(V, T)
    assert seen[:len(V1)].all() and not seen[len(V1):].any()
    # without the outer box in the way the inner one is seen
    assert outside_views(V, T, occluders=np.r_[np.zeros(len(T1), bool),
                                              np.ones(len(T2), bool)])[len(V1):].all()


def test_hidden_surface_of_a_head_with_a_part_inside_and_a_pit():
    """A ball head with a ball inside (an eyeball) and a deep pit (a nostril)."""
    V1, T1 = _ball(subdivisions=4)
    top = np.flatnonzero(V1[:, 2] > 0.995)         # the vertices around the pole
    V1[top, 2] = 0.2                               # pushed deep: a narrow pit
    V2, T2 = _ball(0.2, subdivisions=2)
    V, T = _with((V1, T1), (V2, T2))
    h = find_hidden_surface(V, T)
    assert h.part[len(V1):].all() and not h.part[:len(V1)].any()
    assert h.skin_pieces == 1
    assert h.cavity[top].all() and h.cavity.sum() == len(top)
    # the same head turned inside out is read the other way round
    flipped = find_hidden_surface(V, T[:, ::-1])
    assert np.array_equal(flipped.part, h.part)
    assert np.array_equal(flipped.cavity, h.cavity)


def _cap(radius: float, polar_max: float, rings: int, segments: int):
    """A spherical cap about +z (polar angle up to ``polar_max`` degrees), facing out."""
    th = np.radians(np.linspace(0, polar_max, rings + 1)[1:])
    ph = np.linspace(0, 2 * np.pi, segments, endpoint=False)
    P = np.vstack([[0, 0, 1.0], np.stack([np.outer(np.sin(th), np.cos(ph)),
                                          np.outer(np.sin(th), np.sin(ph)),
                                          np.repeat(np.cos(th)[:, None], segments, 1)],
                                         -1).reshape(-1, 3)])
    j = np.arange(segments)
    T = [np.c_[np.zeros(segments, int), 1 + j, 1 + (j + 1) % segments]]
    for r in range(rings - 1):
        a, b = 1 + r * segments + j, 1 + (r + 1) * segments + j
        a1, b1 = 1 + r * segments + (j + 1) % segments, 1 + (r + 1) * segments + (j + 1) % segments
        T += [np.c_[a, b, b1], np.c_[a, b1, a1]]
    return P * radius, np.vstack(T)


def test_a_mouth_bag_of_its_own_glimpsed_through_the_lips_is_a_part():
    """A face mask with an open mouth and, behind it, a bag of its own as large as a
    sixth of the face: seen from a few directions through the mouth only, it is a
    part (it was taken for skin, and pulled onto the scan's lips); the two halves
    of a face split down the middle stay skin."""
    V1, T1 = _cap(60.0, 80, 30, 64)
    C = V1[T1].mean(axis=1)
    T1 = T1[~((np.abs(C[:, 0]) < 20) & (np.abs(C[:, 1] + 20) < 6) & (C[:, 2] > 0))]
    V2, T2 = _cap(24.0, 100, 12, 32)
    V2 = V2 * [1, 0.5, -1] + [0, -20, 40]      # opening toward the mouth, facing in
    V, T = _with((V1, T1), (V2, T2))
    h = find_hidden_surface(V, T)
    assert h.part[len(V1):].all() and h.skin_pieces == 1
    used = np.isin(np.arange(len(V1)), T1)
    assert not h.part[:len(V1)][used].any()
    # the mask cut in two along x = 0 (its vertices there split): two skin pieces
    left = V1[T1].mean(axis=1)[:, 0] < 0
    W = np.vstack([V1, V1])
    halves = np.vstack([T1[left], T1[~left] + len(V1)])
    split = find_hidden_surface(W, halves)
    assert split.skin_pieces == 2


def test_hidden_surface_of_the_sample_eyeballs_are_parts():
    t = make_template(resolution=40)
    h = find_hidden_surface(t.mesh.vertices, t.mesh.triangles)
    eyes = np.concatenate([t.parts["eyeball_left"], t.parts["eyeball_right"]])
    assert h.part[eyes].all() and h.part.sum() == len(eyes)
    assert h.cavity.mean() < 0.05


@pytest.fixture
def counted_views(tmp_path, monkeypatch):
    """A private disk cache, an empty in-process cache, and a count of the calls of
    the line-casting function (:func:`outside_views`) that finding a hidden surface
    makes."""
    monkeypatch.setenv("FACEWRAP_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("FACEWRAP_CACHE", raising=False)
    calls = []

    def counting(*args, **kwargs):
        calls.append(1)
        return outside_views(*args, **kwargs)

    monkeypatch.setattr(roles, "outside_views", counting)
    cached_hidden_surface.clear()
    yield calls
    cached_hidden_surface.clear()


def _head_with_eye():
    return _with(_ball(subdivisions=3), _ball(0.2, subdivisions=1))


def _same(a, b) -> bool:
    return (np.array_equal(a.part, b.part) and np.array_equal(a.cavity, b.cavity)
            and a.skin_pieces == b.skin_pieces)


def test_hidden_surface_is_found_once_per_template_content_on_disk(counted_views, tmp_path):
    V, T = _head_with_eye()
    first = cached_hidden_surface(V, T)
    cast = len(counted_views)
    assert cast > 0 and list((tmp_path / "cache").glob("hidden-surface-*.npz"))
    cached_hidden_surface.clear()          # as a fresh process: only the disk remembers
    again = cached_hidden_surface(V, T)
    assert len(counted_views) == cast and _same(again, first)
    assert _same(again, find_hidden_surface(V, T))
    # another template (one vertex moved) is found anew, and kept beside the first
    moved = V.copy()
    moved[0] *= 1.01
    cached_hidden_surface(moved, T)
    assert len(counted_views) > cast
    assert len(list((tmp_path / "cache").glob("hidden-surface-*.npz"))) == 2


def test_hidden_surface_corrupt_entry_is_found_again(counted_views, tmp_path):
    V, T = _head_with_eye()
    first = cached_hidden_surface(V, T)
    cast = len(counted_views)
    for entry in (tmp_path / "cache").glob("hidden-surface-*.npz"):
        entry.write_bytes(entry.read_bytes()[:40])        # truncated
    cached_hidden_surface.clear()
    again = cached_hidden_surface(V, T)
    assert len(counted_views) > cast and _same(again, first)
    # ... and stored whole again: the next process reads it
    cached_hidden_surface.clear()
    cast = len(counted_views)
    assert _same(cached_hidden_surface(V, T), first) and len(counted_views) == cast


def test_hidden_surface_entry_of_another_size_is_not_used(counted_views, tmp_path):
    V, T = _head_with_eye()
    cached_hidden_surface(V, T)
    import zipfile
    (entry,) = (tmp_path / "cache").glob("hidden-surface-*.npz")
    with np.load(entry) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["part"] = arrays["part"][:-1]                 # an entry that cannot be this one
    with open(entry, "wb") as f:
        np.savez(f, **arrays)
    assert zipfile.is_zipfile(entry)
    cached_hidden_surface.clear()
    cast = len(counted_views)
    assert len(cached_hidden_surface(V, T).part) == len(V) and len(counted_views) > cast


def test_hidden_surface_cache_off_computes_and_writes_nothing(counted_views, tmp_path,
                                                              monkeypatch):
    monkeypatch.setenv("FACEWRAP_CACHE", "0")
    V, T = _head_with_eye()
    first = cached_hidden_surface(V, T)
    cast = len(counted_views)
    cached_hidden_surface.clear()
    assert _same(cached_hidden_surface(V, T), first)
    assert len(counted_views) == 2 * cast
    assert not (tmp_path / "cache").exists()


def test_vertex_roles_priorities_and_ranges():
    n = 8
    h = type("H", (), {})()
    from facewrap.wrapping.roles import HiddenSurface
    h = HiddenSurface(part=np.r_[np.zeros(6, bool), [True, True]],
                      cavity=np.r_[[False, True], np.zeros(6, bool)], skin_pieces=1)
    roles = vertex_roles(n, h, exclude=[2, 6], pinned=[3])
    assert roles.tolist() == [FITTED, CAVITY, EXCLUDED, PINNED, FITTED, FITTED, PART, PART]
    ranges = role_ranges(roles)
    assert set(ranges) == set(VERTEX_ROLES)
    back = np.empty(n, np.int8)
    for name, rs in ranges.items():
        for a, b in rs:
            back[a:b] = VERTEX_ROLES.index(name)
    assert np.array_equal(back, roles)
    assert sum(role_counts(roles).values()) == n
    # a fit mask decides which vertices are pulled, even a cavity; parts outside it
    # still follow as parts, the rest are left out
    assert vertex_roles(n, h, fit_mask=[0, 1]).tolist() == [FITTED] * 2 + [EXCLUDED] * 4 + [PART] * 2
    assert vertex_roles(n, h, fit_mask=[0, 1, 6], exclude=[1]).tolist() == \
        [FITTED, CAVITY, EXCLUDED, EXCLUDED, EXCLUDED, EXCLUDED, FITTED, PART]
    with pytest.raises(ValueError, match="exclude"):
        vertex_roles(n, h, exclude=[8])
    with pytest.raises(ValueError, match="fit_mask"):
        vertex_roles(n, h, fit_mask=np.ones(3, bool))


@pytest.fixture(scope="module")
def sample():
    template = make_template(resolution=40)
    return template, make_scan(template, resolution=60)


def test_wrap_sample_eyeballs_follow_and_are_left_out_of_the_metrics(sample):
    template, scan = sample
    r = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
             WrapSettings(model="graph"))
    eyes = np.concatenate([template.parts["eyeball_left"], template.parts["eyeball_right"]])
    assert (r.roles[eyes] == PART).all()
    aligned = r.transform.apply(template.mesh.vertices)
    assert not side_changes(template.mesh.triangles, aligned, r.vertices, r.roles).any()
    assert r.metrics["finish"]["pinned"] == 0
    # fit_hidden pulls them too: every vertex is fitted
    everything = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
                      WrapSettings(model="rbf", fit_hidden=True))
    assert (everything.roles == FITTED).all()


def test_pinned_vertices_stay_where_the_similarity_puts_them(sample):
    template, scan = sample
    face = template.parts["face"]
    pins = face[:200]
    r = wrap(template.mesh, scan.mesh, template.landmarks, scan.landmarks,
             WrapSettings(model="graph"), pinned=pins)
    aligned = r.transform.apply(template.mesh.vertices)
    assert np.allclose(r.vertices[pins], aligned[pins], atol=1e-9 * template.mesh.scale()
                       * r.transform.scale)
    assert (r.roles[pins] == PINNED).all() and r.metrics["finish"]["pinned"] == 200
    free = np.setdiff1d(face, pins)
    assert np.abs(r.vertices[free] - aligned[free]).max() > 1e-3


def test_relax_flips_unfolds_a_pushed_vertex_and_keeps_fixed_ones():
    g = np.stack(np.meshgrid(np.arange(6.0), np.arange(6.0)), -1).reshape(-1, 2)
    V = np.c_[g, np.zeros(36)]
    quads = [i for i in range(29) if i % 6 < 5]
    T = np.array([[i, i + 1, i + 7] for i in quads] + [[i, i + 7, i + 6] for i in quads])
    fit = V.copy()
    fit[14] = [3.7, 3.7, 0.0]                      # over its neighbours: folds
    assert flipped_triangles(fit, V, T).any()
    out, moved = relax_flips(Mesh(V, T), V, fit, fixed=np.isin(np.arange(36), [0, 35]))
    assert not flipped_triangles(out, V, T).any()
    assert moved[14] and not moved[[0, 35]].any()
    assert np.array_equal(out[~moved], fit[~moved])


def test_folded_in_finds_a_triangle_inside_out():
    g = np.stack(np.meshgrid(np.arange(3.0), np.arange(3.0)), -1).reshape(-1, 2)
    V = np.c_[g, np.zeros(9)]
    T = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [3, 4, 7], [3, 7, 6],
                  [4, 5, 8], [4, 8, 7]])
    T[3] = T[3][::-1]                              # inside out among its neighbours
    from facewrap.geometry import face_normals
    assert np.flatnonzero(folded_in(face_normals(V, T), T)).tolist() == [3]


def test_follow_skin_keeps_a_part_behind_skin_that_came_towards_it():
    V1, T1 = _ball(subdivisions=4)
    V2, T2 = _ball(0.15, center=(0.0, 0.0, 0.75), subdivisions=2)   # behind the +z cap
    V, T = _with((V1, T1), (V2, T2))
    roles = np.r_[np.zeros(len(V1), np.int8), np.full(len(V2), PART, np.int8)]
    fit = V.copy()
    cap = V1[:, 2] > 0.6
    fit[:len(V1)][cap, 2] = 0.6 + 0.5 * (V1[cap, 2] - 0.6)    # the cap flattens inwards
    assert side_changes(T, V, fit, roles).any()               # left as it was: through
    out = follow_skin(T, V, fit, roles)
    assert not side_changes(T, V, out, roles).any()
    assert np.array_equal(out[:len(V1)], fit[:len(V1)])       # the skin is not touched
    assert not flipped_triangles(out, V, T)[len(T1):].any()   # nor the part dented


@needs_data
@pytest.mark.slow
def test_ict_full_head_onto_james_parts_stay_behind_the_skin(tmp_path):
    """Issue 17: ICT's full head onto the james scan with landmarks only."""
    from facewrap.io import read_mesh
    from facewrap.io.landmarks import read_ljson
    from facewrap.io.profile import read_template_profile
    head = read_mesh(ICT / "generic_neutral_mesh.obj")
    prof = read_template_profile(ICT / "vertex_indices.json")
    scan = read_mesh(DATA / "scans" / "james" / "james.obj")
    lm = read_ljson(DATA / "scans" / "james" / "james.ljson")
    fitting = np.zeros(head.n_vertices, bool)
    fitting[prof.fitting] = True
    # as `facewrap wrap` does with the profile found beside the template
    r = wrap(head, scan, prof.landmarks, lm, WrapSettings(model="graph"), exclude=~fitting)
    counts = {name: int((r.roles == i).sum()) for i, name in enumerate(VERTEX_ROLES)}
    # ICT's parts table: 14,062 skin vertices (with the sockets), the rest parts
    assert counts["part"] == 26719 - 14062
    assert 2800 <= counts["cavity"] <= 4500          # the mouth and eye sockets at least
    assert counts["fitted"] + counts["cavity"] + counts["excluded"] == 14062
    aligned = r.transform.apply(head.vertices)
    assert not side_changes(head.triangles, aligned, r.vertices, r.roles).any()
    inside = fitting[head.triangles].all(axis=1)
    assert flipped_triangles(r.vertices, aligned, head.triangles)[inside].sum() <= 1


@pytest.mark.parametrize("model", ["graph", "hybrid"])
def test_a_part_inside_the_head_does_not_change_the_skins_fit(sample, model):
    """The parts follow the skin at the end, so the skin's fit must not depend on
    them.  They moved the fit's frame and the pose's pivot, and as nodes of the
    deformation graph, tied to the nearest skin nodes, a part held those nodes
    together like a strut (a tongue between the lips; ICT's head opening its jaw,
    bench_heads), and the fold repairs counted their triangles: a ball inside the
    sample head moved its fit by 0.2 mm and its result by up to 10 mm."""
    template, scan = sample
    m = template.mesh
    lo, hi = m.vertices.min(axis=0), m.vertices.max(axis=0)
    ball = _ball(0.03 * float(np.linalg.norm(hi - lo)), 0.5 * (lo + hi), subdivisions=2)
    n = m.n_vertices
    # the sample's own polygons (quads) and the ball's triangles
    dressed = Mesh(np.vstack([m.vertices, ball[0]]),
                   list(m.polygons()) + [f + n for f in ball[1]])
    shapes = {k: np.vstack([v, ball[0]]) for k, v in template.blendshapes.items()}
    runs = [wrap(t, scan.mesh, template.landmarks, scan.landmarks, WrapSettings(model=model),
                 blendshapes=s if model == "hybrid" else None)
            for t, s in ((m, template.blendshapes), (dressed, shapes))]
    assert (runs[1].roles[n:] == PART).all()
    # the fit itself, and the result after the projection and the fold repairs
    tolerance = 1e-6 * m.scale() * runs[0].transform.scale
    for field in ("warped", "vertices"):
        moved = np.linalg.norm(getattr(runs[1], field)[:n] - getattr(runs[0], field), axis=1)
        assert moved.max() < tolerance, field


def test_follow_skin_starts_the_parts_from_the_pose_the_blend_weights_made():
    """A jaw opened by a shape drops the tooth under a skin patch that stays where it
    was: the tooth stays dropped (from the neutral, the still patch held it up)."""
    g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    skin = np.c_[g, np.zeros(25)]
    T = np.array([[i, i + 1, i + 6] for i in range(19) if i % 5 < 4]
                 + [[i, i + 6, i + 5] for i in range(19) if i % 5 < 4])
    R = np.vstack([skin, [[2.0, 2.0, -0.5]]])
    roles = np.r_[np.zeros(25, np.int8), [PART]].astype(np.int8)
    rest = R.copy()
    rest[25] = [2.0, 2.0, -1.5]                          # the shape dropped the tooth
    fit = rest.copy()
    fit[:25, 2] += 0.25                                  # the skin a little beyond it
    out = follow_skin(T, R, fit, roles, start=rest)
    np.testing.assert_allclose(out[25], [2.0, 2.0, -1.25], atol=1e-6)
    assert follow_skin(T, R, fit, roles)[25, 2] > -0.5   # from the neutral: held up


@needs_data
@pytest.mark.parametrize("expression", [{"eyeBlink_L": 1.0}, {"jawOpen": 0.8},
                                        {"jawOpen": 0.6, "mouthSmile_L": 1.0}])
def test_ict_parts_follow_its_own_shapes_onto_a_face_of_them(ict_folder, expression):
    """ICT's full head (hybrid, four of its shapes) onto a face its shapes make:
    the teeth where ICT's shapes put them (before: the lips carried them, 7-8 mm
    off on average with the jaw open) and no part through the closed eyelid
    (before: 5 vertices, the put-back at the lid's thin edge crossing it)."""
    from facewrap.datasets import ICTFaceKit
    from facewrap.geometry.similarity import similarity_transform
    from facewrap.wrapping.follow import side_changes
    kit = ICTFaceKit(ict_folder)
    head = kit.neutral
    V0 = head.vertices
    shapes = {n: np.asarray(kit.shape(n))
              for n in ("jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L")}
    truth = np.asarray(kit.shape("identity000")) + sum(
        w * (shapes[k] - V0) for k, w in expression.items())
    face = kit.part_mesh("face")
    n = face.n_vertices
    ids = np.asarray(kit.indices["idx_to_landmark_verts"])
    r = wrap(head, Mesh(10 * truth[:n], face.triangles), Landmarks.from_vertices(ids),
             Landmarks.from_points(10 * truth[ids]), WrapSettings(model="hybrid"),
             blendshapes=shapes)
    parts = np.where(r.roles == PART, PART, 0).astype(np.int8)
    assert not side_changes(head.triangles, r.transform.apply(V0), r.vertices,
                            parts).any()
    placed = similarity_transform(10 * truth[:n], r.vertices[:n], scale=False).apply(10 * truth)
    teeth = slice(17039, 21451)                          # ICT's parts table
    assert np.linalg.norm(r.vertices[teeth] - placed[teeth], axis=1).mean() < 1.0
