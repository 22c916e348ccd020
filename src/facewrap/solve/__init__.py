"""Linear algebra shared by wrapping, transfer and avatar.

Factorisations (:mod:`.factor`)
    :func:`factorize` (checked sparse Cholesky, LU fallback), :func:`refactorize`,
    :class:`Factor`, :func:`solve_spd`
Fixed unknowns (:mod:`.fixed`)
    :class:`FixedSystem` (``x[known] = y``, factored once, solved many times),
    :func:`split_fixed`, :func:`known_mask`
Krylov (:mod:`.krylov`)
    :func:`conjugate_gradients` (the one preconditioned CG), :class:`CGResult`,
    :func:`block_jacobi`
Normal equations (:mod:`.gauss_newton`)
    :func:`gauss_newton_step` (stacked weighted terms, damped), :func:`normal_equations`
    and :class:`NormalEquations` (assembled once, solved for any damping), :func:`gram_matrix`,
    :func:`sparse_gram_matrix`
Jacobians (:mod:`.block_jacobian`)
    :class:`BlockJacobian` (sparse graph columns beside dense blend columns)
"""

from facewrap.solve.block_jacobian import BlockJacobian
from facewrap.solve.factor import Factor, factorize, refactorize, solve_spd
from facewrap.solve.fixed import FixedSystem, known_mask, split_fixed
from facewrap.solve.gauss_newton import (NormalEquations, gauss_newton_step, gram_matrix,
                                         normal_equations, sparse_gram_matrix)
from facewrap.solve.krylov import CGResult, block_jacobi, conjugate_gradients

__all__ = ["Factor", "factorize", "refactorize", "solve_spd", "gauss_newton_step",
           "normal_equations", "NormalEquations",
           "gram_matrix", "sparse_gram_matrix", "BlockJacobian", "FixedSystem",
           "split_fixed", "known_mask", "conjugate_gradients", "CGResult", "block_jacobi"]
