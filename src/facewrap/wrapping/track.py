"""4D tracking: register a sequence of scans of one performer, frame after frame.

Frame 0 is a normal :func:`~facewrap.wrapping.wrap` (it needs landmarks).  Every
later frame starts from the previous result: its similarity replaces the
landmark alignment and its blend weights start the fit (see
:func:`tracking_schedule`).  Where a frame has no landmarks of its own, the
fitted landmark positions of the previous frames, moved on at their last
velocity and onto the new scan (closest points), stand in for them with a
small weight (:data:`PROPAGATED_LANDMARKS`).

:func:`track` returns a :class:`TrackResult` with one :class:`~facewrap.wrapping.stages.WrapResult`
per frame, the per-frame blend weights and the fit over time;
:func:`write_track_outputs` writes the numbered OBJ sequence, the weights as
CSV and a JSON report.
"""

from __future__ import annotations

import csv
import io as _io
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from facewrap.geometry import ClosestPointTree
from facewrap.io import write_mesh
from facewrap.io.atomic import atomic_write
from facewrap.io.mtl import with_library
from facewrap.io.paths import staged_outputs
from facewrap.landmarks import Landmarks
from facewrap.mesh import Mesh, check_mesh
from facewrap.params import expect_instance
from facewrap.wrapping.icp.schedule import Stage
from facewrap.wrapping.models import default_schedule, model_spec
from facewrap.wrapping.models.graph import GraphCache
from facewrap.wrapping.settings import WrapSettings
from facewrap.wrapping.stages import WrapResult, wrap

__all__ = ["TrackResult", "FrameError", "track", "tracking_schedule", "wrap_following",
           "write_track_outputs"]

#: landmark weight factor of frames whose landmarks are predicted from the previous
#: frames.  Larger factors let the lag of the first, unpredicted frame compound
#: over the sequence; the velocity prediction matters as much (on the sample's
#: ramp with landmarks on frame 0 only; docs/benchmarks.md).
PROPAGATED_LANDMARKS = 0.05
#: a frame fitted without landmarks of its own whose fit stays farther than this
#: fraction of the first frame's head size from its scan (p95) is warned about:
#: another scan than the sequence's (the sample with a sphere as frame 1: 15 %; a
#: smile of the same face under the rbf model, which cannot follow it: 3.6 %)
FRAME_FIT_LIMIT = 0.08


def tracking_schedule(model: str) -> list[Stage] | None:
    """The schedule of frames after the first: the model's default schedule
    without its landmark-only stages (the warm start is already close); None for
    a model with no ICP (rigid, rbf: fitted in closed form every frame).

    Where a frame has no landmarks of its own, :func:`track` also lowers every
    landmark weight (``WrapSettings.landmark_scale`` × 0.05): landmarks carried
    over from the previous frame would hold the face where it *was*, so they
    only guard against gross failure and the scan surface drives the fit; they
    never pull the result (``WrapSettings.landmark_pull`` is off there).
    """
    if not model_spec(model).fitted_by_icp:
        return None
    return [st for st in default_schedule(model) if st.data_weight > 0]


@dataclass
class TrackResult:
    """Outcome of :func:`track`.

    Attributes
    ----------
    frames : list of WrapResult
    weights : (F, K) float64 or None
        Blend weights per frame (blendshape / hybrid models).
    shape_names : list of str
    landmarks_given : (F,) bool
        Whether each frame had its own landmarks (else they were propagated).
    """
    frames: list
    weights: np.ndarray | None
    shape_names: list
    landmarks_given: np.ndarray

    def summary(self) -> list[dict]:
        """Per-frame numbers (fit, landmarks, iterations, seconds) and the frame's
        input warnings (:attr:`WrapResult.warnings`)."""
        out = []
        for i, r in enumerate(self.frames):
            row = {"frame": i, "landmarks_given": bool(self.landmarks_given[i]),
                   "iterations": len(r.history), "seconds": r.timings.get("total"),
                   "warnings": list(r.warnings)}
            row.update({k: v for k, v in r.metrics.items() if not isinstance(v, dict)})
            out.append(row)
        return out


