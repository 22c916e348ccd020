"""facewrap.transfer.ambiguity: where the result depends on the correspondence."""

import numpy as np
import pytest

from transfer_cases import pair, random_rotation


def test_partner_ambiguity_finds_the_crease_and_not_rigid_motion(pair):
    """Candidates agree under a rigid motion (ambiguity ~0) and disagree along a
    crease (half the face hinged by 40°): target triangles there rank highest,
    and the first marker hint lies on it."""
    from facewrap.transfer.ambiguity import ambiguity_summary, partner_ambiguity
    face, scan, _, _, corr = pair
    V = face.vertices
    c = V.mean(axis=0)
    R = random_rotation(np.random.default_rng(7))
    rigid = partner_ambiguity(corr, face, scan, (V - c) @ R.T + c)
    assert np.nanmax(rigid) < 1e-6
    angle = np.radians(40)
    hinge = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0],
                      [-np.sin(angle), 0, np.cos(angle)]])
    folded = V.copy()
    right = V[:, 0] > c[0]
    folded[right] = (V[right] - c) @ hinge.T + c
    amb = partner_ambiguity(corr, face, scan, folded, neighbours=8)
    T = scan.triangles
    x = scan.vertices[T].mean(axis=1)[:, 0] - c[0]
    edge = np.median(np.linalg.norm(V[face.triangles[:, 0]] - V[face.triangles[:, 1]],
                                    axis=1))
    near, far = np.abs(x) < 1.5 * edge, np.abs(x) > 6 * edge
    assert np.nanmean(amb[near]) > 20 * np.nanmean(amb[far])
    summary = ambiguity_summary(amb, scan, count=5)
    hints = summary["marker_hints"]
    assert 1 <= len(hints) <= 5 and abs(scan.vertices[hints[0], 0] - c[0]) < 2 * edge
    gaps = [np.linalg.norm(scan.vertices[a] - scan.vertices[b])
            for i, a in enumerate(hints) for b in hints[i + 1:]]
    assert min(gaps, default=np.inf) >= 0.05 * scan.scale() - 1e-9
    assert summary["p90"] >= summary["median"] >= 0
    with pytest.raises(ValueError, match="one value per target triangle"):
        ambiguity_summary(amb[:-1], scan)
