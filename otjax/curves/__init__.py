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

Transport plan and engine (Python bookkeeping around the JAX kernel):

- :class:`TransportPlan` -- the plan's state: points located in triangles,
  assigned to edges, per-edge costs; :meth:`TransportPlan.apply` returns a
  :class:`Change`.
- :class:`CurveEngine` -- a plan and what scores and applies its changes:
  exports candidate stencils (:meth:`CurveEngine.candidates`), scores them in
  batches (:meth:`CurveEngine.score_candidates`) and applies them
  (:meth:`CurveEngine.apply`); the decimation loop's fast path exports flat
  batches (:meth:`CurveEngine.exports`) located and scored by one fused
  kernel (:meth:`CurveEngine.score_batches`, :mod:`otjax.curves.scoring`).
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
  :data:`QUEUES` -- the greedy collapse loop (:mod:`otjax.decimation`) over a
  curve engine, and its queue kinds.
- :func:`optimal_position` -- closed-form relocation (paper §3.3), applied by
  :func:`otjax.decimation.relocation.relocate`; :func:`refine`, :func:`minimize_lbfgs` --
  L-BFGS refinement on the fixed-assignment cost.
- :func:`reconstruct_curve`, :class:`CurveResult` -- the pipeline and its
  result (also at the top level, ``otjax.reconstruct_curve``);
  :func:`default_initial_vertices` -- its default initial subset size, by
  :func:`local_thickness` (noisy points or exact samples).

Scoring runs in JAX's float64 mode (exact point location): research code
calls these inside ``jax.enable_x64(True)`` (``reconstruct_curve`` does it
itself).

Example:
  >>> import jax, numpy as np
  >>> from otjax import curves
  >>> p = np.random.default_rng(0).random((40, 2))
  >>> with jax.enable_x64(True):
  ...     engine = curves.CurveEngine(curves.Triangulation(p), p, np.ones(40))
  ...     cands = engine.candidates(range(len(p)))
  ...     delta, _ = engine.score_candidates(cands)
  >>> len(delta) == len(cands) > 0
  True
"""

from otjax.curves.cost import (
    StencilCost,
    assign_points,
    batched_stencil_cost,
    fixed_assignment_cost,
    segment_sqdist,
    stencil_cost,
)
from otjax.curves.decimate import QUEUES, DecimationStats, decimate, within_tolerance
from otjax.curves.engine import CurveEngine, Scored
from otjax.curves.mass_before import mass_before_rank, mass_before_sort
from otjax.curves.plan import Change, TransportPlan
from otjax.curves.reconstruct import default_initial_vertices, reconstruct_curve
from otjax.curves.refinement import minimize_lbfgs, refine
from otjax.curves.relocation import optimal_position
from otjax.curves.result import CurveResult
from otjax.curves.stencils import CandidateCost, CandidateStencil
from otjax.curves.thickness import local_thickness
from otjax.curves.triangulation import CollapsePlan, MovePlan, Triangulation, edge_key
from otjax.stencil import Buckets, EdgeStencil, pack_edge_stencils

__all__ = [
    "QUEUES",
    "Buckets",
    "CandidateCost",
    "CandidateStencil",
    "Change",
    "CollapsePlan",
    "CurveEngine",
    "CurveResult",
    "DecimationStats",
    "EdgeStencil",
    "MovePlan",
    "Scored",
    "StencilCost",
    "TransportPlan",
    "Triangulation",
    "assign_points",
    "batched_stencil_cost",
    "decimate",
    "default_initial_vertices",
    "edge_key",
    "fixed_assignment_cost",
    "local_thickness",
    "mass_before_rank",
    "mass_before_sort",
    "minimize_lbfgs",
    "optimal_position",
    "pack_edge_stencils",
    "reconstruct_curve",
    "refine",
    "segment_sqdist",
    "stencil_cost",
    "within_tolerance",
]
