"""Hostile inputs of a seventh sweep: the Python library, called from a pipeline.

Classes:

- a wrap's result held the caller's own :class:`~facewrap.wrapping.Stage` objects
  (``result.settings.stages[0] is settings.stages[0]``): changing the result's
  settings, to try a variant, changed the caller's; the result now holds copies
  (the inputs themselves, read-only or not, were and are left as they were);
- indices given as floats were cast silently, 2.5 becoming vertex 2: a
  :class:`~facewrap.Mesh`'s faces and corner tables, :class:`~facewrap.Landmarks`
  ids, transfer markers, ``personalise_shapes``'s anchors, ``fit_examples``'s and
  ``stabilise``'s rigid vertices; whole floats (2.0, as a text table reads) are
  still taken, any other number is refused naming the argument
  (:func:`~facewrap.geometry.checks.as_whole_indices`);
- geometry functions answered wrongly what they did not check: ``new_creases``
  cast float triangles (no crease found) and met a vertex count not the
  reference's with an ``IndexError``; ``turned_triangles`` took NaN positions as
  upright; ``similarity_transform`` failed on a NaN with "SVD did not converge"
  (NaN weights too); ``write_mesh`` of an array failed with ``AttributeError``;
  each now names the argument;
- surface landmarks with barycentric coordinates that are NaN, negative or do not
  sum to 1 gave NaN positions or points off the mesh, silently; the JSON reader
  refused them, the :class:`~facewrap.Landmarks` constructor now does too (one
  rule, :func:`~facewrap.landmarks.barycentric_problem`);
- shapes of another vertex count failed with numpy's "operands could not be
  broadcast" (``wrap``'s blendshapes; ``personalise_shapes`` and ``fit_examples``
  with "all input arrays must have the same shape"), or passed silently
  (``stabilise`` of an expression with a vertex fewer than its neutral); each now
  names the shape (:func:`~facewrap.geometry.checks.as_shape_dict`);
- arguments of the wrong kind failed as ``AttributeError`` deep inside, or with a
  message naming nothing (``replace() should be called on dataclass instances``):
  a dict for ``WrapSettings`` or ``CorrespondenceSettings``, an array for a mesh or
  landmarks, a dict for a ``GraphCache``, a string for ``initial``, a job, a job's
  path field holding a number, one path where a list of them belongs (read as its
  characters, as were a single string for a Mesh's ``materials`` or ``groups`` and
  for Landmarks' ``names``), ``DeformationTransfer.transfer`` before ``fit`` or
  with a dict of shapes; each is now a ``TypeError`` naming the argument
  (:func:`~facewrap.params.expect_instance`);
- inputs a wrap cannot fit named no argument: a NaN in the scan ("V must be
  finite"), a scan without faces ("T must hold at least one triangle"), a template
  landmark beyond the template (``IndexError``), a ``scan_tree`` of another mesh (a
  numpy broadcast error), a template landmark given twice to the rbf model ("two
  landmarks are at the same position"); each now starts with what it is about
  (``"scan: ..."``, ``"template landmarks: ..."``), which a job turns into its file;
- numpy's strings were refused as settings (``WrapSettings(model=np.str_("rbf"))``,
  a model name read from an array: "must be one of ... 'rbf' ...; got
  np.str_('rbf')"); they are now the option they hold;
- the shared caches were not thread-safe: two threads wrapping at once raised
  ``KeyError`` in :class:`~facewrap.wrapping.GraphCache` when one dropped the graph
  the other had just found, and :func:`~facewrap.parallel.thread_map` on two
  threads shut down the pool the other was submitting to ("cannot schedule new
  futures after shutdown").

Inputs are the built-in sample at its smallest, built in memory.
"""

from __future__ import annotations

import copy
import sys
import threading

import numpy as np
import pytest

from facewrap import InputError, Landmarks, Mesh, WrapSettings, pair_landmarks, wrap
from facewrap.geometry import (ClosestPointTree, new_creases, similarity_transform,
                               turned_triangles)
