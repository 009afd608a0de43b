"""Proposed vertex moves (§4.3) for the decimation engine: each vertex
relocated alone on the current plan, solved but not applied.

:func:`propose_moves` runs, per vertex, a few alternations of the closed-form
target under its local plan (:func:`local_target`), a damped move and a
re-solve of its closed star; the result is a :class:`StarMove` that
:meth:`otjax.surfaces.engine.SurfaceEngine.apply` writes into the plan. The
moves follow the rules of :func:`otjax.surfaces.relocation.relocate` (its
:data:`~otjax.surfaces.relocation.DAMPING`, its degeneracy test) without
changing the plan.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, LocalLP, lower_bound
from otjax.surfaces.plan import Stencil, SurfacePlan
from otjax.surfaces.relaxation import GAIN, Solver
from otjax.surfaces.relocation import DAMPING, ROUNDS, degenerates, star_corners


class StarMove(NamedTuple):
    """A relocation of one vertex, solved but not applied (the decimation
    engine applies it: :meth:`otjax.surfaces.engine.SurfaceEngine.apply`).

    Attributes:
      vertex: the vertex id.
      position: ``(3,)`` float64 its new position.
      stencil: its closed star's local problem with the vertex at
        ``position`` (``lp`` costs there); ``stencil.cost`` is what those
        partial masses cost now, before the move.
      plan: ``(P, K)`` float64 the local plan to write (already
        :meth:`~otjax.surfaces.plan.SurfacePlan.sparsified`).
      delta: the change of the plan's total cost the move makes (``< 0``).
      rounds: alternations that lowered the cost.
    """

    vertex: int
    position: np.ndarray
    stencil: Stencil
    plan: np.ndarray
    delta: float
    rounds: int


def star_stencil(plan: SurfacePlan, v: int) -> Stencil:
    """The stencil of a move of ``v``: the vertices of its closed star and
    its facets (the simplices whose bins move with it, and the neighbours'
    vertex bins a point may leave them for)."""
    c = plan.complex
    return plan.stencil(c.vertex_closure(v).vertices, c.star(v).triangles)


def stencil_plan(plan: SurfacePlan, stencil: Stencil) -> np.ndarray:
    """``(P, K)`` the plan's current entries on the stencil's simplices as a local plan of its LP."""
    counts = [1] * len(stencil.vertices) + [len(plan.bins[f].capacity) for f in stencil.facets]
    offsets = np.concatenate([[0], np.cumsum(counts)]).astype(np.int64)
    out = np.zeros(stencil.lp.cost.shape)
    for s, key in enumerate(stencil.vertices + stencil.facets):
        e = plan.entries(key)
        if e is not None:
            np.add.at(out, (np.searchsorted(stencil.points, e.point), offsets[s] + e.bin), e.mass)
    return out


def local_target(plan: SurfacePlan, stencil: Stencil, local: np.ndarray, v: int) -> np.ndarray | None:
    """``(3,)`` the paper's ``v*`` (§4.3) of ``v`` under the
    local plan ``local`` ``(P, K)`` of its :func:`star_stencil`: each simplex
    of its star carrying mass gives its own minimiser, averaged by mass (the
    same as :func:`~otjax.surfaces.relocation.relocation_targets` on the plan
    the local one is written into); ``None`` if no simplex of the star
    carries mass."""
    pts = plan.points[stencil.points]
    pos = plan.complex.positions
    top, weight, col = np.zeros(3), 0.0, 0
    for key in stencil.vertices + stencil.facets:
        n = len(plan.bins[key].capacity) if isinstance(key, tuple) else 1
        m = local[:, col:col + n]
        col += n
        if key == v:
            alpha, rest = np.ones(1), np.zeros((1, 3))
        elif isinstance(key, tuple) and v in key:
            bary = plan.bins[key].barycentric
            mine = np.array(key) == v
            alpha = bary[:, mine][:, 0]
            rest = bary[:, ~mine] @ pos[[u for u in key if u != v]]
        else:
            continue
        mass = m.sum(axis=0)  # (n,) per bin
        den = float(np.sum(mass * alpha**2))
        if not den > 0:
            continue
        num = alpha @ (m.T @ pts) - (mass * alpha) @ rest
        share = float(mass.sum())
        top += share * num / den
        weight += share
    return top / weight if weight > 0 else None


def moved_lp(plan: SurfacePlan, stencil: Stencil, v: int, position: np.ndarray) -> LocalLP:
    """The stencil's LP with ``v`` at ``position`` (the other vertices where they are)."""
    pos = plan.complex.positions

    def at(ids):
        out = pos[list(ids)].copy()
        out[np.array(ids) == v] = position
        return out

    sites = np.concatenate([at(stencil.vertices)] + [plan.bins[f].barycentric @ at(f) for f in stencil.facets])
    diff = plan.points[stencil.points][:, None, :] - sites[None, :, :]
    lp = stencil.lp
    return LocalLP(np.einsum("pkd,pkd->pk", diff, diff), lp.mass, lp.capacity, lp.simplex, lp.is_vertex)


