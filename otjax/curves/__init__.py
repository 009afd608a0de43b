"""2D curves: the building blocks of :func:`otjax.reconstruct_curve`, public.

``otjax.reconstruct_curve`` is the one-call pipeline. This namespace exposes
the pieces it is made of, for research code that wants to score its own
candidates, drive its own queue or relocate vertices its own way (the
notebooks in ``notebooks/`` use nothing else):

Topology (Python, exact predicates):

- :class:`Triangulation` -- embedded triangulation inside four pinned corners;
  half-edge collapses made possible by flips, vertex moves.
- :class:`CollapsePlan`, :func:`edge_key` -- a planned collapse; canonical
  ``(min, max)`` edge keys.

Transport plan (Python bookkeeping around the JAX kernel):

- :class:`TransportPlan` -- points located in triangles, assigned to edges,
  cached per-edge costs; exports candidate stencils
  (:meth:`TransportPlan.candidates`), scores them in batches
  (:meth:`TransportPlan.score`) and applies them (:meth:`TransportPlan.apply`);
  the decimation loop's fast path exports flat batches
  (:meth:`TransportPlan.exports`) located and scored by one fused kernel
  (:meth:`TransportPlan.score_batches`, :mod:`otjax.curves.scoring`).
- :class:`CandidateStencil`, :class:`CandidateCost` -- one exported candidate
  and its scored outcome.

Stencil batches (the padded arrays of the public batched kernel):

- :class:`EdgeStencil`, :class:`Buckets`, :func:`pack_edge_stencils`.

JAX kernels (pure functions of arrays):

- :func:`stencil_cost` -- cost of one stencil; ``jax.vmap`` it for a batch.
- :data:`batched_stencil_cost` -- ``jax.jit(jax.vmap(stencil_cost))``.
- :class:`StencilCost` -- what the kernels return.
- :func:`fixed_assignment_cost` -- total cost as a differentiable function
  of the vertex positions, the assignment held fixed.
- :func:`segment_sqdist`, :func:`assign_points`, :func:`mass_before_sort`,
  :func:`mass_before_rank` -- the kernels' parts.

Drivers:

- :func:`decimate`, :class:`DecimationStats`, :func:`within_tolerance`,
  :data:`QUEUES` -- the greedy collapse loop and its queue kinds.
- :func:`optimal_position`, :func:`relocate` -- closed-form relocation
  (paper §3.3); :func:`refine`, :func:`minimize_lbfgs` -- L-BFGS refinement
  on the fixed-assignment cost.
- :func:`reconstruct_curve`, :class:`CurveResult` -- the pipeline and its
  result (also at the top level, ``otjax.reconstruct_curve``);
  :func:`default_initial_vertices` -- its default initial subset size.

Example:
  >>> import numpy as np
  >>> from otjax import curves
  >>> p = np.random.default_rng(0).random((40, 2))
  >>> plan = curves.TransportPlan(curves.Triangulation(p), p, np.ones(40))
  >>> cands = plan.candidates(range(len(p)))
  >>> delta, _ = plan.score(cands)
  >>> len(delta) == len(cands) > 0
  True
"""

from otjax.curves.cost import (
    StencilCost,
    assign_points,
    batched_stencil_cost,
    fixed_assignment_cost,
    mass_before_rank,
    mass_before_sort,
    segment_sqdist,
    stencil_cost,
)
from otjax.curves.decimate import QUEUES, DecimationStats, decimate, within_tolerance
from otjax.curves.plan import CandidateCost, CandidateStencil, TransportPlan
from otjax.curves.reconstruct import default_initial_vertices, reconstruct_curve
from otjax.curves.relocation import minimize_lbfgs, optimal_position, refine, relocate
from otjax.curves.result import CurveResult
from otjax.curves.triangulation import CollapsePlan, Triangulation, edge_key
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils

__all__ = [
    "QUEUES",
    "Buckets",
    "CandidateCost",
    "CandidateStencil",
    "CollapsePlan",
    "CurveResult",
    "DecimationStats",
    "EdgeStencil",
    "StencilCost",
    "TransportPlan",
    "Triangulation",
    "assign_points",
    "batched_stencil_cost",
    "decimate",
    "default_initial_vertices",
    "edge_key",
    "fixed_assignment_cost",
    "mass_before_rank",
    "mass_before_sort",
    "minimize_lbfgs",
    "optimal_position",
    "pack_edge_stencils",
    "reconstruct_curve",
    "refine",
    "relocate",
    "segment_sqdist",
    "stencil_cost",
    "within_tolerance",
]
