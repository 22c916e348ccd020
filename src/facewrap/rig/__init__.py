"""A person's own rig from their scans (issue 19).

Shapes (:mod:`.personalise`)
    :func:`personalise_shapes`, :class:`PersonalisedShapes`, :data:`PERSONALISE_METHODS`
"""

from facewrap.rig.personalise import (PERSONALISE_METHODS, PersonalisedShapes,
                                      personalise_shapes)

__all__ = ["personalise_shapes", "PersonalisedShapes", "PERSONALISE_METHODS"]
