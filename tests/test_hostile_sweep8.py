"""Hostile inputs of an eighth sweep: one test per bug class it found.

Classes:

- meshes without a surface reached the commands that check none: ``evaluate`` of
  a PLY point cloud failed with "T must hold at least one triangle" naming no
  file, and measured a scan whose triangles all have zero area (a mesh collapsed
  to a line) as if it were one; ``transfer`` onto or from such a mesh solved it
  silently into garbage (exit status 0).  Each is now refused naming the file, as
  ``wrap`` refuses a scan (:func:`~facewrap.jobs.input_checks.check_surface`);
- ``convert`` of a PLY point cloud to OBJ wrote a file of ``v`` lines that every
  command, ``info`` too, then refused ("no faces ('f' lines)"); it is now refused
  before anything is written, pointing to PLY.

Inputs are the built-in sample at its smallest and tiny meshes written here.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import facewrap
from facewrap.io.dispatch import read_mesh, write_mesh
from facewrap.mesh import Mesh
# the fixture: the built-in sample at its smallest (template 24, scan 40), as files
from test_hostile_more import sample  # noqa: F401
from test_hostile_sweep import error_line


# -- meshes without a surface --------------------------------------------------------------
def collapsed(path, out):
    """The mesh at ``path`` with every triangle's third corner moved onto its second
    (all of zero area), written to ``out``."""
    mesh = read_mesh(path)
    T = mesh.triangles.copy()
    T[:, 2] = T[:, 1]
    write_mesh(out, Mesh(mesh.vertices, T))
    return out


def test_evaluate_and_transfer_refuse_a_mesh_without_a_surface(sample, tmp_path, capsys):
    cloud = tmp_path / "cloud.ply"
    write_mesh(cloud, Mesh(read_mesh(sample["scan"]).vertices, np.zeros((0, 3), int)))
    flat = collapsed(sample["scan"], tmp_path / "flat.obj")
    for scan, problem in ((cloud, "has no faces"), (flat, "scan is degenerate")):
        rc = facewrap("evaluate", sample["template"], scan, "-q")
        error_line(capsys, rc, str(scan), problem)
    rc = facewrap("evaluate", cloud, sample["scan"], "-q")
    error_line(capsys, rc, str(cloud), "has no faces")
    markers = tmp_path / "markers.txt"
    markers.write_text("0 0\n50 50\n99 99\n")
    shapes = sample["blendshapes/blink"].parent
    flat_template = collapsed(sample["template"], tmp_path / "flat_template.obj")
    for k, (source, target) in enumerate(((sample["template"], flat_template),
                                          (flat_template, sample["template"]))):
        out = tmp_path / f"out{k}"
        rc = facewrap("transfer", source, target, "--source-shapes", shapes,
                      "--markers", markers, "-o", out, "-q")
        error_line(capsys, rc, str(flat_template), "neutral is degenerate")
        assert not out.exists()


def test_convert_refuses_a_point_cloud_to_obj(sample, tmp_path, capsys):
    cloud = tmp_path / "cloud.ply"
    write_mesh(cloud, Mesh(read_mesh(sample["scan"]).vertices, np.zeros((0, 3), int)))
    out = tmp_path / "cloud.obj"
    error_line(capsys, facewrap("convert", cloud, out), str(cloud), "has no faces")
    assert not out.exists()
    assert facewrap("convert", cloud, tmp_path / "again.ply") == 0
    assert read_mesh(tmp_path / "again.ply").n_vertices == read_mesh(cloud).n_vertices