from facewrap.io import read_mesh, write_mesh
from facewrap.geometry.similarity import Similarity
from facewrap.jobs import TransferJob, WrapJob, run_transfer_job, run_wrap_job
from facewrap.parallel import thread_map
from facewrap.rig import fit_examples, personalise_shapes, stabilise
from facewrap.sample import make_scan, make_template
from facewrap.transfer import DeformationTransfer, find_correspondence
from facewrap.wrapping import GraphCache, Stage, track

RBF = WrapSettings(model="rbf")


@pytest.fixture(scope="module")
def small():
    """The sample at its smallest: template 24, scan 40, and the face alone."""
    tpl = make_template(24)
    scan = make_scan(tpl, resolution=40, texture_size=16)
    face, keep = tpl.mesh.submesh(tpl.mesh.face_groups == 0)
    shapes = {k: v[keep] for k, v in tpl.blendshapes.items()}
    return {"tpl": tpl, "scan": scan, "face": face, "shapes": shapes}


def wrap_args(small) -> tuple:
    return (small["tpl"].mesh, small["scan"].mesh, small["tpl"].landmarks,
            small["scan"].landmarks)


def read_only(a) -> np.ndarray:
    out = np.array(a)
    out.setflags(write=False)
    return out


# -- results hold no part of the caller's settings -----------------------------------
def test_a_result_holds_copies_of_the_callers_stages(small):
    stages = [Stage(iterations=2), Stage(iterations=2, smooth_weight=0.1)]
    settings = WrapSettings(model="hybrid", stages=stages)
    shapes = {k: read_only(v) for k, v in small["tpl"].blendshapes.items()}
    exclude = read_only(np.arange(5))
    before = copy.deepcopy((settings, shapes, exclude))
    result = wrap(*wrap_args(small), settings, blendshapes=shapes, exclude=exclude)
    assert settings == before[0] and np.array_equal(exclude, before[2])
    assert all(np.array_equal(shapes[k], before[1][k]) for k in shapes)
    assert result.settings.stages is not stages
    result.settings.stages[0].iterations = 7          # a variant, tried on the result
    assert stages[0].iterations == 2 and settings == before[0]


# -- indices given as floats -----------------------------------------------------------
def test_fractional_indices_are_refused_whole_ones_taken(small):
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    assert Mesh(V, [[0.0, 1.0, 2.0]]).faces_array().tolist() == [[0, 1, 2]]
    with pytest.raises(ValueError, match="faces must hold whole numbers"):
        Mesh(V, np.array([[0.5, 1, 2], [1, 3, 2]]))
    with pytest.raises(ValueError, match="faces must hold whole numbers"):
        Mesh(V, [[0, 1, 2], [1, 3, 2.5]])
    with pytest.raises(ValueError, match="face_uvs must hold whole numbers"):
        Mesh(V, [[0, 1, 2]], uvs=np.zeros((3, 2)), face_uvs=[[0.7, 1, 2]])
    with pytest.raises(ValueError, match="integer indices"):
        Mesh(V, np.array([[True, False, True]]))
    with pytest.raises(ValueError, match="landmark indices must hold whole numbers"):
        Landmarks.from_vertices([0.5, 1.7])
    face, shapes = small["face"], small["shapes"]
    markers = np.array([[0, 0], [50, 50], [99, 99]])
    with pytest.raises(InputError, match="markers must hold whole numbers"):
        find_correspondence(face, face, markers + 0.5)
    same = Similarity(np.eye(3), np.zeros(3), 1.0)
    with pytest.raises(ValueError, match="anchors must hold whole numbers"):
        personalise_shapes(face, shapes, face, same, anchors=[0.5, 10.7])
    with pytest.raises(ValueError, match="rigid must hold whole numbers"):
        stabilise(face.vertices, face.vertices, [0.2, 1.5, 2.9, 30.1])
    with pytest.raises(ValueError, match="rigid must hold whole numbers"):
        fit_examples(face, shapes, [shapes["smile"]], rigid=[0.5])


