"""A person's own rig from their scans (issue 19).

The rig (:mod:`.build`)
    :func:`build_rig`, :class:`Rig`
Shapes (:mod:`.personalise`)
    :func:`personalise_shapes`, :class:`PersonalisedShapes`, :data:`PERSONALISE_METHODS`
Head motion (:mod:`.stabilise`)
    :func:`stabilise`, :class:`Stabilised`, :func:`least_moving`
Expression wraps refined by texture (:mod:`.texture_flow`, :mod:`.flow_match`)
    :func:`refine_by_texture`, :class:`TextureRefinement`, :class:`TextureFlowSettings`,
    :func:`flow_matches`, :class:`FlowMatches`
Shapes corrected by expression scans (:mod:`.examples`)
    :func:`fit_examples`, :class:`ExampleFit`, :class:`ExampleSettings`, :func:`fit_weights`
"""

from facewrap.rig.build import Rig, build_rig
from facewrap.rig.examples import ExampleFit, ExampleSettings, fit_examples, fit_weights
from facewrap.rig.personalise import (PERSONALISE_METHODS, PersonalisedShapes,
                                      personalise_shapes)
from facewrap.rig.flow_match import FlowMatches, flow_matches
from facewrap.rig.stabilise import Stabilised, least_moving, stabilise
from facewrap.rig.texture_flow import TextureFlowSettings, TextureRefinement, refine_by_texture

__all__ = ["build_rig", "Rig", "personalise_shapes", "PersonalisedShapes",
           "PERSONALISE_METHODS", "fit_examples", "ExampleFit", "ExampleSettings",
           "fit_weights", "stabilise", "Stabilised", "least_moving", "refine_by_texture",
           "TextureRefinement", "TextureFlowSettings", "flow_matches", "FlowMatches"]
