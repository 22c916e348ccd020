"""Whether the scan looks like the template where its landmarks are: a face, and not
a flat plane, a ball or another object that its landmarks were clicked on.

Every other check of a wrap looks at the landmarks or at the scan alone; a scan of
another object with landmarks on it passes them all, and the fit then presses the
template onto it without a word (the built-in sample onto a plane: 29 mm median
error against its truth, against 3.5 mm onto its scan).  Under the landmark
similarity, the template's face (its fitted vertices within the landmarks' reach
of their centre) lies close to a face scan: a quarter of it is farther than 10 %
of the landmarks' spread on the sample's scans of other faces and expressions, on
ICT's expression and identity shapes, on meshmonk's demo face and on james.  On
a plane or a ball that quarter is 30 % and more away; :data:`UNLIKE` lies
between.  A warning, never a change to the fit.
"""

from __future__ import annotations

import numpy as np

from facewrap.geometry import ClosestPointTree

__all__ = ["UNLIKE", "check_likeness"]

#: warn when a quarter of the template's face lies farther than this fraction of
#: the landmarks' spread from the scan, under the landmark similarity
UNLIKE = 0.2


def check_likeness(aligned, fitted, aligned_points, scan_points,
                   tree: ClosestPointTree) -> list[str]:
    """A warning when the template's face under the landmark similarity lies far
    from the scan (see the module docstring).

    Parameters
    ----------
    aligned : (n, 3) float
        Template vertices under the landmark similarity.
    fitted : (n,) bool
        The template vertices the fit pulls onto the scan (skin, not excluded).
    aligned_points, scan_points : (k, 3) float
        The paired landmarks: the template's under the similarity, the scan's.
    tree : ClosestPointTree
        The scan's.

    Returns
    -------
    list of str
        One line starting ``"scan: "``, or none.

    Examples
    --------
    >>> from facewrap.sample import make_scan, make_template
    >>> t = make_template(16)
    >>> s = make_scan(t, resolution=24, texture_size=8, transform=False)
    >>> fitted = np.ones(t.mesh.n_vertices, bool)
    >>> check_likeness(t.mesh.vertices, fitted, t.landmarks.positions(t.mesh),
    ...                s.landmarks.points, ClosestPointTree(s.mesh.vertices,
    ...                                                     s.mesh.triangles))
    []
    """
    P, Q = np.asarray(aligned_points, np.float64), np.asarray(scan_points, np.float64)
    spread = float(np.sqrt(((Q - Q.mean(axis=0)) ** 2).sum(axis=1).mean()))
    centre = P.mean(axis=0)
    reach = np.linalg.norm(P - centre, axis=1).max()
    A = np.asarray(aligned, np.float64)
    face = np.asarray(fitted, bool) & (np.linalg.norm(A - centre, axis=1) < reach)
    if spread <= 0 or face.sum() < 10:
        return []
    off = float(np.percentile(tree.query(A[face]).distances, 75)) / spread
    if off <= UNLIKE:
        return []
    return [f"scan: under the landmark alignment a quarter of the template's face lies "
            f"more than {100 * off:.0f} % of the landmarks' spread from it (a face "
            f"scan: under {100 * UNLIKE / 2:.0f} %): is it a scan of a face, with its "
            "landmarks? (the fit presses the template onto whatever it is)"]
