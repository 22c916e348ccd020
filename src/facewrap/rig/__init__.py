"""A person's own rig from their scans (issue 19).

The rig (:mod:`.build`)
    :func:`build_rig`, :class:`Rig`
Shapes (:mod:`.personalise`)
    :func:`personalise_shapes`, :class:`PersonalisedShapes`, :data:`PERSONALISE_METHODS`
Head motion (:mod:`.stabilise`)
    :func:`stabilise`, :class:`Stabilised`, :func:`least_moving`
Shapes corrected by expression scans (:mod:`.examples`)
    :func:`fit_examples`, :class:`ExampleFit`, :class:`ExampleSettings`, :func:`fit_weights`
"""

from facewrap.rig.build import Rig, build_rig
from facewrap.rig.examples import ExampleFit, ExampleSettings, fit_examples, fit_weights
from facewrap.rig.personalise import (PERSONALISE_METHODS, PersonalisedShapes,
                                      personalise_shapes)
from facewrap.rig.stabilise import Stabilised, least_moving, stabilise

__all__ = ["build_rig", "Rig", "personalise_shapes", "PersonalisedShapes",
           "PERSONALISE_METHODS", "fit_examples", "ExampleFit", "ExampleSettings",
           "fit_weights", "stabilise", "Stabilised", "least_moving"]
