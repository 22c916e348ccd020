"""The hybrid model: a deformation graph acting on blended positions (SPEC §2.4).

    b_i(w) = n_i + Σ_k w_k d_ik                                          [4]
    v_i    = Σ_j a_ij ( R_j (b_i(w) − x_j(w)) + x_j(w) + t_j )           [8]
    E      = Σ_k w_k² (blend)  +  eq. 7 on x(w) (smooth)                 [9]

**Graph nodes follow the blend**: ``x_j(w) = b_{node_j}(w)``.  Why:

- with ``R = I, t = 0`` the model is exactly the blendshape model for every
  ``w`` and the graph's smoothness energy is exactly zero, so the graph only
  pays for what the blendshapes cannot explain (detail, identity) and never
  fights a large expression (a jaw opened by 3 cm is free for the graph);
- rotations pivot about where the node *is* in the current expression, so a
  node on an opened jaw rotates its own neighbourhood, not a point 3 cm away;
- with fixed nodes, ``R_j`` and ``w`` would be coupled through the lever arm
  ``b_i(w) − x_j`` and the Gauss–Newton system would be worse conditioned.

The test suite checks the first property and the Jacobians (including the
``w``-columns of both the vertices and the smoothness term) against finite
differences.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from facewrap.solve import BlockJacobian
from facewrap.wrapping.models.base import DeformationModel, LastBlend
from facewrap.wrapping.models.blendshape import bound_violation
from facewrap.wrapping.models.graph import (DeformationGraph, GraphParams, graph_jacobian, graph_smoothness,
                    graph_vertices, resample_params)

__all__ = ["HybridParams", "HybridModel"]


@dataclass(frozen=True)
class HybridParams:
    """Graph parameters (``graph``) and blend weights ``w`` (K,)."""
    graph: GraphParams
    w: np.ndarray


class HybridModel(DeformationModel):
    """Deformation graph on top of blendshapes.

    Parameters
    ----------
    base : (n, 3) float64
        Neutral positions (the aligned template).
    deltas : (3n, K) float64
        Blendshape deltas in ``base``'s frame
        (:func:`~facewrap.wrapping.models.blendshape.blendshape_basis`).
    graph : DeformationGraph

    Increment order: [graph (6m), δw (K)]; Jacobians are
    :class:`~facewrap.solve.BlockJacobian` (graph sparse, weights dense).  Regularisers ``"smooth"`` (eq. 7
    per edge, normalised by the edge count) and ``"blend"`` (eq. 5).
    """

    regularizer_names = ("smooth", "blend", "bounds")
    param_block = 6

    def __init__(self, base, deltas, graph: DeformationGraph, *, bounds=None):
        self.bounds = None if bounds is None else (float(bounds[0]), float(bounds[1]))
        self.base = np.asarray(base, dtype=np.float64)
        self.deltas = np.asarray(deltas, dtype=np.float64)
        self.graph = graph
        self.n_vertices = len(self.base)
        self.n_shapes = self.deltas.shape[1]
        self.n_graph = 6 * graph.n_nodes
        self.n_params = self.n_graph + self.n_shapes
        # deltas at the nodes, (m, 3, K), and per vertex, (n, 3, K)
        self._D = self.deltas.reshape(self.n_vertices, 3, self.n_shapes)
        self._D_nodes = self._D[graph.nodes]
        # along each graph edge: D_xk − D_xj, (e, 3, K), what the smoothness's
        # w-columns rotate (fixed by the graph)
        self._D_edges = (self._D_nodes[graph.edges[:, 1]]
                         - self._D_nodes[graph.edges[:, 0]])
        # skinning weights as an (n, m) matrix: Σ_j a_ij f(node j) is one product
        k = graph.vertex_nodes.shape[1]
        self._skin = sp.csr_matrix(
            (graph.vertex_weights.ravel(), graph.vertex_nodes.ravel(),
             np.arange(0, k * self.n_vertices + 1, k)),
            shape=(self.n_vertices, graph.n_nodes))
        self._last_blend = LastBlend(self.base, self.deltas)

    def initial_params(self, weights=None) -> HybridParams:
        """Identity graph; blend weights ``weights`` (K,) or zeros."""
        w = np.zeros(self.n_shapes) if weights is None else np.asarray(weights)
        return HybridParams(GraphParams.identity(self.graph.n_nodes), w)

    def blended(self, w) -> np.ndarray:
        """Neutral plus weighted deltas, before the pose: (n, 3), read-only."""
        return self._last_blend(w)

    def vertices(self, p: HybridParams) -> np.ndarray:
        return graph_vertices(self.blended(p.w), self.graph, p.graph)

    def jacobian(self, p: HybridParams, vertices=None):
        B = self.blended(p.w)
        Jg = graph_jacobian(B, self.graph, p.graph, vertices)
        if not self.n_shapes:
            return Jg
        # dv_i/dw = Σ_j a_ij ( R_j (D_i − D_xj) + D_xj )
        #         = (Σ_j a_ij R_j) D_i + Σ_j a_ij (I − R_j) D_xj
        J, W = self.graph.vertex_nodes, self.graph.vertex_weights
        Dv, skin = self._D, self._skin
        if vertices is not None:
            J, W, Dv, skin = J[vertices], W[vertices], Dv[vertices], skin[vertices]
        R = p.graph.R
        M = np.einsum("nk,nkab->nab", W, R[J])
        node_term = np.matmul(np.eye(3) - R, self._D_nodes)         # (m, 3, K)
        Jw = np.matmul(M, Dv) + (skin @ node_term.reshape(len(R), -1)).reshape(Dv.shape)
        return BlockJacobian(Jg, Jw.reshape(-1, self.n_shapes))

    def regularizers(self, p: HybridParams) -> dict:
        B = self.blended(p.w)
        r, Jg = graph_smoothness(B, self.graph, p.graph)
        scale = self.graph.smoothness_scale
        out = {}
        if self.n_shapes:
            # d e_jk / dw = (R_j − I)(D_xk − D_xj)
            j = self.graph.edges[:, 0]
            Jw = np.matmul(p.graph.R[j] - np.eye(3), self._D_edges)
            out["smooth"] = (r * scale, BlockJacobian(Jg, Jw.reshape(-1, self.n_shapes))
                             * scale)
            Jb = BlockJacobian(sp.csr_matrix((self.n_shapes, self.n_graph)),
                               np.eye(self.n_shapes))
            out["blend"] = (np.asarray(p.w, dtype=np.float64), Jb)
            if self.bounds is not None:
                r, d = bound_violation(p.w, self.bounds)
                out["bounds"] = (r, BlockJacobian(sp.csr_matrix((self.n_shapes,
                                                                 self.n_graph)),
                                                  np.diag(d)))
        else:
            out["smooth"] = (r * scale, Jg * scale)
        return out

    def regularizer_residuals(self, p: HybridParams) -> dict:
        r = graph_smoothness(self.blended(p.w), self.graph, p.graph, jacobian=False)
        out = {"smooth": r * self.graph.smoothness_scale}
        if self.n_shapes:
            out["blend"] = np.asarray(p.w, dtype=np.float64)
            if self.bounds is not None:
                out["bounds"] = bound_violation(p.w, self.bounds)[0]
        return out

    def update(self, p: HybridParams, delta) -> HybridParams:
        d = np.asarray(delta, dtype=np.float64)
        return HybridParams(p.graph.updated(d[:self.n_graph]), p.w + d[self.n_graph:])

    def on_graph(self, graph: DeformationGraph, p: HybridParams
                 ) -> tuple["HybridModel", HybridParams]:
        """The same model on another graph of the template (coarse-to-fine): the
        blend weights carry over, the graph's motion is resampled on the blended
        positions it acts on."""
        g = resample_params(self.blended(p.w), self.graph, p.graph, graph)
        return (HybridModel(self.base, self.deltas, graph, bounds=self.bounds),
                HybridParams(g, p.w))

    def summary(self, p: HybridParams) -> dict:
        return {"nodes": self.graph.n_nodes, "edges": int(len(self.graph.edges)),
                "shapes": self.n_shapes}
