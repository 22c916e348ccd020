"""Ground truth on real data: ICT-FaceKit's face registered to another ICT identity
in an extreme expression (jaw open, eyes shut), another triangulation, noise, mm,
a rigid motion.  The full benchmark (remeshed 60k scans, holes, peers) is
``benchmarks/bench_nicp.py``."""

import numpy as np
import pytest

from facewrap.landmarks import IBUG68_NAMES, Landmarks
from facewrap.mesh import Mesh
from facewrap.wrapping import WrapSettings, wrap

from conftest import needs_data

pytestmark = needs_data


@pytest.fixture(scope="module")
def ict_case(ict_folder):
    from facewrap.datasets import ICTFaceKit
    kit = ICTFaceKit(ict_folder)
    face = kit.part_mesh("face")
    n = face.n_vertices
    V0 = face.vertices
    expressions = ["jawOpen", "eyeBlink_L", "eyeBlink_R", "mouthSmile_L"]
    shapes = {name: np.asarray(kit.shape(name)[:n]) for name in expressions}
    truth = (V0 + (kit.shape("identity000")[:n] - kit.neutral.vertices[:n])
             + (shapes["jawOpen"] - V0) + (shapes["eyeBlink_L"] - V0)
             + (shapes["eyeBlink_R"] - V0))
    # another triangulation: quads split along their other diagonal
    polys = face.polygons()
    tris = []
    for p in polys:
        if len(p) == 4:
            tris += [[p[1], p[2], p[3]], [p[1], p[3], p[0]]]
        else:
            tris += [[p[0], p[i], p[i + 1]] for i in range(1, len(p) - 1)]
    rng = np.random.default_rng(0)
    # cm -> mm, a rigid motion, 0.2 mm noise
    a = 0.3
    R = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    truth_mm = 10.0 * truth @ R.T + [5.0, -20.0, 30.0]
    scan_v = truth_mm + rng.normal(scale=0.2, size=truth_mm.shape)
    scan = Mesh(scan_v, tris)
    lm = kit.landmarks
    scan_lm = Landmarks.from_points(truth_mm[lm.vertex], names=IBUG68_NAMES)
    return face, lm, shapes, scan, scan_lm, truth_mm


@pytest.mark.slow
def test_hybrid_registers_ict_jaw_open_eyes_shut_below_a_millimetre(ict_case):
    face, lm, shapes, scan, scan_lm, truth = ict_case
    errors = {}
    for model in ("graph", "hybrid"):
        r = wrap(face, scan, lm, scan_lm, WrapSettings(model=model), blendshapes=shapes)
        errors[model] = np.linalg.norm(r.vertices - truth, axis=1)
        if model == "hybrid":
            w = dict(zip(r.shape_names, r.weights))
            assert w["jawOpen"] == pytest.approx(1.0, abs=0.15)
            assert w["mouthSmile_L"] == pytest.approx(0.0, abs=0.15)
    e = errors["hybrid"]                                  # mm, every face vertex
    assert e.mean() < 0.6 and np.percentile(e, 95) < 1.5
    assert e.mean() < 0.5 * errors["graph"].mean()