def _propagated_landmarks(previous: WrapResult, template_landmarks: Landmarks,
                          tree: ClosestPointTree, before: WrapResult | None = None
                          ) -> Landmarks:
    """Landmarks for a frame that has none: where the fit put them on the
    previous frame, moved on by their last velocity (constant-velocity
    prediction, when two frames are known), then onto this frame's scan."""
    P = template_landmarks.positions(previous.mesh)
    if before is not None:
        P = 2.0 * P - template_landmarks.positions(before.mesh)
    return Landmarks.from_points(tree.query(P).points, names=template_landmarks.names)


def wrap_following(template: Mesh, scan: Mesh, template_landmarks: Landmarks,
                   scan_landmarks: Landmarks | None, previous: WrapResult,
                   settings: WrapSettings | None = None, *, before: WrapResult | None = None,
                   blendshapes=None, scan_tree: ClosestPointTree | None = None,
                   **options) -> WrapResult:
    """One scan wrapped warm-started from ``previous`` (a later frame of :func:`track`).

    ``previous``'s similarity and blend weights start the fit, with
    :func:`tracking_schedule` unless ``settings.stages`` is set.  Without
    ``scan_landmarks``, the landmarks are predicted from ``previous`` (and
    ``before``, the frame before it: constant velocity), put onto the scan and
    weighted by :data:`PROPAGATED_LANDMARKS`.  Other arguments (and ``options``:
    ``exclude``, ``graph_cache``, ...) as for :func:`~facewrap.wrapping.wrap`;
    ``settings`` are the first frame's.
    """
    s0 = settings or WrapSettings()
    tree = scan_tree or ClosestPointTree(scan.vertices, scan.triangles)
    given = scan_landmarks is not None
    lm = scan_landmarks if given else _propagated_landmarks(previous, template_landmarks,
                                                            tree, before)
    model = previous.settings.model
    # carried-over landmarks are predictions: they guide, they never pull
    s = replace(s0, model=model, stages=s0.stages or tracking_schedule(model),
                landmark_scale=s0.landmark_scale * (1.0 if given else PROPAGATED_LANDMARKS),
                landmark_pull=s0.landmark_pull and given)
    return wrap(template, scan, template_landmarks, lm, s, blendshapes=blendshapes,
                scan_tree=tree, initial=previous, **options)


def track(template: Mesh, scans, template_landmarks: Landmarks, scan_landmarks,
          settings: WrapSettings | None = None, *, blendshapes=None, exclude=None,
          progress=None, graph_cache: GraphCache | None = None,
          first_settings: WrapSettings | None = None) -> TrackResult:
    """Register ``template`` to every scan of a sequence.

    Parameters
    ----------
    template : Mesh
    scans : sequence of Mesh
        The frames, in order.
    template_landmarks : Landmarks
    scan_landmarks : sequence of (Landmarks or None)
        One entry per frame; the first must be given, the others may be None.
    settings : WrapSettings, optional
        For the first frame; later frames use :func:`tracking_schedule` unless
        ``settings.stages`` is set.
    blendshapes : dict name -> (n, 3), optional
    exclude : vertex ids or mask, optional
    progress : callable(frame_index, WrapResult), optional
        Called after each frame.
    graph_cache : GraphCache, optional
        Passed to every :func:`~facewrap.wrapping.wrap` (default: the shared cache).
    first_settings : WrapSettings, optional
        The first frame's wrap alone (default ``settings``): detected landmarks
        weigh less there (:func:`~facewrap.detection.for_wrap.detected_landmark_settings`)
        than the fitted landmarks the later frames carry over.

    Returns
    -------
    TrackResult
    """
    scans = list(scans)
    scan_landmarks = list(scan_landmarks)
    if not scans:
        raise ValueError("track needs at least one scan")
    if len(scan_landmarks) != len(scans):
        raise ValueError(f"{len(scans)} scans but {len(scan_landmarks)} landmark entries")
    if scan_landmarks[0] is None:
        raise ValueError("the first frame needs landmarks")
    s0 = settings or WrapSettings()
    frames, given = [], []
    previous = None
    for i, scan in enumerate(scans):
        expect_instance(scan, Mesh, f"scans[{i}]")
        lm = scan_landmarks[i]
        given.append(lm is not None)
        try:
            check_mesh(scan, "scan")   # before its tree, which would name no argument
            tree = ClosestPointTree(scan.vertices, scan.triangles)
            if previous is None:
                result = wrap(template, scan, template_landmarks, lm, first_settings or s0,
                              exclude=exclude, blendshapes=blendshapes, scan_tree=tree,
                              graph_cache=graph_cache)
            else:
                result = wrap_following(template, scan, template_landmarks, lm, previous,
                                        s0, before=frames[-2] if len(frames) > 1 else None,
                                        exclude=exclude, blendshapes=blendshapes,
                                        scan_tree=tree, graph_cache=graph_cache)
        except ValueError as exc:
            raise FrameError(i, str(exc)) from None
        size = (frames[0] if frames else result).mesh.scale()
        if lm is None and result.metrics.get("fit_p95", 0.0) > FRAME_FIT_LIMIT * size:
            result.warnings.append(
                f"scan: the fit of this frame, which has no landmarks of its own, "
                f"stays {result.metrics['fit_p95']:.3g} from it (p95, scan units; "
                f"{100 * result.metrics['fit_p95'] / size:.0f} % of the head's size in frame 0): "
                "a scan of another sequence or no face?")
        frames.append(result)
        if progress is not None:
            progress(i, result)
        previous = result
    weights = None
    if frames[0].weights is not None:
        weights = np.stack([r.weights for r in frames])
    return TrackResult(frames, weights, list(frames[0].shape_names), np.array(given))


