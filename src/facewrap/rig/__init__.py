"""A person's own rig from their scans (issue 19).

The rig (:mod:`.build`)
    :func:`build_rig`, :class:`Rig`
Shapes (:mod:`.personalise`)
    :func:`personalise_shapes`, :class:`PersonalisedShapes`, :data:`PERSONALISE_METHODS`
"""

from facewrap.rig.build import Rig, build_rig
from facewrap.rig.personalise import (PERSONALISE_METHODS, PersonalisedShapes,
                                      personalise_shapes)

__all__ = ["build_rig", "Rig", "personalise_shapes", "PersonalisedShapes", "PERSONALISE_METHODS"]
