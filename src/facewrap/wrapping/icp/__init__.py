"""Non-rigid ICP: the one registration engine, its stage schedule and energy terms.

* :mod:`.engine` — :class:`NonRigidICP` (IRLS + Levenberg–Marquardt over a schedule);
* :mod:`.schedule` — :class:`Stage` (validated) and the default schedule per model;
* :mod:`.terms` — the energy terms, each a residual and its Jacobian.
"""

from facewrap.wrapping.icp.engine import NonRigidICP
from facewrap.wrapping.icp.schedule import Stage

__all__ = ["NonRigidICP", "Stage"]
