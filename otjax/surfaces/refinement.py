"""Gradient refinement of vertex positions with the plan fixed.

:func:`refine` runs conjugate gradient on the fixed-plan cost of the
simplices around the free vertices
(:func:`otjax.surfaces.fixed_plan_cost.refine_positions`), then takes the
largest halving of that step that flattens no facet (the degeneracy test of
:mod:`otjax.surfaces.relocation`); it never raises the cost.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import jax
import numpy as np

from otjax.batch.pipeline import require_x64
from otjax.surfaces.fixed_plan_cost import fixed_plan_cost, refine_positions
from otjax.surfaces.packed_entries import pack_entries, rows_of
from otjax.surfaces.plan import SurfacePlan
from otjax.surfaces.relocation import degenerates

#: Conjugate-gradient steps of :func:`refine`.
REFINE_STEPS = 8
#: Halvings of a refinement step tried when the full step flattens a facet.
REFINE_HALVINGS = 8


class RefineStats(NamedTuple):
    """What :func:`refine` did.

    Attributes:
      cost_before, cost_after: the fixed-plan cost of the simplices around
        the free vertices (the only part of the total that moves), before
        and after; ``cost_after <= cost_before``.
      costs: that cost after each conjugate-gradient step.
      step: the fraction of the refined step taken (1, or less when a
        facet would degenerate; 0 when nothing moved).
      moved: ids of the vertices whose position changed, increasing.
    """

    cost_before: float
    cost_after: float
    costs: tuple[float, ...]
    step: float
    moved: tuple[int, ...]


_fixed_plan_cost = jax.jit(fixed_plan_cost)


def refine(plan: SurfacePlan, vertices: Sequence[int] | None = None,
           steps: int = REFINE_STEPS) -> RefineStats:
    """Gradient refinement of vertex positions with the plan fixed.

    Minimises the fixed-plan cost of the simplices around ``vertices`` over
    their positions by ``steps`` conjugate-gradient steps with an exact line
    search (:func:`~otjax.surfaces.fixed_plan_cost.refine_positions`), then
    takes the largest step ``2^-k`` towards the result that flattens no
    facet. The cost is convex, so any such step costs no more than the start;
    the positions move only if the cost went down.

    Args:
      plan: the plan (entries unchanged); its complex's positions move.
      vertices: the free vertex ids; default every live vertex.
      steps: conjugate-gradient steps.

    Returns:
      :class:`RefineStats`; the plan's total cost changes by
      ``cost_after - cost_before <= 0``.
    """
    require_x64("refine")
    c = plan.complex
    free = np.flatnonzero(c.alive) if vertices is None else np.array(
        sorted({int(v) for v in vertices if c.alive[v]}), np.int64)
    facets = sorted({t for v in free.tolist() for t in c.vertex_triangles[v]})
    # every corner of a star facet gets a row, for the degeneracy test
    corners = np.array(facets, np.int64).reshape(-1, 3)
    packed = pack_entries(plan, free.tolist() + facets, np.concatenate([free, corners.ravel()]))
    free_mask = np.zeros(len(packed.positions), bool)
    free_mask[rows_of(packed, free)] = True
    got = refine_positions(packed.positions, free_mask, packed.points, packed.entries, steps)
    costs = tuple(float(x) for x in np.asarray(got.costs))
    start, end = packed.positions, np.asarray(got.positions)
    unchanged = RefineStats(costs[0], costs[0], costs, 0.0, ())
    if not costs[-1] < costs[0]:
        return unchanged
    rows = rows_of(packed, corners)
    step = 1.0
    for _ in range(REFINE_HALVINGS):
        trial = start + step * (end - start)
        if not degenerates(start[rows], trial[rows]):
            break
        step /= 2
    else:
        return unchanged
    after = float(_fixed_plan_cost(trial, packed.points, packed.entries))
    if not after < costs[0]:
        return unchanged
    n = len(packed.vertex_ids)
    shifted = np.flatnonzero(np.any(trial[:n] != start[:n], axis=1))
    for r in shifted:
        c.move(int(packed.vertex_ids[r]), trial[r])
    return RefineStats(costs[0], after, costs, step, tuple(int(v) for v in packed.vertex_ids[shifted]))