def test_geometry_refuses_what_it_would_answer_wrongly(small, tmp_path):
    face = small["face"]
    V, T = face.vertices, face.triangles
    with pytest.raises(ValueError, match="triangles must hold integer indices"):
        new_creases(V, V, T + 0.5)                    # cast to T: no crease, silently
    with pytest.raises(ValueError, match="one topology"):
        new_creases(V[:-5], V, T)                     # an IndexError
    with pytest.raises(ValueError, match="vertices must be finite"):
        turned_triangles(V * np.nan, V, T)            # NaN turns nowhere: "upright"
    with pytest.raises(ValueError, match="source and target must be finite"):
        similarity_transform(np.full((3, 3), np.nan), np.eye(3))   # SVD's LinAlgError
    with pytest.raises(ValueError, match="weights must be"):
        similarity_transform(np.eye(3), np.eye(3), weights=[1.0, np.nan, 1.0])
    with pytest.raises(TypeError, match="mesh must be a Mesh"):
        write_mesh(tmp_path / "out.obj", V)
    with pytest.raises(TypeError, match="path must be a str or os.PathLike"):
        read_mesh(None)


# -- surface landmarks off their triangles ---------------------------------------------
@pytest.mark.parametrize("bary", [[np.nan, 0.5, 0.5], [1.0, 1.0, 0.0], [-5.0, 3.0, 3.0]])
def test_barycentric_coordinates_off_the_triangle_are_refused(bary):
    with pytest.raises(ValueError, match="barycentric coordinates must be 3 numbers"):
        Landmarks.from_barycentric([0], [bary])
    assert Landmarks.from_barycentric([0], [[0.2, 0.3, 0.5]]).positions(
        np.eye(3), [[0, 1, 2]]).round(6).tolist() == [[0.2, 0.3, 0.5]]


# -- shapes of another vertex count ----------------------------------------------------
def test_shapes_of_another_vertex_count_are_named(small):
    shapes = dict(small["tpl"].blendshapes)
    short = {**shapes, "smile": shapes["smile"][:-3]}
    for model in ("hybrid", "rbf"):   # checked whether the model uses them or not
        with pytest.raises(ValueError, match=r"blendshapes\['smile'\] must have shape"):
            wrap(*wrap_args(small), WrapSettings(model=model), blendshapes=short)
    with pytest.raises(TypeError, match="blendshapes must be a dict"):
        wrap(*wrap_args(small), WrapSettings(model="hybrid"), blendshapes=list(shapes.values()))
    face, fshapes = small["face"], small["shapes"]
    fshort = {**fshapes, "smile": fshapes["smile"][:-1]}
    same = Similarity(np.eye(3), np.zeros(3), 1.0)
    with pytest.raises(ValueError, match=r"shapes\['smile'\] must have shape"):
        personalise_shapes(face, fshort, face, same)
    with pytest.raises(ValueError, match=r"shapes\['smile'\] must have shape"):
        fit_examples(face, fshort, [fshapes["smile"]])
    with pytest.raises(ValueError, match="one topology"):   # passed silently
        stabilise(face.vertices[:-1], face.vertices, [0, 1, 2])


