import numpy as np
import pytest

from facewrap.geometry import ClosestPointTree
from facewrap.mesh import Mesh
from facewrap.wrapping.blend import SmoothExtension, smooth_extension
from facewrap.wrapping.projection import METHOD_PRISM, project_to_surface


def grid(n, size=1.0, z=lambda x, y: 0 * x, jitter=0.0, seed=0, quads=True):
    x, y = np.meshgrid(np.linspace(-size, size, n), np.linspace(-size, size, n))
    rng = np.random.default_rng(seed)
    x = x + jitter * rng.uniform(-1, 1, x.shape) * 2 * size / n
    y = y + jitter * rng.uniform(-1, 1, y.shape) * 2 * size / n
    V = np.stack([x, y, z(x, y)], -1).reshape(-1, 3)
    i = np.arange(n * n).reshape(n, n)
    a, b, c, d = i[:-1, :-1], i[:-1, 1:], i[1:, 1:], i[1:, :-1]
    if quads:
        F = np.stack([a, b, c, d], -1).reshape(-1, 4)
    else:
        F = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                            np.stack([a, c, d], -1).reshape(-1, 3)])
    return Mesh(V, F)


def bump(x, y):
    return 0.3 * np.exp(-(x ** 2 + y ** 2) / 0.3)


def test_projected_vertices_lie_on_scan_along_interpolated_normals():
    template = grid(25, 0.8)  # flat, above the scan's bump
    template = template.with_vertices(template.vertices + [0, 0, 0.1])
    scan = grid(60, 1.0, bump, jitter=0.3, quads=False)
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    proj = project_to_surface(template, tree, max_distance=0.5, max_normal_angle=80)
    assert proj.projected.mean() > 0.9
    on = proj.projected & (proj.method == METHOD_PRISM)
    assert on.sum() > 0.8 * template.n_vertices
    scale = scan.scale()
    d = tree.query(proj.vertices[proj.projected]).distances
    assert d.max() <= 1e-6 * scale
    # V - P is parallel to the interpolated (unnormalised) normal at P
    T = scan.triangles[proj.triangles[on]]
    N = np.einsum("ij,ijk->ik", proj.barycentric[on], tree.vertex_normals[T])
    diff = template.vertices[on] - proj.vertices[on]
    cross = np.linalg.norm(np.cross(diff, N), axis=1)
    assert np.all(cross <= 1e-6 * scale + 1e-9 * np.linalg.norm(diff, axis=1))


def test_masked_and_unreachable_vertices_follow_without_tearing():
    template = grid(30, 1.4)  # wider than the scan: the rim has nothing below it
    template = template.with_vertices(template.vertices + [0, 0, 0.05])
    scan = grid(50, 1.0, bump, quads=False)
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    mask = np.linalg.norm(template.vertices[:, :2], axis=1) > 0.25  # hole in the mask
    proj = project_to_surface(template, tree, mask=mask, max_distance=0.4)
    assert not proj.projected[~mask].any()
    assert not proj.projected[np.abs(template.vertices[:, :2]).max(1) > 1.0].any()
    # no tear: neighbouring vertices move alike (edge length changes stay small)
    E = np.array([[a, b] for f in template.polygons() for a, b in zip(f, np.roll(f, -1))])
    before = np.linalg.norm(np.diff(template.vertices[E], axis=1)[:, 0], axis=1)
    after = np.linalg.norm(np.diff(proj.vertices[E], axis=1)[:, 0], axis=1)
    assert np.max(np.abs(after - before)) < 0.6 * before.mean()
    # the masked centre rose with its neighbours toward the bump (not left at 0.05)
    centre = np.argmin(np.linalg.norm(template.vertices[:, :2], axis=1))
    assert proj.vertices[centre, 2] > 0.15


def test_smooth_extension_reproduces_linear_fields_and_keeps_known_values():
    m = grid(15)
    V = m.vertices
    known = np.abs(V[:, :2]).max(1) > 0.5
    lin = V @ np.array([[0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.]]) + 1.0
    for order in (1, 2):
        out = smooth_extension(m, lin, known, order=order)
        assert np.allclose(out[known], lin[known])
        assert np.allclose(out, lin, atol=1e-8)


