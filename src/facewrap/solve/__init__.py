"""Linear algebra shared by wrapping, transfer and avatar.

Factorisations (:mod:`.factor`)
    :func:`factorize` (checked sparse Cholesky, LU fallback), :func:`refactorize`,
    :class:`Factor`, :func:`solve_spd`
Normal equations (:mod:`.factor`)
    :func:`gauss_newton_step` (stacked weighted terms, damped)
Fixed unknowns (:mod:`.fixed`)
    :class:`FixedSystem` (``x[known] = y``, factored once, solved many times),
    :func:`split_fixed`
Jacobians (:mod:`.block_jacobian`)
    :class:`BlockJacobian` (sparse graph columns beside dense blend columns)
"""

from facewrap.solve.block_jacobian import BlockJacobian
from facewrap.solve.factor import Factor, factorize, gauss_newton_step, refactorize, solve_spd
from facewrap.solve.fixed import FixedSystem, known_mask, split_fixed

__all__ = ["Factor", "factorize", "refactorize", "solve_spd", "gauss_newton_step",
           "BlockJacobian", "FixedSystem", "split_fixed", "known_mask"]
