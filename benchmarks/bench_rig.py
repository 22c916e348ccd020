"""Benchmark: a person's shapes from their neutral scan alone (issue 19, first part).

ICT-FaceKit identities the template has never been fitted to are made into neutral
scans the way the other ground-truth cases are (``_nicp_cases.ict_case``: ICT's
face region, another topology of 60k triangles, noise along the normal, a hole in
the cheek, noisy landmarks, mm and a random rigid motion).  Each is wrapped with
the hybrid model (ICT's 53 expression shapes), then every one of the 53 template
shapes is carried onto the wrapped neutral by deformation transfer
(:func:`facewrap.rig.personalise_shapes`, the default) and, as the baseline, by
adding the template's displacement (``"delta"``).  The truth of shape *k* for
identity *i* is ICT's own model: identity *i* plus shape *k*'s displacement, in the
scan's frame.  Errors are per-vertex distances (mm) over the vertices the scan
sees (the case's mask), per shape; the table gives, over the 53 shapes, the mean
of their means, the worst shape's mean and the mean and worst of their p95s, and
the neutral wrap's own error for reference.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _nicp_cases as cases  # noqa: E402
from facewrap.geometry.similarity import similarity_transform  # noqa: E402
from facewrap.rig import PERSONALISE_METHODS, personalise_shapes  # noqa: E402
from facewrap.wrapping import WrapSettings, wrap  # noqa: E402

#: held-out identities (the wrap benchmarks use 001–003)
IDENTITIES = ("identity004", "identity005", "identity006")


def _truth_shapes(case, identity):
    """Each template shape on this identity, in the scan's frame (mm)."""
    kit = cases.ict_kit()
    V0 = case.template.vertices
    person = V0 + (kit.shape(identity)[:cases.N_FACE] - kit.neutral.vertices[:cases.N_FACE])
    frame = similarity_transform(person, case.truth)          # exact: 10 R, t
    return {k: frame.apply(person + (S - V0)) for k, S in case.blendshapes.items()}


def run_identity(identity: str) -> dict:
    case = cases.ict_case(f"neutral {identity}", identity, {})
    t = time.perf_counter()
    r = wrap(case.template, case.scan, case.landmarks, case.scan_landmarks,
             WrapSettings(model="hybrid"), blendshapes=case.blendshapes)
    wrap_s = time.perf_counter() - t
    neutral_err = np.linalg.norm(r.vertices - case.truth, axis=1)[case.mask]
    truth = _truth_shapes(case, identity)
    row = {"identity": identity, "wrap_s": wrap_s, "neutral_mean": float(neutral_err.mean()),
           "neutral_p95": float(np.percentile(neutral_err, 95)), "methods": {}}
    for method in PERSONALISE_METHODS:
        out = personalise_shapes(case.template, case.blendshapes, r.mesh, r.transform,
                                 method=method)
        errs = {k: np.linalg.norm(out.shapes[k] - truth[k], axis=1)[case.mask]
                for k in truth}
        means = np.array([e.mean() for e in errs.values()])
        p95 = np.array([np.percentile(e, 95) for e in errs.values()])
        worst = list(errs)[int(np.argmax(means))]
        row["methods"][method] = {
            "mean": float(means.mean()), "worst_mean": float(means.max()), "worst": worst,
            "p95": float(p95.mean()), "worst_p95": float(p95.max()),
            "seconds": sum(out.timings.values())}
    return row


def run(quick: bool = False, log=print) -> dict:
    if not cases.ict_available():
        return {"rows": [], "notes": ["skipped: ../shared/data/ict-facekit not found"]}
    rows = []
    for identity in IDENTITIES[:1] if quick else IDENTITIES:
        rows.append(run_identity(identity))
        log(f"rig {identity}: " + ", ".join(
            f"{m} {v['mean']:.3f}/{v['worst_mean']:.3f} mm"
            for m, v in rows[-1]["methods"].items()))
    return {"rows": rows, "notes": []}


def markdown(result: dict) -> str:
    lines = ["## A person's shapes from their neutral scan (issue 19)", "",
             __doc__.split("\n\n", 1)[1].strip(), ""]
    if not result["rows"]:
        return "\n".join(lines + result["notes"]) + "\n"
    lines += ["| identity | neutral wrap mean / p95 (mm) | method | shapes' mean (mm) | "
              "worst shape's mean (mm) | shapes' p95, mean / worst (mm) | 53 shapes (s) |",
              "|---|---|---|---|---|---|---|"]
    for r in result["rows"]:
        for m, v in r["methods"].items():
            lines.append(f"| {r['identity']} | {r['neutral_mean']:.3f} / {r['neutral_p95']:.3f}"
                         f" | {m} | {v['mean']:.3f} | {v['worst_mean']:.3f} ({v['worst']}) | "
                         f"{v['p95']:.3f} / {v['worst_p95']:.3f} | {v['seconds']:.2f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    print(markdown(run(quick="--quick" in sys.argv)))
