"""Benchmark: a person's shapes from their scans (issue 19).

**Neutral only.**
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

**With example scans.**  Identity 004 is made a person whose expressions are not
ICT's: a smile 1.4 times stronger on their left (ICT's ``mouthSmile_L/R`` with a
smooth per-side gain, 1.0 on the right), a jaw that opens with a twist (their
``jawOpen`` is ICT's plus 0.35 ``jawLeft``) and brows that rise unevenly (the four
brow-raising shapes at 1.3 on the left, 0.8 on the right).  Six of their
expressions are scanned the way the neutral is (another topology, noise, a hole,
noisy landmarks), each with a random head motion of 5–15 degrees and 5–20 mm
on top of the neutral scan's pose, and given to
:func:`facewrap.rig.build_rig` with the expression each was meant to be (its
weights, the capture's script).  Reported, over the neutral scan's seen vertices
(mm): each example's reconstruction by the rig at its fitted weights against the
truth (and against its own stabilised wrap, next to the neutral-only rig's at its
best weights), the stabilisation's error (the found pose applied to the moved
truth, against the unmoved truth), and held-out expressions of the person (not
among the six) made by each rig at their own weights against the truth.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _nicp_cases as cases  # noqa: E402
from facewrap.geometry.similarity import Similarity, similarity_transform  # noqa: E402
from facewrap.rig import PERSONALISE_METHODS, build_rig, personalise_shapes  # noqa: E402
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


#: the person given example scans
EXAMPLE_IDENTITY = "identity004"
_SMILE = ("mouthSmile_L", "mouthSmile_R")
_BROWS = ("browInnerUp_L", "browInnerUp_R", "browOuterUp_L", "browOuterUp_R")
#: the six scanned expressions, as meant (weights of ICT's shapes)
EXAMPLES = ({k: 1.0 for k in _SMILE}, {"jawOpen": 1.0}, {k: 1.0 for k in _BROWS},
            {"mouthSmile_L": 0.6, "mouthSmile_R": 0.6, "jawOpen": 0.5},
            {"jawOpen": 0.7, "browInnerUp_L": 0.8, "browInnerUp_R": 0.8},
            {"mouthSmile_L": 1.0, "jawOpen": 0.3, "browOuterUp_L": 0.6,
             "browOuterUp_R": 0.6})
#: expressions of the person not among the examples
HELD_OUT = ({k: 0.5 for k in _SMILE}, {"jawOpen": 0.5}, {k: 0.5 for k in _BROWS},
            {"jawOpen": 0.8, "mouthSmile_L": 0.8, "mouthSmile_R": 0.8},
            {"mouthSmile_R": 1.0, "browInnerUp_R": 1.0, "browOuterUp_R": 1.0})


def _side(x, left, right, width=0.8):
    """A gain of ``left`` on the face's left (x > 0, cm), ``right`` on its right."""
    return (right + (left - right) / (1.0 + np.exp(-x / width)))[:, None]


def person_displacements(V0, shapes):
    """The person's own displacement of each shape (cm, the template's topology)."""
    out = {k: S - V0 for k, S in shapes.items()}
    for k in _SMILE:
        out[k] = _side(V0[:, 0], 1.4, 1.0) * out[k]
    for k in _BROWS:
        out[k] = _side(V0[:, 0], 1.3, 0.8) * out[k]
    out["jawOpen"] = out["jawOpen"] + 0.35 * (shapes["jawLeft"] - V0)
    return out