class FrameError(ValueError):
    """A frame's wrap refused its inputs; ``frame`` is which (0-based), the message
    the wrap's ("scan landmarks: ...", so a caller can name the file)."""

    def __init__(self, frame: int, message: str):
        super().__init__(message)
        self.frame = frame


def track_output_files(folder, n_frames: int, *, prefix: str = "frame",
                       weights: bool = True) -> list[Path]:
    """The files :func:`write_track_outputs` writes for ``n_frames`` frames.

    Known before the fit, so a command can check them against its inputs.

    Examples
    --------
    >>> [p.name for p in track_output_files("out", 2, weights=False)]
    ['frame_0000.obj', 'frame_0001.obj', 'track.json']
    """
    folder = Path(folder)
    width = max(4, len(str(n_frames - 1)))
    meshes = [folder / f"{prefix}_{i:0{width}d}.obj" for i in range(n_frames)]
    return meshes + ([folder / "weights.csv"] if weights else []) + [folder / "track.json"]


def write_track_outputs(folder, result: TrackResult, *, prefix: str = "frame",
                        extra_report: dict | None = None,
                        output_frame: str = "scan") -> dict:
    """Write ``prefix_0000.obj``…, ``weights.csv`` and ``track.json`` into ``folder``.

    The files are staged and moved into ``folder`` together
    (:func:`facewrap.io.paths.staged_outputs`): a failure leaves none of them.
    ``output_frame="template"`` writes every frame mapped back through the inverse
    of the first frame's landmark similarity (one map for the whole sequence, so
    the performer's head motion relative to frame 0 is kept); ``"scan"`` (the
    default) writes them where the scans are.  ``track.json`` records it.  The
    frames name no material library (the template's is not written beside them).
    Returns the paths written.
    """
    if output_frame not in ("scan", "template"):
        raise ValueError(f"output_frame must be 'scan' or 'template', got {output_frame!r}")
    has_weights = result.weights is not None
    final = track_output_files(folder, len(result.frames), prefix=prefix,
                               weights=has_weights)
    back = result.frames[0].transform.inverse() if output_frame == "template" else None
    with staged_outputs() as stage:
        staged = stage.folder(folder)
        for path, r in zip(final, result.frames):
            mesh = r.mesh if back is None else r.mesh.with_vertices(back.apply(r.vertices))
            # the template's mtllib is not beside the frames: name none (materials kept)
            write_mesh(staged / path.name, with_library(mesh, None))
        if has_weights:
            buf = _io.StringIO()
            w = csv.writer(buf, lineterminator="\n")
            w.writerow(["frame", *result.shape_names])
            for i, row in enumerate(result.weights):
                w.writerow([i, *(f"{x:.6f}" for x in row)])
            with atomic_write(staged / "weights.csv", "w") as fh:
                fh.write(buf.getvalue())
        report = {"frames": result.summary(), "output_frame": output_frame,
                  **(extra_report or {})}
        with atomic_write(staged / "track.json", "w") as fh:
            json.dump(report, fh, indent=1)
    paths = {"meshes": final[:len(result.frames)]}
    if has_weights:
        paths["weights"] = final[-2]
    paths["report"] = final[-1]
    return paths