def test_pieces_no_known_vertex_reaches_are_held_at_zero_not_solved(monkeypatch):
    """A second piece (a part: an eyeball beside the skin) with no known vertex keeps
    a zero displacement and never enters the factorisation; the skin's extension is
    the one it has alone."""
    import facewrap.wrapping.blend as blend
    skin, part = grid(12), grid(9)
    n = skin.n_vertices
    both = Mesh(np.vstack([skin.vertices, part.vertices + [0, 0, -1.0]]),
                np.vstack([skin.triangles, part.triangles + n]))
    known = np.zeros(both.n_vertices, dtype=bool)
    known[:n] = np.abs(skin.vertices[:, :2]).max(1) > 0.5
    d = np.random.default_rng(0).normal(size=(both.n_vertices, 3))
    sizes = []
    real = blend.FixedSystem
    monkeypatch.setattr(blend, "FixedSystem",
                        lambda *a, **k: sizes.append(len(real(*a, **k).free)) or real(*a, **k))
    extend = SmoothExtension(both, order=1)
    out = extend(d, known)
    assert sizes == [int((~known[:n]).sum())]              # the part's vertices held
    assert np.all(out[n:] == 0.0)
    alone = smooth_extension(Mesh(skin.vertices, skin.triangles), d[:n], known[:n], order=1)
    assert np.allclose(out[:n], alone, rtol=0, atol=1e-9)
    assert np.allclose(extend(d, known), out, rtol=0, atol=1e-12)   # used again


def test_bad_arguments():
    m = grid(5)
    tree = ClosestPointTree(m.vertices, m.triangles)
    with pytest.raises(ValueError, match="mask"):
        project_to_surface(m, tree, mask=np.ones(3, bool))
    with pytest.raises(ValueError, match="methods"):
        project_to_surface(m, tree, methods=("magic",))


def test_projection_does_not_fold_triangles_over_a_coarse_scan():
    """A fine, wavy template over a coarse zigzag scan: vertices landing on either
    side of a scan crease turn template triangles over; the fold guard lets those
    follow the blend instead (with the guard off the problem shows)."""
    from facewrap.geometry import face_normals
    template = grid(40, 1.0, lambda x, y: 0.1 * np.sin(5 * y))
    template = template.with_vertices(template.vertices + [0, 0, 0.1])
    zigzag = lambda x, y: 0.4 * np.abs(np.sin(8 * x)) * (1 - 0.3 * y ** 2)  # noqa: E731
    scan = grid(17, 1.2, zigzag, quads=False)
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    T = template.triangles
    n0 = face_normals(template.vertices, T)

    def flipped(p):
        return int(np.sum(np.einsum("ij,ij->i", face_normals(p.vertices, T), n0) < 0))
    kw = dict(max_distance=0.6, max_normal_angle=80)
    plain = project_to_surface(template, tree, fold_rounds=0, **kw)
    guarded = project_to_surface(template, tree, **kw)
    assert flipped(plain) > 10 and flipped(guarded) == 0
    assert guarded.projected.mean() > 0.4


def _strip_with_sliver():
    """A flat fan around a sliver (triangle 0: 0.01 wide under a unit edge)."""
    V = np.array([[0, 0, 0], [1, 0, 0], [.5, .01, 0], [.5, 1, 0], [.5, -1, 0],
                  [-1, 0, 0], [2, 0, 0]], dtype=float)
    T = np.array([[0, 1, 2], [1, 3, 2], [2, 3, 0], [0, 4, 1], [5, 0, 3], [5, 4, 0],
                  [1, 6, 3], [1, 4, 6]])
    return V, T


