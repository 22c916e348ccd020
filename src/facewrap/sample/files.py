"""Writing the sample as plain files that any tool (or the CLI) can read."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from facewrap.io.atomic import atomic_write
from facewrap.io.images import save_png
from facewrap.io.landmarks import write_points, write_vertex_indices
from facewrap.io.obj import write_obj
from facewrap.mesh import Mesh
from facewrap.sample.scan import SampleScan, make_scan
from facewrap.sample.surface import EXPRESSIONS
from facewrap.sample.template import SampleTemplate, make_template

__all__ = ["sample_paths", "write_sample"]

_MTL = "newmtl skin\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nd 1\nillum 1\nmap_Kd scan_texture.png\n"


def sample_paths(folder, expressions=EXPRESSIONS) -> dict[str, Path]:
    """Where :func:`write_sample` writes each file of the sample, without writing.

    Parameters
    ----------
    folder : str or os.PathLike
    expressions : iterable of str
        The template's blendshape names (default :data:`EXPRESSIONS`, those of
        ``make_template()``).

    Returns
    -------
    dict of str to Path
        The keys of :func:`write_sample`'s result, in the order it writes them.

    Examples
    --------
    >>> sorted(p.name for p in sample_paths("out", ["blink"]).values())[:3]
    ['blink.obj', 'ground_truth.npy', 'scan.mtl']
    """
    folder = Path(os.fspath(folder))
    paths = {"template": folder / "template.obj",
             "template_landmarks": folder / "template_landmarks.txt"}
    paths.update({f"blendshapes/{name}": folder / "blendshapes" / f"{name}.obj"
                  for name in expressions})
    paths.update(scan=folder / "scan.obj", scan_mtl=folder / "scan.mtl",
                 scan_texture=folder / "scan_texture.png",
                 scan_landmarks=folder / "scan_landmarks.txt",
                 ground_truth=folder / "ground_truth.npy")
    return paths


def write_sample(folder, template: SampleTemplate | None = None,
                 scan: SampleScan | None = None) -> dict[str, Path]:
    """Write the sample as plain files that any tool (or the CLI) can read.

    Files: ``template.obj``, ``template_landmarks.txt`` (0-based vertex ids, one per
    line), ``blendshapes/<name>.obj``, ``scan.obj`` (``mtllib scan.mtl``, UVs),
    ``scan.mtl`` and ``scan_texture.png``, ``scan_landmarks.txt`` (``x y z`` lines,
    in :data:`LANDMARK_NAMES` order) and ``ground_truth.npy`` ((n_template, 3),
    NaN for the eyeballs).  Each file is replaced atomically.

    Parameters
    ----------
    folder : str or os.PathLike
        Created if missing.
    template : SampleTemplate, optional
        Default ``make_template()``.
    scan : SampleScan, optional
        Default ``make_scan(template)``.

    Returns
    -------
    dict of str to Path
        ``"template"``, ``"template_landmarks"``, ``"blendshapes/<name>"`` for each
        expression, ``"scan"``, ``"scan_mtl"``, ``"scan_texture"``,
        ``"scan_landmarks"``, ``"ground_truth"``.

    Examples
    --------
    >>> import tempfile
    >>> tpl = make_template(24)
    >>> paths = write_sample(tempfile.mkdtemp(), tpl,
    ...                      make_scan(tpl, resolution=24, texture_size=8))
    >>> paths["scan"].read_text().splitlines()[1]
    'mtllib scan.mtl'
    >>> paths["blendshapes/blink"].relative_to(paths["scan"].parent).as_posix()
    'blendshapes/blink.obj'
    """
    folder = Path(os.fspath(folder))
    (folder / "blendshapes").mkdir(parents=True, exist_ok=True)
    template = make_template() if template is None else template
    scan = make_scan(template) if scan is None else scan
    paths = sample_paths(folder, template.blendshapes)
    write_obj(paths["template"], template.mesh, header="facewrap sample template")
    write_vertex_indices(paths["template_landmarks"], template.landmarks)
    for name, V in template.blendshapes.items():
        write_obj(paths[f"blendshapes/{name}"], template.mesh.with_vertices(V),
                  header=f"facewrap sample blendshape {name}")
    m = scan.mesh
    textured = Mesh(m.vertices, (m.face_offsets, m.face_indices), uvs=m.uvs,
                    mtllib=("scan.mtl",), materials=("skin",),
                    face_materials=np.zeros(m.n_faces, dtype=np.int64))
    write_obj(paths["scan"], textured, header="facewrap sample scan")
    with atomic_write(paths["scan_mtl"], "w", encoding="utf-8", newline="\n") as fh:
        fh.write(_MTL)
    save_png(paths["scan_texture"], np.asarray(scan.texture, dtype=np.uint8))
    write_points(paths["scan_landmarks"], scan.landmarks.points)
    with atomic_write(paths["ground_truth"], "wb") as fh:
        np.save(fh, np.asarray(scan.ground_truth))
    return paths
