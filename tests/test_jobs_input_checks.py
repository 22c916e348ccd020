"""Input checks of a wrap against naive oracles: the same counts, linear-time code."""

from collections import Counter

import numpy as np
import pytest

from facewrap.geometry import connected_components
from facewrap.geometry.duplicates import any_duplicate_positions, duplicate_rows
from facewrap.jobs.input_checks import survey_mesh, weld_duplicates
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh


def _naive_survey(V, T) -> dict:
    """Counts by plain Python: repeated-vertex and zero-area triangles, edges shared
    by more than two good triangles, pieces among the used vertices."""
    repeated = [len(set(t)) < 3 for t in T.tolist()]
    edges = Counter()
    for t, rep in zip(T.tolist(), repeated):
        if not rep:
            for a, b in ((t[0], t[1]), (t[1], t[2]), (t[2], t[0])):
                edges[(min(a, b), max(a, b))] += 1
    used = sorted(set(T.ravel().tolist()))
    labels = connected_components(T, len(V))
    return {"repeated": sum(repeated), "non_manifold": sum(c > 2 for c in edges.values()),
            "pieces": len({labels[v] for v in used})}


def _counts(lines) -> dict:
    out = {"repeated": 0, "non_manifold": 0, "pieces": 1}
    for line in lines:
        words = line.split(": ", 1)[1].split()
        if "repeated" in line:
            out["repeated"] = int(words[2])
        elif "non-manifold" in line:
            out["non_manifold"] = int(words[2])
        elif "pieces" in line:
            out["pieces"] = int(words[2])
    return out


@pytest.mark.parametrize("seed", range(12))
def test_survey_counts_match_a_naive_count(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(6, 40))
    V = rng.normal(size=(n, 3))
    T = rng.integers(0, n, size=(int(rng.integers(3, 60)), 3))
    # some triangles with a repeated vertex, some fins on one edge, a loose piece
    fins = rng.integers(0, len(T), size=4)
    T[fins, :2] = T[fins[0], :2]
    k = rng.integers(0, len(T), size=3)
    T[k, 2] = T[k, 0]
    lines = survey_mesh(Mesh(V, T), "m.obj", "scan")
    assert _counts(lines) == _naive_survey(V, T), lines


def test_survey_names_each_oddity():
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 1], [5, 5, 5],
                  [6, 5, 5], [5, 6, 5], [0, -1, 0]], float)
    T = np.array([[0, 1, 2], [0, 1, 3], [0, 1, 4], [5, 6, 7], [0, 0, 8]])
    lines = survey_mesh(Mesh(V, T), "s.obj", "scan")
    assert any("1 triangle(s) with a repeated vertex" in x for x in lines)
    assert any("1 non-manifold edge(s)" in x for x in lines)
    # the repeated-vertex triangle still ties vertex 8 to the first piece
    assert any("2 disconnected pieces (the largest has 6 of 9 vertices)" in x
               for x in lines)
    assert all(x.startswith("s.obj: scan has") for x in lines)


@pytest.mark.parametrize("seed", range(6))
def test_duplicate_check_agrees_with_duplicate_rows(seed):
    rng = np.random.default_rng(seed)
    V = rng.integers(-2, 3, size=(int(rng.integers(1, 200)), 3)).astype(float)
    if seed % 2:
        V = V + rng.normal(size=V.shape)   # all distinct
    assert any_duplicate_positions(V) == (len(duplicate_rows(V)[0]) < len(V))
    # bit patterns, as the weld compares them: -0.0 is another position than 0.0
    assert not any_duplicate_positions(np.array([[0.0, 0, 1], [-0.0, 0, 1]]))


def test_weld_keeps_distinct_scans_as_they_are():
    V = np.random.default_rng(3).normal(size=(30, 3))
    mesh = Mesh(V, np.arange(30).reshape(10, 3))
    lm = Landmarks.from_vertices([0, 5, 9])
    same, lm2, note = weld_duplicates(mesh, lm, "s.obj")
    assert same is mesh and lm2 is lm and note is None
    welded, _, note = weld_duplicates(Mesh(np.vstack([V, V[:2]]), np.vstack(
        [np.arange(30).reshape(10, 3), [[30, 31, 2]]])), lm, "s.obj")
    assert welded.n_vertices == 30 and "2 duplicate vertices" in note