def test_settle_turns_a_sliver_back_with_its_neighbourhood_rotation():
    from facewrap.geometry import flipped_triangles
    from facewrap.geometry.similarity import Similarity
    from facewrap.wrapping.unfold import settle_turned_corners
    V, T = _strip_with_sliver()
    # the whole neighbourhood turned 30 degrees about x and moved: the sliver's
    # corner slipped across the long edge
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    motion = Similarity(np.array([[1, 0, 0], [0, c, -s], [0, s, c]]), np.array([3., 1, 2]))
    fit = motion.apply(V)
    fit[2] = motion.apply(V[2] * [1, -1, 1])
    assert flipped_triangles(fit, V, T).tolist() == [True] + [False] * 7
    out, moved = settle_turned_corners(Mesh(V, T), V, fit)
    assert moved.tolist() == [False, False, True, False, False, False, False]
    assert not flipped_triangles(out, V, T).any()
    assert np.allclose(out, motion.apply(V), atol=1e-9)        # where the motion puts it
    # a corner that may not move is left turned; so is a turned triangle of fair shape
    kept, none = settle_turned_corners(Mesh(V, T), V, fit, movable=np.arange(7) != 2)
    assert not none.any() and np.array_equal(kept, fit)
    fair = V.copy()
    fair[3] = [.5, -.5, 0]                                     # triangles 1, 2 turned over
    same, none = settle_turned_corners(Mesh(V, T), V, fair)
    assert not none.any() and np.array_equal(same, fair)


def test_relax_flips_fewest_never_leaves_more_folds_than_it_was_given():
    from facewrap.geometry import flipped_triangles
    from facewrap.wrapping.unfold import relax_flips
    rng = np.random.default_rng(3)
    g = np.stack(np.meshgrid(np.arange(8.0), np.arange(8.0)), -1).reshape(-1, 2)
    V = np.c_[g, np.zeros(64)]
    quads = [i for i in range(55) if i % 8 < 7]
    T = np.array([[i, i + 1, i + 9] for i in quads] + [[i, i + 9, i + 8] for i in quads])
    for _ in range(20):
        fit = V + rng.normal(scale=0.6, size=V.shape) * [1, 1, 0.2]
        fixed = rng.random(64) < 0.3
        out, moved = relax_flips(Mesh(V, T), V, fit, fixed=fixed, rounds=3, fewest=True)
        assert flipped_triangles(out, V, T).sum() <= flipped_triangles(fit, V, T).sum()
        assert not moved[fixed].any() and np.array_equal(out[~moved], fit[~moved])


@pytest.mark.parametrize("masked", [False, True])
def test_a_biharmonic_fill_follows_the_scan_across_a_hole_and_folds_nothing(masked):
    """Vertices over a hole of a curved scan do not land; a harmonic blend sags
    between the landing points around it, the biharmonic fill (blend_order 2)
    follows the bump.  Vertices the mask leaves out keep the harmonic blend."""
    from facewrap.geometry import turned_triangles
    template = grid(31, 0.8)
    template = template.with_vertices(template.vertices + [0, 0, 0.1])
    scan = grid(70, 1.0, bump, jitter=0.2, quads=False)
    C = scan.vertices[scan.triangles].mean(axis=1)
    hole = np.hypot(C[:, 0] - 0.1, C[:, 1]) < 0.3          # over the bump's top
    scan = Mesh(scan.vertices, scan.triangles[~hole])
    tree = ClosestPointTree(scan.vertices, scan.triangles)
    V = template.vertices
    mask = None
    if masked:          # the hole's far half may not be projected at all
        mask = ~((np.hypot(V[:, 0] - 0.1, V[:, 1]) < 0.3) & (V[:, 0] > 0.1))
    kw = dict(max_distance=0.5, max_normal_angle=80, mask=mask)
    one = project_to_surface(template, tree, blend_order=1, **kw)
    two = project_to_surface(template, tree, blend_order=2, **kw)
    np.testing.assert_array_equal(one.projected, two.projected)
    gap = ~two.projected & (mask if masked else True)
    assert gap.sum() > 20
    truth = lambda P: np.abs(P[:, 2] - bump(P[:, 0], P[:, 1]))   # height off the bump
    # (with the far half masked, the near half's fill meets the harmonic far half)
    better = 0.8 if masked else 0.5
    assert truth(two.vertices[gap]).mean() < better * truth(one.vertices[gap]).mean()
    assert not turned_triangles(two.vertices, V, template.triangles).any()
    np.testing.assert_array_equal(two.vertices[two.projected], one.vertices[one.projected])
    if masked:          # left out: harmonic, as with blend_order 1
        np.testing.assert_allclose(two.vertices[~mask], one.vertices[~mask], atol=1e-9)
