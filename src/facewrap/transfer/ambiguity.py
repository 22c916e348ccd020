"""Where a transfer depends on the correspondence: partner ambiguity per target triangle.

Deformation transfer copies each target triangle's deformation from its source
partners, and the partners come from a nearest-centroid match on the deformed
source.  Where the source deforms smoothly, any nearby partner gives the same
gradient and the choice does not matter; where it does not (skin folding between a
leg and the body, lips, eyelids), a partner one triangle over gives another
deformation, and the result depends on exactly how the correspondence slid.

:func:`partner_ambiguity` measures that: for each target triangle, the spread of
the source pose gradients over its ``k`` nearest compatible source triangles (the
candidates the match chose from), averaged over the poses.  It is a
dimensionless strain: 0.1 means candidates a few triangles apart deform 10 %
differently.  On Sumner's cat → lion poses it ranks
the error of the transferred lion gradients against Sumner's own results well, the
most ambiguous triangles carry several times the error of the rest, and the
suggested marker places are the lower flanks and belly, where the study in
``benchmarks/studies/cat_lion_oracle`` found half of the error (figures in
docs/benchmarks.md, from ``benchmarks/bench_transfer.py``).
:func:`ambiguity_summary` turns it into the few target vertices where more markers
would help most.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from facewrap.mesh import Mesh
from facewrap.transfer.correspondence import Correspondence
from facewrap.transfer.triangle_matching import triangle_centroids_normals
from facewrap.transfer.gradients import gradient_operator
from facewrap.transfer.deformation import as_pose_stack, source_gradient_blocks

__all__ = ["partner_ambiguity", "ambiguity_summary"]

#: poses whose gradients are held at once (k x source triangles x 9 floats each)
_POSE_CHUNK = 8


def partner_ambiguity(correspondence: Correspondence, source: Mesh, target: Mesh,
                      poses, neighbours: int = 8) -> np.ndarray:
    """Spread of the candidate partners' pose gradients, per target triangle.

    Parameters
    ----------
    correspondence : Correspondence
        Of ``source`` and ``target`` (its deformed mesh places the two together).
    source, target : Mesh
        The reference meshes.
    poses : (k, n_source, 3) or (n_source, 3) float
        Source poses (the ones to transfer).
    neighbours : int
        Candidates per target triangle: its nearest source triangles by centroid
        whose normals are within 90°.

    Returns
    -------
    (n_target_triangles,) float64
        Root-mean-square distance (Frobenius) of the candidates' deformation
        gradients from their mean, averaged over the poses; NaN where no candidate
        is compatible.

    Examples
    --------
    >>> from facewrap.sample import make_template
    >>> from facewrap.transfer import find_correspondence
    >>> face = make_template(resolution=24).mesh
    >>> corr = find_correspondence(face, face, (np.arange(0, 500, 50),) * 2)
    >>> a = partner_ambiguity(corr, face, face, face.vertices * 1.1)  # uniform scale
    >>> float(np.nanmax(a)) < 1e-6
    True
    """
    correspondence.check(source, target)
    P, _ = as_pose_stack(poses, source.n_vertices)
    k = max(1, min(int(neighbours), len(source.triangles)))
    if correspondence.deformed_mesh == "source":
        cs, ns = triangle_centroids_normals(correspondence.deformed, source.triangles)
        ct, nt = triangle_centroids_normals(target.vertices, target.triangles)
    else:
        cs, ns = triangle_centroids_normals(source.vertices, source.triangles)
        ct, nt = triangle_centroids_normals(correspondence.deformed, target.triangles)
    _, nb = cKDTree(cs).query(ct, k=k)
    nb = nb.reshape(len(ct), k)
    ok = np.einsum("ikj,ij->ik", ns[nb], nt) > 0
    count = ok.sum(axis=1)
    w = ok[..., None].astype(np.float64)
    op = gradient_operator(source.vertices, source.triangles)
    total = np.zeros(len(ct))
    for start in range(0, len(P), _POSE_CHUNK):
        for S in source_gradient_blocks(op, P[start:start + _POSE_CHUNK]):
            g = S[nb]                                               # (t, k, 9)
            mean = (g * w).sum(axis=1) / np.maximum(count, 1)[:, None]
            spread = (((g - mean[:, None]) ** 2) * w).sum(axis=(1, 2))
            total += np.sqrt(spread / np.maximum(count, 1))
    out = total / len(P)
    out[count == 0] = np.nan
    return out


def ambiguity_summary(ambiguity, target: Mesh, count: int = 10,
                      separation: float = 0.05) -> dict:
    """Distribution of :func:`partner_ambiguity` and where to add markers.

    Parameters
    ----------
    ambiguity : (n_target_triangles,) float
    target : Mesh
    count : int
        At most this many target vertices to suggest.
    separation : float
        Suggested vertices lie at least this far apart (fraction of the target's
        bounding-box diagonal), so each names another region.

    Returns
    -------
    dict
        ``median``, ``p90``, ``max`` (over triangles with candidates) and
        ``marker_hints``: target vertex ids, most ambiguous first (a vertex takes
        the largest ambiguity of its triangles).
    """
    a = np.asarray(ambiguity, dtype=np.float64)
    T = target.triangles
    if a.shape != (len(T),):
        raise ValueError(f"ambiguity must have one value per target triangle "
                         f"({len(T)}), got shape {a.shape}")
    V = target.vertices
    known = np.isfinite(a)
    per_vertex = np.full(len(V), -np.inf)
    np.maximum.at(per_vertex, T[known].ravel(), np.repeat(a[known], 3))
    gap = separation * target.scale()
    hints = []
    for v in np.argsort(-per_vertex):
        if len(hints) >= count or not np.isfinite(per_vertex[v]):
            break
        if all(np.linalg.norm(V[v] - V[h]) >= gap for h in hints):
            hints.append(int(v))
    vals = a[known]
    return {"median": float(np.median(vals)) if len(vals) else None,
            "p90": float(np.percentile(vals, 90)) if len(vals) else None,
            "max": float(vals.max()) if len(vals) else None,
            "marker_hints": hints}
