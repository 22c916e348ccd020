"""Where the scan does not reach: the template's landmarks the fit puts past the
scan's edge.

A scan with its chin cut off, or a hole over an eye, still gets a whole fitted
face: the fit follows the rest of the face there, it does not measure it.  The
result looks complete and nothing said so (ICT's face onto james with the chin
cut: fit p95 3.6 mm against the whole scan, 0.8 with the chin;
``benchmarks/bench_degraded_scans.py``).  The template's landmarks tell: every
one of them, paired on the scan or not (the cut took the chin's scan landmarks
with it, not the chin's place), should end up on the scan.  One whose closest
scan point lies on the scan's border, off to the side
(:func:`facewrap.evaluate.surface_distances`), and farther than
:data:`OFF_SCAN` of the landmarks' spread, lies where the scan has no surface,
unless its scan partner lies on the scan: then the scan has that place, and the
fit missed it (the landmark checks speak of that).  Landmarks on the rim of an
opening (eye corners, the lips of an open mouth) sit on the border too, mostly
within a millimetre of it.
"""

from __future__ import annotations

import numpy as np

from facewrap.evaluate import surface_distances
from facewrap.geometry import ClosestPointTree
from facewrap.landmarks import Landmarks

__all__ = ["landmarks_off_scan", "OFF_SCAN"]

#: fraction of the landmarks' spread (their bounding-box diagonal on the fit) past
#: the scan's edge from which a landmark is off the scan.  ICT's face onto james:
#: the landmarks of a cut-off chin lie 2.4-17 mm past the cut (6 of 7 past 5.8),
#: those in a 15 mm hole over an eye 1.2-10 mm (4 of 6); on ICT's ground-truth
#: scans, landmarks on the rims of the eyes and an open mouth 0.02-2.0 mm, and a
#: smile's mouth corner and its scan partner 3.7 and 3.5 mm (the remeshed rim);
#: the spread is 230-250 mm
OFF_SCAN = 0.025


def landmarks_off_scan(template_landmarks: Landmarks, vertices, triangles,
                       tree: ClosestPointTree, paired=None, partners=None) -> list[str]:
    """One warning naming the template landmarks the fit puts past the scan's edge
    where the scan has no surface.

    Parameters
    ----------
    template_landmarks : Landmarks
        All of the template's landmarks (paired or not), on the template.
    vertices : (n, 3) float
        The fit, in the scan's frame.
    triangles : (t, 3) int
        The template's.
    tree : ClosestPointTree
        The scan.
    paired : (l,) int, optional
        The template landmarks that have a scan partner...
    partners : (l, 3) float, optional
        ...and where the partners are on the scan.

    Returns
    -------
    list of str
        Empty, or one line.

    Examples
    --------
    >>> g = np.stack(np.meshgrid(np.arange(5.0), np.arange(5.0)), -1).reshape(-1, 2)
    >>> V = np.c_[g, np.zeros(25)]
    >>> T = np.array([[i, i + 1, i + 6] for i in range(19) if i % 5 < 4]
    ...              + [[i, i + 6, i + 5] for i in range(19) if i % 5 < 4])
    >>> scan = ClosestPointTree(V[:15], T[(T < 15).all(axis=1)])   # rows y >= 3 cut
    >>> lm = Landmarks.from_vertices([0, 12, 22])
    >>> landmarks_off_scan(lm, V, T, scan)[0][:58]
    'scan: template landmark 2 lies past the edge of the scan ('
    >>> landmarks_off_scan(lm, V, T, scan, [2], [[2.0, 2.0, 0.0]])    # a fit's miss
    []
    """
    P = template_landmarks.positions(np.asarray(vertices, dtype=np.float64), triangles)
    if len(P) < 2:
        return []
    spread = float(np.linalg.norm(np.ptp(P, axis=0)))
    d = surface_distances(P, tree)
    off = ~d.covered & (d.distances > OFF_SCAN * spread)
    if off.any() and paired is not None and len(paired):
        partner = surface_distances(partners, tree)
        # a partner on the scan: the scan has that place, the fit missed it
        on = partner.covered | (partner.distances <= OFF_SCAN * spread)
        off[np.asarray(paired)[on]] = False
    off = np.flatnonzero(off)
    if not len(off):
        return []
    names = ", ".join(template_landmarks.label(i) for i in off[:8]) + (
        f" and {len(off) - 8} more" if len(off) > 8 else "")
    which = (f"template landmark {names} lies" if len(off) == 1 else
             f"{len(off)} template landmarks ({names}) lie")
    return [f"scan: {which} past the edge of the scan (up to "
            f"{d.distances[off].max():.3g} scan units): the scan has a hole there, or "
            "ends short of the face; the fit there follows the rest of the face, it "
            "does not measure it"]