def propose_moves(plan: SurfacePlan, vertices: Sequence[int], solve: Solver, rounds: int = ROUNDS, *,
                  damping: float = DAMPING) -> list[StarMove | None]:
    """The §4.3 relocation of each vertex, alone on the current plan, without changing it.

    For each vertex, up to ``rounds`` alternations of: the closed-form target
    under the current local plan (:func:`local_target`), a move ``damping``
    of the way there, the transport on its closed star re-solved. An
    alternation is kept only if it lowers the star's cost (by more than
    :data:`~otjax.surfaces.relaxation.GAIN` of it) and flattens no facet
    (:func:`~otjax.surfaces.relocation.degenerates`); the first that does not ends the vertex's moves.
    A move whose LP's lower bound (:func:`~otjax.lp.problem.lower_bound`)
    already misses that gain is not solved.
    Each round solves the stencils of every vertex still moving in one
    ``solve`` call. Proposals are independent of one another: applying two
    whose closed stars share a vertex is not what visiting them in turn does.

    Args:
      plan: the plan (not changed).
      vertices: ``B`` live vertex ids.
      solve: the local LP solver.
      rounds, damping: as :func:`~otjax.surfaces.relocation.relocate`.

    Returns:
      ``B`` entries: the :class:`StarMove` of each vertex, ``None`` where no
      alternation lowered its star's cost.
    """
    state = {}  # v -> (position, lp, local plan, cost, rounds kept, stencil before)
    for v in dict.fromkeys(int(v) for v in vertices):
        if plan.complex.alive[v]:
            st = star_stencil(plan, v)
            if len(st.points):
                state[v] = (plan.complex.positions[v].copy(), st.lp, stencil_plan(plan, st), st.cost, 0, st)
    moving = list(state)
    for _ in range(rounds):
        trials = []
        for v in moving:
            x, lp, local, _, _, st = state[v]
            target = local_target(plan, st, local, v)
            if target is None:
                continue
            new = x + damping * (target - x)
            if np.array_equal(new, x) or degenerates(star_corners(plan, v, x), star_corners(plan, v, new)):
                continue
            lp = moved_lp(plan, st, v, new)
            if lower_bound(lp) >= state[v][3] * (1.0 - GAIN):
                continue  # no plan at the new position could be kept: the vertex stops, unsolved
            trials.append((v, new, lp))
        solved = solve([lp for _, _, lp in trials]) if trials else []
        moving = []
        for (v, new, lp), sol in zip(trials, solved):
            if sol.status not in (CONVERGED, ITERATION_LIMIT):
                continue
            st, cost = state[v][5], state[v][3]
            local = SurfacePlan.sparsified(st, sol.plan)
            if not np.all(local.sum(axis=1) > 0):  # a failed member's zero plan: not feasible
                continue
            after = float(np.sum(local * lp.cost))
            if after < cost * (1.0 - GAIN):
                state[v] = (new, lp, local, after, state[v][4] + 1, st)
                moving.append(v)
        if not moving:
            break
    out: list[StarMove | None] = []
    for v in (int(v) for v in vertices):
        got = state.get(v)
        if got is None or got[4] == 0:
            out.append(None)
            continue
        x, lp, local, cost, kept, st = got
        out.append(StarMove(v, x, st._replace(lp=lp), local, cost - st.cost, kept))
    return out
