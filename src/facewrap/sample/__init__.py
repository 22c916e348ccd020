"""The built-in synthetic sample: a procedural template head, scans of other faces,
and the truth that relates them.

Everything here is a pure, deterministic function of its arguments (fixed seeds,
``np.random.default_rng``), needs no data files and carries no licence.  It is the
default input of ``make demo`` and of every test that must run without real data.

The parameter domain and its layout (:mod:`.layout`)
    where eyes, lids and lips are; the landmarks; :data:`LANDMARK_NAMES`
Identities (:mod:`.identity`)
    feature parameters of a face drawn from a seed
The parametric head and its expressions (:mod:`.surface`)
    :data:`EXPRESSIONS`
The template (:mod:`.template`)
    :func:`make_template`, :class:`SampleTemplate`
Scans with ground truth (:mod:`.scan`), their skin texture (:mod:`.skin`)
    :func:`make_scan`, :class:`SampleScan`
Sequences (:mod:`.sequence`) and files (:mod:`.files`)
    :func:`make_sequence`, :func:`write_sample`, :func:`sample_paths`

Examples
--------
>>> tpl = make_template(24)
>>> tpl.mesh.n_vertices == len(tpl.params), sorted(tpl.blendshapes) == sorted(EXPRESSIONS)
(True, True)
>>> scan = make_scan(tpl, resolution=30, texture_size=32)
>>> scan.mesh.is_triangle_mesh, scan.ground_truth.shape == (tpl.mesh.n_vertices, 3)
(True, True)
"""

from facewrap.sample.files import sample_paths, write_sample
from facewrap.sample.layout import LANDMARK_NAMES
from facewrap.sample.scan import SampleScan, make_scan
from facewrap.sample.sequence import make_sequence
from facewrap.sample.surface import EXPRESSIONS
from facewrap.sample.template import SampleTemplate, make_template

__all__ = [
    "EXPRESSIONS", "LANDMARK_NAMES", "SampleTemplate", "SampleScan",
    "make_template", "make_scan", "make_sequence", "sample_paths", "write_sample",
]
