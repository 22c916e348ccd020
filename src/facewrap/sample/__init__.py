"""The built-in sample: a procedural face template and scans with ground truth."""

from facewrap.sample.face import make_scan, make_template, write_sample

__all__ = [
    "make_scan", "make_template", "write_sample",
]