def _head_motion(rng):
    """A rotation of 5-15 degrees about a random axis and a 5-20 mm translation."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    a = np.radians(rng.uniform(5, 15))
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    t = rng.normal(size=3)
    return Similarity(np.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K,
                      t * rng.uniform(5, 20) / np.linalg.norm(t), 1.0)


def _blend(neutral, shapes, weights):
    return neutral + sum(w * (shapes[k] - neutral) for k, w in weights.items())


def _example_cases(identity, examples, n_triangles: int = 60000):
    """The neutral case, the person's model and each example's case and motion,
    scanned with about ``n_triangles`` triangles."""
    kit = cases.ict_kit()
    size = "" if n_triangles == 60000 else f" {n_triangles}"
    neutral = cases.ict_case(f"neutral {identity}{size}", identity, {},
                             n_triangles=n_triangles)
    V0 = neutral.template.vertices
    face = V0 + (kit.shape(identity)[:cases.N_FACE] - kit.neutral.vertices[:cases.N_FACE])
    own = person_displacements(V0, neutral.blendshapes)
    frame = similarity_transform(face, neutral.truth)          # exact: 10 R, t
    rng = np.random.default_rng(19)
    out = []
    for j, w in enumerate(examples):
        m = _head_motion(rng)
        P = face + sum(x * own[k] for k, x in w.items())
        rigid = (m.rotation @ frame.rotation, m.rotation @ frame.translation + m.translation)
        out.append((cases.ict_case(f"rig example {identity} {j}{size}", identity, {},
                                   person=P, rigid=rigid, seed=j + 1,
                                   n_triangles=n_triangles), m))
    return neutral, face, own, frame, out


def run_examples(identity: str = EXAMPLE_IDENTITY, examples=EXAMPLES) -> dict:
    neutral, face, own, frame, made = _example_cases(identity, examples)
    t = time.perf_counter()
    rig = build_rig(neutral.template, neutral.scan, neutral.landmarks,
                    neutral.scan_landmarks, neutral.blendshapes,
                    expression_scans=[c.scan for c, _ in made],
                    expression_landmarks=[c.scan_landmarks for c, _ in made],
                    expression_weights=list(examples))
    seconds = time.perf_counter() - t
    mask, V = neutral.mask, rig.neutral.vertices
    truth_of = lambda w: frame.apply(face + sum(x * own[k] for k, x in w.items()))  # noqa: E731
    rows = []
    for j, ((case, motion), w) in enumerate(zip(made, examples)):
        fitted = rig.examples.weights[j]
        truth = truth_of(w)
        err = np.linalg.norm(_blend(V, rig.shapes, fitted) - truth, axis=1)[mask]
        pose = np.linalg.norm(rig.examples.poses[j].apply(case.truth) - truth, axis=1)[mask]
        turned = np.degrees(np.arccos(np.clip((np.trace(motion.rotation) - 1) / 2, -1, 1)))
        rows.append({"meant": w, "mean": float(err.mean()), "p95": float(np.percentile(err, 95)),
                     "wrap": rig.examples.errors[j], "prior": rig.examples.prior_errors[j],
                     "stabilised": float(pose.mean()), "stabilised_max": float(pose.max()),
                     "motion": (float(turned), float(np.linalg.norm(motion.translation))),
                     "weights": {k: x for k, x in fitted.items() if x > 0.05}})
    held = []
    for w in HELD_OUT:
        truth = truth_of(w)
        held.append({"weights": w, **{name: float(np.linalg.norm(
            _blend(V, S, w) - truth, axis=1)[mask].mean())
            for name, S in (("rig", rig.shapes), ("neutral_only", rig.prior))}})
    return {"identity": identity, "examples": rows, "held_out": held,
            "timings": dict(rig.timings, seconds=seconds), "k": len(examples)}


def run(quick: bool = False, log=print) -> dict:
    if not cases.ict_available():
        return {"rows": [], "notes": ["skipped: ../shared/data/ict-facekit not found"]}
    rows = []
    for identity in IDENTITIES[:1] if quick else IDENTITIES:
        rows.append(run_identity(identity))
        log(f"rig {identity}: " + ", ".join(
            f"{m} {v['mean']:.3f}/{v['worst_mean']:.3f} mm"
            for m, v in rows[-1]["methods"].items()))
    ex = run_examples(examples=EXAMPLES[:3] if quick else EXAMPLES)
    log("rig examples: " + ", ".join(f"{r['mean']:.3f}" for r in ex["examples"]) + " mm; "
        "stabilised " + ", ".join(f"{r['stabilised']:.3f}" for r in ex["examples"]) + " mm")
    return {"rows": rows, "examples": ex, "notes": []}


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
    if result.get("examples"):
        lines += [""] + _examples_markdown(result["examples"])
    return "\n".join(lines) + "\n"


def _weights_text(w):
    return ", ".join(f"{k} {x:.2f}" for k, x in w.items())


def _examples_markdown(ex: dict) -> list[str]:
    lines = [f"With {ex['k']} example scans of {ex['identity']} (mm; times measured under "
             "load):", "",
             "| example (meant) | head motion | rig vs truth, mean / p95 | rig vs its wrap, "
             "mean / p95 | neutral-only rig vs its wrap, mean | stabilisation, mean / max | "
             "fitted weights > 0.05 |", "|---|---|---|---|---|---|---|"]
    for r in ex["examples"]:
        lines.append(f"| {_weights_text(r['meant'])} | {r['motion'][0]:.1f}°, "
                     f"{r['motion'][1]:.1f} mm | {r['mean']:.3f} / {r['p95']:.3f} | "
                     f"{r['wrap']['mean']:.3f} / {r['wrap']['p95']:.3f} | "
                     f"{r['prior']['mean']:.3f} | {r['stabilised']:.3f} / "
                     f"{r['stabilised_max']:.3f} | {_weights_text(r['weights'])} |")
    lines += ["", "| held-out expression | rig vs truth, mean | neutral-only rig vs truth, "
              "mean |", "|---|---|---|"]
    for h in ex["held_out"]:
        lines.append(f"| {_weights_text(h['weights'])} | {h['rig']:.3f} | "
                     f"{h['neutral_only']:.3f} |")
    t = ex["timings"]
    lines += ["", f"Times (s): neutral wrap {t['wrap']:.2f}, 53 shapes {t['shapes']:.2f}, "
              f"{ex['k']} expression wraps {t['expressions']:.2f} "
              f"({t['expressions'] / ex['k']:.2f} each), stabilisation {t['stabilise']:.3f}, "
              f"example fit {t['examples']:.2f}; total {t['total']:.2f}."]
    return lines


if __name__ == "__main__":
    print(markdown(run(quick="--quick" in sys.argv)))
