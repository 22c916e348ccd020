"""``build_rig``: a person's scans in, their rig out.

The neutral scan is wrapped (the hybrid model) and the template's shapes are made
the person's (:mod:`.personalise`).  Expression scans, when given, are each
wrapped warm-started from the neutral's result
(:func:`facewrap.wrapping.track.wrap_following`, as a sequence's later frame is),
after a rough rigid pre-alignment (the head moves between scans): from the
expression's landmarks to the neutral scan's, reweighted so that the mouth and
brows, which the expression moves, count little; or, for a scan without
landmarks, by rigid ICP of the neutral wrap onto it (its landmarks then are the
neutral's moved along and snapped onto the scan, weighted low, as for a
sequence).  Each wrap is stabilised (:mod:`.stabilise`: a robust fit on the
skull-rigid vertices, then the prior rig's prediction of the expression registered
onto its scan) and the shapes are corrected to reproduce them (:mod:`.examples`).
Where the neutral scan and an expression scan both carry a texture, the
expression's wrap is refined by it first (:mod:`.texture_flow`: the neutral's
texture baked into the template's layout, matched to the expression scan's by
optical flow), so that the skin sits on the same skin in both.  That baked texture
is the rig's (:attr:`Rig.texture`): a job writes it instead of baking it again,
and each scan's closest-point tree, built once, serves its wrap, the bake and the
refinement.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace

import numpy as np
from threadpoolctl import threadpool_limits

from facewrap.geometry import ClosestPointTree
from facewrap.geometry.similarity import Similarity
from facewrap.landmarks import Landmarks, pair_landmarks
from facewrap.mesh import Mesh, check_mesh
from facewrap.parallel import run_on, usable_threads
from facewrap.rig.examples import ExampleFit, ExampleSettings, fit_examples, fit_weights
from facewrap.rig.personalise import personalise_shapes
from facewrap.rig.stabilise import (Stabilised, least_moving, refine_pose, stabilise,
                                    unlike_neutral)
from facewrap.rig.texture_flow import TextureFlowSettings, flow_available, refine_by_texture
from facewrap.texture.tiles import TiledBake, bake_tiles
from facewrap.texture.udim import FIRST_TILE
from facewrap.wrapping import WrapResult, WrapSettings, wrap
from facewrap.wrapping.align import rigid_icp
from facewrap.wrapping.follow import follow_skin
from facewrap.wrapping.roles import FITTED, PART
from facewrap.wrapping.track import FrameError, wrap_following

__all__ = ["Rig", "build_rig"]


@dataclass(frozen=True)
class Rig:
    """A person's rig in the template's topology.

    Attributes
    ----------
    neutral : Mesh
        The template wrapped onto the person's neutral scan (the scan's frame).
    shapes : dict of str to (n, 3) float64
        The template's shapes made the person's (absolute positions).
    wrap : WrapResult
        The neutral's wrap (metrics, roles, alignment).
    method : str
        How the shapes were carried (:data:`~facewrap.rig.PERSONALISE_METHODS`).
    timings : dict
        Seconds: ``wrap``, ``shapes``, ``total``; with a texture, ``texture``
        (the neutral's bake); with expression scans, ``expressions`` (their wraps,
        refinements and stabilisations), ``stabilise`` (the stabilisations' own
        seconds), ``examples`` and, when textures refined them, ``texture_flow``
        (the refinements' own seconds).  The bake runs beside the shapes and the
        wraps, the refinements and stabilisations beside the wraps: their seconds
        are part of the others', not added to them.
    examples : ExampleFit or None
        With expression scans: their weights, reconstruction errors and rigid
        poses (:class:`~facewrap.rig.ExampleFit`); ``shapes`` are then the
        corrected ones.  None without.
    expression_wraps : list of WrapResult
        One per expression scan (in its scan's frame).
    prior : dict of str to (n, 3) float64
        The shapes before the examples corrected them (the neutral-only rig's).
    texture_refinements : list of (TextureRefinement or None)
        One per expression scan: how its texture refined its wrap
        (:class:`~facewrap.rig.TextureRefinement`); None where it did not (no
        texture, refinement off, OpenCV missing).  Empty without expression scans.
    texture : TiledBake or None
        The neutral scan's texture baked into the template's layout
        (:func:`facewrap.texture.tiles.bake_tiles`, one image per texture set, at
        ``TextureFlowSettings.texture_size``) when a texture is given and both
        meshes have texture coordinates; None otherwise.
    """

    neutral: Mesh
    shapes: dict
    wrap: WrapResult
    method: str
    timings: dict = field(default_factory=dict)
    examples: ExampleFit | None = None
    expression_wraps: list = field(default_factory=list)
    prior: dict = field(default_factory=dict)
    texture_refinements: list = field(default_factory=list)
    texture: TiledBake | None = None

    def shape_mesh(self, name: str) -> Mesh:
        """Shape ``name`` as a mesh in the template's exact topology."""
        return self.neutral.with_vertices(self.shapes[name])

    def write_gltf(self, path, *, scale: float = 1.0, textures=None) -> None:
        """The neutral with every shape as a named morph target (``.glb``/``.gltf``);
        see :func:`facewrap.io.gltf.write_gltf_morphs`."""
        from facewrap.io.gltf import write_gltf_morphs
        write_gltf_morphs(path, self.neutral, self.shapes, scale=scale, name="rig",
                          textures=textures)


def _head_motion(neutral: WrapResult, template_landmarks: Landmarks, scan: Mesh,
                 landmarks: Landmarks | None, tree: ClosestPointTree,
                 rigid: np.ndarray) -> Similarity:
    """A rough rigid motion from the neutral scan's frame to ``scan``'s.

    From the landmarks when given (the neutral wrap's landmarks onto the scan's,
    robustly: the ones the expression moves lose their weight), else by trimmed
    rigid ICP of the neutral wrap's skull-rigid vertices onto the scan.
    """
    if landmarks is not None:
        ia, ib = pair_landmarks(template_landmarks, landmarks, ("template", "scan"))
        ours = template_landmarks.positions(neutral.mesh)[ia]
        theirs = landmarks.positions(scan)[ib]
        return stabilise(ours, theirs, np.arange(len(ia))).pose
    points = neutral.vertices[rigid]
    return rigid_icp(points, tree, max_distance=0.1 * scan.scale()).transform


def _expression_fits(template, result, template_landmarks, scans, landmarks, trees,
                     rigid, blendshapes, settings, wrap_options, finish, beside):
    """Each expression scan wrapped from the neutral's result, moved by the head's
    rough motion first (so the warm start begins where the head now is), then
    passed through ``finish(wrap, scan, k, tree)`` (its texture refinement and
    stabilisation: it returns the wrap, its :class:`TextureRefinement` or None,
    its :class:`~facewrap.rig.stabilise.Stabilised` and the seconds stabilising
    took) on the executor ``beside`` (None: here, one after the other).

    Returns the lists of the wraps, their refinements, their stabilisations and
    those seconds, and the wraps before their refinements (by geometry alone).
    """
    pending, geometric = [], []
    for k, (scan, lm, tree) in enumerate(zip(scans, landmarks, trees)):
        tree = tree or ClosestPointTree(scan.vertices, scan.triangles)
        motion = _head_motion(result, template_landmarks, scan, lm, tree, rigid)
        start = replace(result, transform=motion.compose(result.transform),
                        mesh=result.mesh.with_vertices(motion.apply(result.vertices)))
        try:
            w = wrap_following(template, scan, template_landmarks, lm, start, settings,
                               blendshapes=blendshapes, scan_tree=tree, **wrap_options)
        except ValueError as exc:   # which scan it is about: the caller names its file
            raise FrameError(k, str(exc)) from None
        pending.append(run_on(beside, finish, w, scan, k, tree))
        geometric.append(w)
    done = [p.result() for p in pending]
    return (*([d[i] for d in done] for i in range(4)), geometric)


def _flow_wanted(settings: TextureFlowSettings, scans, textures) -> bool:
    """Whether the texture refines the expression wraps, the neutral's texture being
    baked: on, some expression scan textured (with texture coordinates), and
    OpenCV there (else one warning naming the extra to install)."""
    if not settings.enabled:
        return False
    if not any(t is not None and s.uvs is not None for s, t in zip(scans, textures)):
        return False
    return flow_available(warn=True)


def _reference_image(baked: TiledBake) -> np.ndarray:
    """The image the skin is drawn with: the main image of tile 1001 (the face's;
    images of materials overlapping it, eyes, come after), else the first."""
    for s, r in baked.images.items():
        if s.tile == FIRST_TILE and s.label is None:
            return r.image
    return next(iter(baked.images.values())).image


def _texture_refiner(template: Mesh, baking, textures, settings: TextureFlowSettings):
    """``refine(wrap, scan, k, tree)`` for :func:`_expression_fits`: expression
    ``k``'s wrap refined by its texture (``textures[k]``) against the neutral's
    texture baked into the template's layout (``baking``: its future, None without);
    the wrap as it is (and None) where either is missing."""
    def refine(w: WrapResult, scan: Mesh, k: int, tree: ClosestPointTree):
        image = textures[k]
        if baking is None or image is None or scan.uvs is None:
            return w, None
        reference = _reference_image(baking.result())
        roles = w.roles if w.roles is not None else np.zeros(template.n_vertices, np.int8)
        aligned = w.transform.apply(template.vertices)
        # the parts move from where the wrap put them, with the skin's refinement
        follow = ((lambda V, a=aligned, r=roles, s=w.vertices:
                   follow_skin(template.triangles, a, V, r, start=s))
                  if (roles == PART).any() else None)
        on_scan = None if w.projection is None else w.projection.projected
        r = refine_by_texture(template, w.vertices, reference, scan, image, settings,
                              movable=roles == FITTED, on_scan=on_scan, scan_tree=tree,
                              follow=follow)
        return replace(w, mesh=w.mesh.with_vertices(r.vertices)), r
    return refine


#: rounds of (prior-rig weights, surface registration) in :func:`_stabiliser`
POSE_ROUNDS = 3


def _stabiliser(result: WrapResult, rigid, prior: dict, weights, gamma: float):
    """``stabilised(w, tree, k)``: expression ``k``'s wrap ``w`` moved onto the
    neutral's head pose (a :class:`~facewrap.rig.stabilise.Stabilised`).

    A robust rigid fit on the skull-rigid vertices, then :data:`POSE_ROUNDS` rounds
    of the prior rig's weights for it (``weights[k]``, the expression meant, held
    with ``gamma``) and :func:`~facewrap.rig.stabilise.refine_pose` of that
    prediction onto the scan (its vertices trusted less the more the prediction
    moves them from the neutral).  ``weights`` and ``residual`` of the result are
    the rigid fit's (which rigid vertices the expression moved).  Each scan's is
    its own: they run as the expressions' refinements end."""
    V = result.vertices
    names = list(prior)
    D = np.stack([np.asarray(prior[k]) - V for k in names], axis=2)      # (n, 3, s)
    rows = D.reshape(-1, len(names))                                    # (3n, s)
    gram = rows.T @ rows
    seen = (np.ones(len(V), dtype=bool) if result.projection is None
            else result.projection.projected)

    def stabilised(w: WrapResult, tree: ClosestPointTree, k: int) -> Stabilised:
        mask = None if w.projection is None else w.projection.projected
        both = seen if mask is None else seen & mask
        first = stabilise(w.vertices, V, _seen_rigid(rigid, result, mask))
        pose = first.pose
        meant = weights[k]
        target = None if meant is None else np.array([[meant.get(x, 0.0) for x in names]])
        for _ in range(POSE_ROUNDS):
            alpha = fit_weights(rows, (pose.apply(w.vertices) - V).reshape(-1, 1),
                                prior=target, gamma=gamma, rows=np.repeat(both, 3),
                                gram=gram)[0]
            moved = D @ alpha                                           # (n, 3)
            pose = refine_pose(V + moved, result.mesh.triangles, tree, pose,
                               np.flatnonzero(both), np.linalg.norm(moved, axis=1))
        return Stabilised(pose.apply(w.vertices), pose, first.weights, first.residual)
    return stabilised


def _corrected(result: WrapResult, prior: dict, wraps, geometric, stable, rigid,
               weights, settings: ExampleSettings) -> tuple[list, ExampleFit]:
    """The expression wraps (with :func:`_said_unlike`'s warnings) and the shapes
    corrected to reproduce their stabilised forms (:func:`fit_examples`, the poses
    that stabilised them kept)."""
    with threadpool_limits(limits=1, user_api="blas"):
        masks = [None if w.projection is None else w.projection.projected for w in wraps]
        # a scan of someone else, or of no expression, is said on its wrap's warnings
        wraps = [_said_unlike(*a, result, rigid) for a in zip(wraps, geometric, masks)]
        fit = fit_examples(result.mesh, prior, [x.vertices for x in stable],
                           masks=masks, weights=weights, rigid=rigid, settings=settings)
    return wraps, replace(fit, poses=[x.pose for x in stable])


def _finisher(refine, stabilised):
    """``finish(w, scan, k, tree)`` for :func:`_expression_fits`, on the thread
    beside the next scan's wrap: expression ``k``'s wrap refined by
    ``refine(w, scan, k, tree)`` (:func:`_texture_refiner`), then stabilised by
    ``stabilised(w, tree, k)`` (:func:`_stabiliser`), with the seconds that took."""
    def finish(w: WrapResult, scan: Mesh, k: int, tree: ClosestPointTree):
        w, refinement = refine(w, scan, k, tree)
        t = time.perf_counter()
        return w, refinement, stabilised(w, tree, k), time.perf_counter() - t
    return finish


def _least_moving(blendshapes: dict, template: Mesh, neutral: WrapResult) -> np.ndarray:
    """The skull-rigid vertices when none are given: those the shapes move least,
    among the vertices the neutral scan saw."""
    seen = None if neutral.projection is None else neutral.projection.projected
    return least_moving(np.stack([np.asarray(v, dtype=np.float64)
                                  for v in blendshapes.values()]), template.vertices,
                        among=seen)


def _said_unlike(w: WrapResult, geometric: WrapResult, mask, neutral: WrapResult,
                 rigid) -> WrapResult:
    """``w`` with :func:`~facewrap.rig.stabilise.unlike_neutral`'s line among its
    warnings when there is one; nothing else changes.  Judged on the wrap by
    geometry (``geometric``), stabilised on the skull alone: a texture refinement
    slides skin along the surface (on the sample's 16-pixel textures, skull-rigid
    vertices by 0.8 % of the face's size), which says nothing of whose head it is."""
    seen = None if neutral.projection is None else neutral.projection.projected
    if mask is not None:
        seen = mask if seen is None else seen & mask
    moved = stabilise(geometric.vertices, neutral.vertices,
                      _seen_rigid(rigid, neutral, mask)).vertices
    note = unlike_neutral(moved, neutral.vertices, neutral.mesh.triangles, rigid, seen)
    return w if note is None else replace(w, warnings=[*w.warnings, note])


def _seen_rigid(rigid: np.ndarray, neutral: WrapResult, seen) -> np.ndarray:
    """The rigid vertices both scans saw: where a wrap only followed (the back of
    the head no scanner reached, a hole), its position says nothing of the pose."""
    keep = np.ones(len(rigid), dtype=bool)
    for mask in (seen, None if neutral.projection is None else neutral.projection.projected):
        if mask is not None:
            keep &= mask[rigid]
    return rigid[keep] if keep.sum() >= max(3, len(rigid) // 10) else rigid


def _checked_rigid(rigid, n: int):
    if rigid is None:
        return None
    ids = np.asarray(rigid).reshape(-1)
    if ids.dtype.kind not in "iu" or len(ids) < 3 or ids.min() < 0 or ids.max() >= n:
        raise ValueError(f"rigid_vertices must be at least 3 vertex ids in [0, {n})")
    return ids.astype(np.int64)


def _checked_expressions(scans, *per_scan):
    """The expression scans and each of their per-scan lists (``(name, items)``
    pairs), an empty list standing for None per scan."""
    scans = list(scans)
    out = [scans]
    for what, items in per_scan:
        items = list(items) or [None] * len(scans)
        if len(items) != len(scans):
            raise ValueError(f"{len(scans)} expression scans but {len(items)} {what}")
        out.append(items)
    return out


def build_rig(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
              scan_landmarks: Landmarks, blendshapes: dict, *,
              settings: WrapSettings | None = None, method: str = "deformation",
              anchors=None, expression_scans: Sequence[Mesh] = (),
              expression_landmarks: Sequence[Landmarks | None] = (),
              expression_weights: Sequence[dict | None] = (), rigid_vertices=None,
              example_settings: ExampleSettings | None = None, texture=None,
              expression_textures: Sequence[np.ndarray | None] = (),
              texture_flow: TextureFlowSettings | None = None,
              expression_scan_trees: Sequence[ClosestPointTree | None] = (),
              **wrap_options) -> Rig:
    """Wrap ``template`` onto a person's scans and make its shapes theirs.

    Parameters
    ----------
    template : Mesh
        The template's neutral.
    scan : Mesh
        The person's neutral scan.
    template_landmarks, scan_landmarks : Landmarks
        As for :func:`~facewrap.wrapping.wrap`.
    blendshapes : dict of str to (n, 3) float
        The template's shapes (positions in its topology): the hybrid model fits
        with them, and each is carried onto the person.
    settings : WrapSettings, optional
        Default: the hybrid model.
    method : {"deformation", "delta"}
        See :func:`~facewrap.rig.personalise_shapes`.
    anchors : (k,) int, optional
        See :func:`~facewrap.rig.personalise_shapes`; default ``rigid_vertices``.
    expression_scans : sequence of Mesh, optional
        Scans of the person's expressions (any head pose): each is wrapped,
        stabilised and used to correct the shapes (:func:`~facewrap.rig.fit_examples`).
    expression_landmarks : sequence of (Landmarks or None), optional
        One per expression scan, paired with ``template_landmarks`` as the
        neutral's are; None (or omitted): the head's pose is found by rigid ICP
        and the neutral's landmarks, carried along, guide the wrap weakly.
    expression_weights : sequence of (dict or None), optional
        One per expression scan: the expression the person was asked to make
        (``{"jawOpen": 1.0}``), a prior for its weights; None: free.
    rigid_vertices : (r,) int, optional
        Skull-rigid template vertices (ICT-FaceKit's ``idx_to_rigid_verts``, from
        the profile).  Default: :func:`~facewrap.rig.least_moving` over the
        template's shapes, among the vertices the neutral scan saw.
    example_settings : ExampleSettings, optional
    texture : (H, W, 3) uint8, optional
        The neutral scan's texture (``scan`` has texture coordinates into it),
        baked into the template's layout (:attr:`Rig.texture`).
    expression_textures : sequence of ((h, w, 3) uint8 or None), optional
        One per expression scan, its texture.  Where the neutral's and an
        expression's are both given, the expression's wrap is refined by them
        (:func:`~facewrap.rig.refine_by_texture`) unless ``texture_flow`` is off.
    texture_flow : TextureFlowSettings, optional
        Default: on (needs OpenCV, the extra ``facewrap[flow]``; without it a
        warning and the geometric wraps).
    expression_scan_trees : sequence of (ClosestPointTree or None), optional
        One per expression scan, a tree already built on it (as ``scan_tree`` is
        for the neutral); None (or omitted): built here, once per scan.
    **wrap_options
        Passed to :func:`~facewrap.wrapping.wrap` (``exclude``, ``fit_mask``, ...)
        and, but ``scan_tree`` (the neutral scan's), to the expression scans' wraps.

    Returns
    -------
    Rig

    Raises
    ------
    ValueError
        The neutral's wrap refused its inputs (the message starts with what it is
        about: ``"scan landmarks: ..."``); a
        :class:`~facewrap.wrapping.track.FrameError` when an expression scan's did,
        its ``frame`` saying which (0-based).

    Examples
    --------
    >>> from facewrap.sample import make_scan, make_template
    >>> tpl = make_template(24)
    >>> scan = make_scan(tpl, weights={})                  # a neutral scan
    >>> rig = build_rig(tpl.mesh, scan.mesh, tpl.landmarks, scan.landmarks,
    ...                 tpl.blendshapes)
    >>> sorted(rig.shapes) == sorted(tpl.blendshapes), rig.neutral.n_vertices
    (True, 1164)
    >>> rig.examples is None
    True
    """
    # before the scan's tree, whose own check names neither mesh ("V must be finite")
    check_mesh(template, "template")
    check_mesh(scan, "scan")
    scans, exp_landmarks, exp_weights, exp_textures, exp_trees = _checked_expressions(
        expression_scans, ("expression_landmarks", expression_landmarks),
        ("expression_weights", expression_weights),
        ("expression_textures", expression_textures),
        ("expression_scan_trees", expression_scan_trees))
    texture_flow = texture_flow or TextureFlowSettings()
    if not isinstance(texture_flow, TextureFlowSettings):
        raise ValueError("texture_flow must be a TextureFlowSettings, got "
                         f"{type(texture_flow).__name__}")
    rigid_vertices = _checked_rigid(rigid_vertices, template.n_vertices)
    t0 = time.perf_counter()
    settings = settings or WrapSettings(model="hybrid")
    # one tree of the neutral scan for its wrap and its texture's bake
    scan_tree = wrap_options.pop("scan_tree", None) or ClosestPointTree(scan.vertices,
                                                                        scan.triangles)
    result = wrap(template, scan, template_landmarks, scan_landmarks, settings,
                  blendshapes=blendshapes, scan_tree=scan_tree, **wrap_options)
    t1 = time.perf_counter()
    timings = {"wrap": t1 - t0}
    bakes = texture is not None and template.uvs is not None and scan.uvs is not None
    wanted = bakes and _flow_wanted(texture_flow, scans, exp_textures)

    def bake():   # the rig's texture and the refinements' reference
        t = time.perf_counter()
        baked = bake_tiles(result.mesh, scan, texture, size=texture_flow.texture_size,
                           tree=scan_tree)
        timings["texture"] = time.perf_counter() - t
        return baked

    # the neutral's bake runs on a thread beside its shapes and the expressions'
    # wraps, and so does each expression's refinement and stabilisation: the
    # pictures, flows and texel work release the GIL where the fit holds it, and
    # once the wraps are done the refinements share the cores (ICT face onto six
    # 200k-triangle scans, bench_rig_speed: 22.4 s instead of 27.1 for the whole
    # rig; the neutral alone: 0.9 s less)
    beside = (ThreadPoolExecutor(usable_threads(), "facewrap-beside")
              if (bakes or scans) and usable_threads() > 1 else None)
    try:
        baking = run_on(beside, bake) if bakes else None
        shapes = personalise_shapes(template, blendshapes, result.mesh, result.transform,
                                    method=method,
                                    anchors=rigid_vertices if anchors is None else anchors)
        t2 = time.perf_counter()
        timings["shapes"] = t2 - t1
        if not scans:
            baked = None if baking is None else baking.result()
            timings["total"] = time.perf_counter() - t0
            return Rig(result.mesh, shapes.shapes, result, method, timings,
                       prior=shapes.shapes, texture=baked)
        rigid = (_least_moving(blendshapes, template, result) if rigid_vertices is None
                 else rigid_vertices)
        example_settings = example_settings or ExampleSettings()
        finish = _finisher(_texture_refiner(template, baking if wanted else None,
                                            exp_textures, texture_flow),
                           _stabiliser(result, rigid, shapes.shapes, exp_weights,
                                       example_settings.weight_prior))
        # BLAS one thread from here on: the views use the cores and the ICP does the
        # same, so no result depends on the overlap; the stabilisation's and the
        # example fit's small dense products (s x s normal matrices) only contend on
        # a loaded machine, as in the ICP (a 3 ms product took up to 0.8 s)
        with threadpool_limits(limits=1, user_api="blas"):
            wraps, refinements, stable, seconds, geometric = _expression_fits(
                template, result, template_landmarks, scans, exp_landmarks, exp_trees,
                rigid, blendshapes, settings, wrap_options, finish, beside)
    finally:
        if beside is not None:   # a wrap that fails drops the refinements not begun
            beside.shutdown(wait=True, cancel_futures=True)
    baked = None if baking is None else baking.result()
    if wanted:   # the refinements' own seconds, beside the wraps
        timings["texture_flow"] = sum(r.seconds for r in refinements if r is not None)
    t3 = time.perf_counter()
    wraps, fit = _corrected(result, shapes.shapes, wraps, geometric, stable, rigid,
                            exp_weights, example_settings)
    t5 = time.perf_counter()
    # the stabilisations ran beside the wraps too: their own seconds
    timings.update(expressions=t3 - t2, stabilise=sum(seconds), examples=t5 - t3,
                   total=t5 - t0)
    return Rig(result.mesh, fit.shapes, result, method, timings, fit, wraps, shapes.shapes,
               refinements, baked)
