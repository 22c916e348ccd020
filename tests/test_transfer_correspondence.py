"""facewrap.transfer.correspondence: find_correspondence, saved correspondences,
markers and settings."""

import numpy as np
import pytest

from facewrap.errors import InputError
from facewrap.geometry import closest_points
from facewrap.sample import make_template
from facewrap.transfer import (Correspondence, CorrespondenceSettings,
                               CorrespondenceStage, DeformationTransfer,
                               find_correspondence, match_triangles)
from transfer_cases import pair


def test_self_correspondence_matches_each_triangle_to_itself():
    full = make_template(20).mesh
    mesh, _ = full.submesh(full.face_groups == 0)
    s, t = match_triangles(mesh.vertices, mesh.triangles, mesh.vertices, mesh.triangles)
    np.testing.assert_array_equal(s, t)
    assert len(s) == len(mesh.triangles)


def test_correspondence_fits_and_round_trips(pair, tmp_path):
    face, scan, markers, _, corr = pair
    assert corr.stats["valid_closest"] > 0.95
    assert len(corr.unmatched_target) == 0
    dist = closest_points(scan.vertices, scan.triangles, corr.deformed).distances
    assert dist.mean() < 2e-3 * scan.scale()
    # markers are hard constraints
    np.testing.assert_allclose(corr.deformed[markers[0]], scan.vertices[markers[1]],
                               atol=1e-9)
    path = tmp_path / "pair.npz"
    corr.save(path)
    back = Correspondence.load(path)
    for name in ("source_triangles", "target_triangles", "markers", "deformed"):
        np.testing.assert_array_equal(getattr(back, name), getattr(corr, name))
    assert back.stats == corr.stats
    back.check(face, scan)
    with pytest.raises(InputError, match="pair.npz"):
        back.check(scan, face, path)


def test_correspondence_file_errors(tmp_path):
    bad = tmp_path / "x.npz"
    np.savez(bad, a=np.zeros(3))
    with pytest.raises(InputError, match="not a facewrap correspondence"):
        Correspondence.load(bad)
    junk = tmp_path / "junk.npz"
    junk.write_text("hello")
    with pytest.raises(InputError, match="junk.npz"):
        Correspondence.load(junk)
    with pytest.raises(InputError, match="no such file"):
        Correspondence.load(tmp_path / "missing.npz")
    mesh = tmp_path / "template.obj"            # a mesh given by mistake
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="not a facewrap correspondence") as err:
        Correspondence.load(mesh)
    assert "pickle" not in str(err.value)


def test_markers_out_of_range_raise(pair):
    face, scan, markers, _, _ = pair
    with pytest.raises(InputError, match="m.cons.*target vertex 99999"):
        find_correspondence(face, scan, (markers[0], markers[1] * 0 + 99999),
                            markers_path="m.cons")


def test_settings_validate():
    with pytest.raises(ValueError, match="closest_weight"):
        CorrespondenceStage(closest_weight=-1)
    with pytest.raises(ValueError, match="smooth_weight"):
        CorrespondenceStage(smooth_weight=0, identity_weight=0)
    with pytest.raises(ValueError, match="deform"):
        CorrespondenceSettings(deform="both")
    with pytest.raises(ValueError, match="anchor"):
        DeformationTransfer(anchor="centre")
    with pytest.raises(ValueError, match="fix_flips"):
        DeformationTransfer(fix_flips=1)