# -- arguments of the wrong kind -------------------------------------------------------
def test_arguments_of_the_wrong_kind_are_named(small, tmp_path):
    template, scan, tl, sl = wrap_args(small)
    cases = [
        ("settings must be a WrapSettings", lambda: wrap(template, scan, tl, sl,
                                                          {"model": "rbf"})),
        ("template must be a Mesh", lambda: wrap(template.vertices, scan, tl, sl, RBF)),
        ("template_landmarks must be a Landmarks", lambda: wrap(template, scan, tl.vertex,
                                                                sl, RBF)),
        ("graph_cache must be a GraphCache", lambda: wrap(template, scan, tl, sl, RBF,
                                                          graph_cache={})),
        ("initial must be a WrapResult", lambda: wrap(template, scan, tl, sl, RBF,
                                                      initial="previous.obj")),
        ("scans\\[1\\] must be a Mesh", lambda: track(template, [scan, scan.vertices], tl,
                                                      [sl, None], RBF)),
        ("settings must be a CorrespondenceSettings", lambda: find_correspondence(
            small["face"], small["face"], [[0, 0], [50, 50], [99, 99]], {"deform": "source"})),
        ("correspondence must be a Correspondence", lambda: DeformationTransfer(anchor=0)
         .fit(small["face"], small["face"], "corr.npz")),
        ("job must be a WrapJob", lambda: run_wrap_job({"template": "t.obj"}, RBF)),
        ("WrapJob.template must be a path", lambda: run_wrap_job(
            WrapJob(3, "scan.obj", output=str(tmp_path / "out.obj")), RBF)),
        ("WrapJob.output must be a path", lambda: run_wrap_job(
            WrapJob("t.obj", "scan.obj", output=None), RBF)),
        ("source_shapes must be a list of paths", lambda: run_transfer_job(
            TransferJob("a.obj", "b.obj", "m.txt", "shapes", out=str(tmp_path / "s")))),
    ]
    V = np.eye(3)
    cases += [   # one string where a list of them belongs: read as its letters
        ("names must be a sequence of strings", lambda: Landmarks.from_vertices(
            [0, 1, 2, 0], names="nose")),
        ("materials must be a sequence of strings", lambda: Mesh(
            V, [[0, 1, 2]], materials="skin", face_materials=[0])),
        ("the scan landmarks must be a Landmarks", lambda: pair_landmarks(
            tl, sl.points, ("template", "scan"))),
    ]
    for needle, call in cases:
        with pytest.raises(TypeError, match=needle):
            call()
    with pytest.raises(RuntimeError, match="not fitted: call fit"):
        DeformationTransfer(anchor=0).transfer(small["face"].vertices)


def test_a_dict_of_shapes_to_transfer_is_told_how_to_pass_it(small):
    face = small["face"]
    corr = find_correspondence(face, face, [[0, 0], [50, 50], [99, 99]])
    dt = DeformationTransfer(anchor=0, fix_flips=False).fit(face, face, corr)
    with pytest.raises(TypeError, match="not a dict: pass np.stack"):
        dt.transfer(small["shapes"])


# -- inputs a wrap cannot fit, named ---------------------------------------------------
def test_inputs_a_wrap_cannot_fit_name_what_they_are_about(small):
    template, scan, tl, sl = wrap_args(small)
    V = scan.vertices.copy()
    V[5] = np.nan
    with pytest.raises(ValueError, match=r"^scan: vertex 5 is not finite"):
        wrap(template, scan.with_vertices(V), tl, sl, RBF)
    with pytest.raises(ValueError, match=r"^scan: has no faces"):
        wrap(template, Mesh(scan.vertices, np.zeros((0, 3), int)), tl, sl, RBF)
    far = Landmarks.from_vertices(np.r_[tl.vertex[:-1], 99999], tl.names)
    with pytest.raises(ValueError, match=r"^template landmarks: .* vertex 99999 out of range"):
        wrap(template, scan, far, sl, RBF)
    twice = Landmarks.from_vertices(np.r_[tl.vertex[:-1], tl.vertex[0]], tl.names)
    with pytest.raises(ValueError, match=r"^template landmarks: .*same position"):
        wrap(template, scan, twice, sl, RBF)
    other = ClosestPointTree(template.vertices, template.triangles)
    with pytest.raises(ValueError, match="scan_tree was built on another mesh"):
        wrap(template, scan, tl, sl, RBF, scan_tree=other)
    with pytest.raises(ValueError, match=r"^scan: vertex 5") as error:
        track(template, [scan, scan.with_vertices(V)], tl, [sl, None], RBF)
    assert error.value.frame == 1


# -- numpy scalars as settings ---------------------------------------------------------
def test_numpy_strings_are_the_options_they_hold():
    s = WrapSettings(model=np.str_("rbf"), robust=np.str_("huber"), kernel=np.str_("gaussian"))
    assert (s.model, s.robust, s.kernel) == ("rbf", "huber", "gaussian")
    with pytest.raises(ValueError, match="WrapSettings.blend_order must be one of 1, 2"):
        WrapSettings(blend_order=1.0)                 # a float is still no option 1
    with pytest.raises(ValueError, match="WrapSettings.model must be one of"):
        WrapSettings(model=np.str_("nope"))


