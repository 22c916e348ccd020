"""facewrap.avatar.parts: part frames, part motions, parts files."""

import json
import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.geometry import vertex_normals
from facewrap.avatar import IBUG51_PARTS, part_frame, part_motions, read_parts
from avatar_cases import MOVE, R90, template


def test_default_parts_cover_the_51_points_once():
    owned = np.concatenate([p.landmarks for p in IBUG51_PARTS])
    assert sorted(owned.tolist()) == list(range(51))
    assert [p.name for p in IBUG51_PARTS if p.is_mouth] == ["mouth"]


def test_part_frame_is_a_rotation_with_outward_normal(template):
    face, lm51, _ = template
    P = face.vertices[lm51]
    N = vertex_normals(face.vertices, face.triangles)[lm51]
    for part in IBUG51_PARTS:
        R, extent = part_frame(P, N, part)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) > 0
        assert R[2] @ N[list(part.landmarks)].mean(axis=0) > 0
        assert np.all(extent >= 0)


def test_part_motion_of_a_similar_copy_is_the_similarity(template):
    face, lm51, _ = template
    P = face.vertices[lm51]
    N = vertex_normals(face.vertices, face.triangles)[lm51]
    M, owner, info = part_motions(P, N, MOVE.apply(P), MOVE.apply_vectors(N))
    for k, part in enumerate(IBUG51_PARTS):
        if part.is_mouth:       # z ratio fixed to 1: only in-plane motion scales
            np.testing.assert_allclose(info[k]["ratio"][:2], MOVE.scale, rtol=1e-9)
            continue
        np.testing.assert_allclose(M[k], MOVE.scale * R90, atol=1e-9)
    assert (owner >= 0).all()


def test_read_parts_round_trip_and_errors(tmp_path):
    items = []
    for p in IBUG51_PARTS:
        it = {"name": p.name, "landmarks": [[p.landmarks[0], p.landmarks[-1]]],
              "frame": list(p.frame), "axis": list(p.axis)}
        if p.is_mouth:
            it["mouth"] = {"nose_bottom": p.nose_bottom, "lower_lip": list(p.lower_lip)}
        items.append(it)
    f = tmp_path / "parts.json"
    f.write_text(json.dumps({"format": "facewrap.parts", "version": 1, "parts": items}))
    assert read_parts(f) == IBUG51_PARTS
    f.write_text(json.dumps({"format": "facewrap.parts", "parts": [
        {"name": "eye", "landmarks": [[3, 1]], "axis": [0, 1]}]}))
    with pytest.raises(InputError, match="parts.json.*range"):
        read_parts(f)
    f.write_text("{")
    with pytest.raises(InputError, match="parts.json:1"):
        read_parts(f)