# -- shared caches under threads -------------------------------------------------------
def test_shared_caches_are_safe_on_threads(small, monkeypatch):
    # no disk cache: np.load parses each entry's header with ast.literal_eval, and
    # CPython 3.11's AST constructor fails on two threads at this switch interval
    monkeypatch.setenv("FACEWRAP_CACHE", "0")
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.]])
    T = np.array([[0, 1, 2], [1, 3, 2]])
    meshes = [(V, T), (2 * V, T)]
    cache = GraphCache(1)                             # every other lookup drops one
    errors = []

    def hammer(k):
        try:
            for r in range(3000):
                cache.graph(*meshes[(r // 7 + k) % 2], 0.5)
                if r % 50 == 0:
                    thread_map(lambda x: x, range(2 + (r + k) % 5), threads=2 + (r + k) % 5)
        except Exception as exc:   # noqa: BLE001 - whatever a thread met is the failure
            errors.append(repr(exc))

    switch = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)                       # threads take turns often
    try:
        threads = [threading.Thread(target=hammer, args=(k,)) for k in range(4)]
        [t.start() for t in threads]
        [t.join() for t in threads]
    finally:
        sys.setswitchinterval(switch)
    assert errors == []
    # two wraps at once give what one after another give
    tpl, scan = small["tpl"], small["scan"]
    other = make_scan(tpl, resolution=40, texture_size=16, identity_seed=2)
    jobs = [(tpl.mesh, s.mesh, tpl.landmarks, s.landmarks) for s in (scan, other)]
    graphs = GraphCache(1)
    alone = [wrap(*j, WrapSettings(model="graph"), graph_cache=graphs).vertices for j in jobs]
    together = [None, None]

    def fit(k):
        together[k] = wrap(*jobs[k], WrapSettings(model="graph"), graph_cache=graphs).vertices

    threads = [threading.Thread(target=fit, args=(k,)) for k in range(2)]
    [t.start() for t in threads]
    [t.join() for t in threads]
    # the same to round-off: BLAS's thread count is process-wide, so the two wraps
    # may sum in another order beside each other (2.8e-14 mm under numpy 1.26);
    # a cache handing one wrap the other's state would move whole vertices
    size = float(np.ptp(tpl.mesh.vertices, axis=0).max())
    assert all(np.abs(a - b).max() <= 1e-9 * size for a, b in zip(alone, together))



def test_a_wrap_with_nothing_left_to_pull_says_which_argument_left_nothing():
    """fit_mask all False (or everything excluded) made the ICP fail naming
    max_distance, which was not the cause; the closed-form rbf warp still runs."""
    from facewrap.sample import make_scan, make_template
    from facewrap.wrapping import WrapSettings, wrap
    t = make_template(resolution=20)
    s = make_scan(t, resolution=30)
    n = t.mesh.n_vertices
    with pytest.raises(ValueError, match=r"^fit_mask \(--fit-mask\).*leaves no template"):
        wrap(t.mesh, s.mesh, t.landmarks, s.landmarks, WrapSettings(model="graph"),
             fit_mask=np.zeros(n, bool))
    with pytest.raises(ValueError, match=r"^exclude \(--exclude\)"):
        wrap(t.mesh, s.mesh, t.landmarks, s.landmarks, WrapSettings(model="affine"),
             exclude=np.arange(n))
    r = wrap(t.mesh, s.mesh, t.landmarks, s.landmarks, WrapSettings(model="rbf"),
             fit_mask=np.zeros(n, bool))
    assert np.isfinite(r.vertices).all()


def test_submesh_and_subset_refuse_ids_outside_naming_the_argument():
    """A bare IndexError before."""
    from facewrap.sample import make_template
    t = make_template(resolution=20)
    with pytest.raises(ValueError, match="faces holds polygon ids outside"):
        t.mesh.submesh([10 ** 6])
    with pytest.raises(ValueError, match=r"faces must have shape"):
        t.mesh.submesh(np.array([True, False]))
    with pytest.raises(ValueError, match="index holds landmark ids outside"):
        t.landmarks.subset([500])
    assert t.landmarks.subset([2, 0]).vertex.tolist() == t.landmarks.vertex[[2, 0]].tolist()
