"""Local stencil relaxation of a transport plan (§3.3, Algorithm 2).

Starting from any feasible plan, each facet's stencil (the facet, its
neighbours, their vertices) is cut out with the partial masses its points
have there, solved as a small LP, and written back if its cost did not rise;
sweeps repeat until one lowers the total cost by less than a relative
``tolerance``. Stencils that share no vertex share no simplex, so a sweep is
split into rounds of vertex-disjoint stencils and each round is one batched
solver call; rounds run in order, so each sees the plan the earlier ones left
(the sequential sweep's Gauss-Seidel character is kept between rounds).
"""

from __future__ import annotations

from typing import Callable, NamedTuple, Sequence

import numpy as np
import scipy.spatial

from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, LocalLP, lower_bound
from otjax.surfaces.complex import SimplicialComplex, Triangle, triangle_key
from otjax.surfaces.plan import SurfacePlan

#: Relative decrease of the total cost over a sweep below which relaxation
#: stops (the paper's threshold).
TOLERANCE = 1e-5
MAX_SWEEPS = 10
#: A local solution replaces the plan only if it lowers the stencil's cost by
#: more than this fraction: an equal-cost rewrite gains nothing and would
#: mark the neighbours for another solve.
GAIN = 1e-12


class LocalSolution(NamedTuple):
    """A solved member: ``plan`` ``(P, K)`` feasible, its ``cost``, its ``status``."""

    plan: np.ndarray
    cost: float
    status: int


#: ``solve(problems) -> solutions``, one per problem, in order.
Solver = Callable[[Sequence[LocalLP]], Sequence[LocalSolution]]
#: ``stencil_of(facet) -> (vertices, facets)``: the simplices of a facet's stencil.
StencilRule = Callable[[Triangle], tuple[Sequence[int], Sequence[Triangle]]]


class RelaxationStats(NamedTuple):
    """What a relaxation did.

    Attributes:
      costs: total cost before the first sweep and after each sweep.
      solves: local LPs solved.
      accepted: solutions written back (cost not higher than before).
      rounds: solver calls (rounds of vertex-disjoint stencils).
      unconverged: solutions whose status was not converged (kept only if
        they still lowered the cost: every returned plan is feasible).
      ruled_out: stencils due for a solve that the search before a sweep
        found unable to improve (not built).
      bounded: stencils built but not solved, their bound showing no gain.
    """

    costs: tuple[float, ...]
    solves: int
    accepted: int
    rounds: int
    unconverged: int
    ruled_out: int = 0
    bounded: int = 0

    @property
    def sweeps(self) -> int:
        return len(self.costs) - 1


def facet_ring(complex_: SimplicialComplex) -> StencilRule:
    """The paper's stencil of a facet: it, the facets sharing an edge with it,
    and their vertices."""

    def rule(facet: Triangle):
        facets = (facet,) + complex_.triangle_neighbors(facet)
        return sorted({v for t in facets for v in t}), facets

    return rule


def rounds_of(stencils: Sequence[Sequence[int]]) -> list[list[int]]:
    """Splits stencils (given by their vertex sets) into rounds of
    vertex-disjoint ones, first fit in the given order.

    Example:
      >>> rounds_of([[0, 1], [1, 2], [3], [2, 3]])
      [[0, 2], [1], [3]]
    """
    busy: dict[int, set[int]] = {}
    rounds: list[list[int]] = []
    for i, verts in enumerate(stencils):
        taken = set().union(*(busy.get(v, ()) for v in verts))
        r = 0
        while r in taken:
            r += 1
        if r == len(rounds):
            rounds.append([])
        rounds[r].append(i)
        for v in verts:
            busy.setdefault(v, set()).add(r)
    return rounds


def relax(plan: SurfacePlan, solve: Solver, stencil_of: StencilRule | None = None, *,
          centres: Sequence[Triangle] | None = None, tolerance: float = TOLERANCE,
          max_sweeps: int = MAX_SWEEPS, seed: int = 0) -> RelaxationStats:
    """Relaxes ``plan`` in place by sweeps of local solves (Algorithm 2).

    Args:
      plan: the plan to improve; only its entries change.
      solve: the local LP solver (:data:`Solver`); its plans must be feasible.
      stencil_of: the stencil of a centre facet; default :func:`facet_ring`.
      centres: the facets whose stencils are swept; default every facet.
      tolerance: stop when a sweep lowers the cost by less than this fraction.
      max_sweeps: at most this many sweeps.
      seed: seeds the order of the stencils within each sweep.

    Returns:
      :class:`RelaxationStats`. The total cost never rises: a local solution
      is written back only if it costs less than what it replaces.

    Stencils that cannot lower the cost are not solved, which changes no
    outcome (their solution would be rejected): those whose simplices did not
    change since their last solve (the LP is the same), and those in which no
    point has a bin cheaper than what it pays now (no plan of the stencil
    costs less than ``sum_i m_i min_j C_ij``). The second test is made for
    every stencil at the start of a sweep from one radius search per point,
    and again on each stencil when its round comes.
    """
    rule = stencil_of or facet_ring(plan.complex)
    centres = sorted(plan.complex.triangles) if centres is None else list(centres)
    simplices = [rule(c) for c in centres]
    index = StencilIndex(plan, simplices)
    rng = np.random.default_rng(seed)
    total = plan.total_cost()
    costs = [total]
    solves = accepted = n_rounds = unconverged = ruled_out = bounded = 0
    changed_at = np.full(index.n_simplices, -1)
    solved_at = np.full(len(centres), -1)
    clock = 0
    for _ in range(max_sweeps):
        clock += 1
        stale = (solved_at < 0) | (index.last_change(changed_at) > solved_at)
        live = stale & index.improvable(plan)
        solved_at[stale & ~live] = clock
        ruled_out += int(np.sum(stale & ~live))
        order = [i for i in rng.permutation(len(centres)) if live[i]]
        for members in rounds_of([simplices[i][0] for i in order]):
            clock += 1
            ids = [order[i] for i in members]
            solved_at[ids] = clock
            cut = [s for s in (plan.stencil(*simplices[i]) for i in ids) if len(s.points)]
            cut = [s for s in cut if lower_bound(s.lp) < s.cost * (1.0 - GAIN)]
            bounded += len(members) - len(cut)
            if not cut:
                continue
            solutions = solve([s.lp for s in cut])
            n_rounds += 1
            solves += len(cut)
            for stencil, sol in zip(cut, solutions):
                if sol.status not in (CONVERGED, ITERATION_LIMIT):
                    continue
                unconverged += sol.status != CONVERGED
                written = plan.sparsified(stencil, sol.plan)
                if float(np.sum(written * stencil.lp.cost)) < stencil.cost * (1.0 - GAIN):
                    plan.assign(stencil, written)
                    accepted += 1
                    changed_at[index.ids(stencil.vertices, stencil.facets)] = clock
        previous, total = total, plan.total_cost()
        costs.append(total)
        if previous - total <= tolerance * previous:
            break
    return RelaxationStats(tuple(costs), solves, accepted, n_rounds, unconverged, ruled_out, bounded)


class StencilIndex:
    """The simplices of every stencil as integer ids (vertex ``v`` is ``v``,
    facet ``f`` of the sorted stencil facets is ``V + f``), every bin's
    position with its simplex, and the test of which stencils may improve.
    Positions do not change during a relaxation, so all of it is built once.
    """

    def __init__(self, plan: SurfacePlan, simplices):
        facets = sorted({triangle_key(*t) for _, fs in simplices for t in fs})
        plan.ensure_bins(facets)
        nv = len(plan.complex.positions)
        self.n_vertices = nv
        self.facet_id = {t: nv + i for i, t in enumerate(facets)}
        self.n_simplices = nv + len(facets)
        rows = [np.fromiter(list(map(int, vs)) + [self.facet_id[triangle_key(*t)] for t in fs], np.int64)
                for vs, fs in simplices]
        self.size = np.array([len(r) for r in rows], np.int64)
        self.start = np.concatenate([[0], np.cumsum(self.size)])
        self.flat = np.concatenate(rows) if rows else np.zeros(0, np.int64)
        stencil = np.repeat(np.arange(len(rows)), self.size)
        # simplex -> stencils holding it (CSR), and sorted (stencil, simplex) keys
        order = np.argsort(self.flat, kind="stable")
        self.holders = stencil[order]
        self.holder_start = np.searchsorted(self.flat[order], np.arange(self.n_simplices + 1))
        self.keys = np.sort(stencil * self.n_simplices + self.flat)
        # every bin: position and simplex id; a facet's bins start at bin_start[id - V]
        counts = np.array([len(plan.bins[t].capacity) for t in facets], np.int64)
        self.bin_start = np.concatenate([[0], np.cumsum(counts)])
        corners = plan.complex.positions[np.array(facets, np.int64).reshape(-1, 3)]
        bary = (np.concatenate([plan.bins[t].barycentric for t in facets]) if facets
                else np.zeros((0, 3)))
        facet_bins = np.einsum("nk,nkd->nd", bary, np.repeat(corners, counts, axis=0))
        self.bin_pos = np.concatenate([plan.complex.positions, facet_bins])
        self.bin_owner = np.concatenate([np.arange(nv), nv + np.repeat(np.arange(len(facets)), counts)])
        usable = np.concatenate([plan.complex.alive, np.ones(len(facet_bins), bool)])
        self.tree = scipy.spatial.cKDTree(self.bin_pos[usable])
        self.tree_bin = np.flatnonzero(usable)

    def ids(self, vertices, facets) -> np.ndarray:
        return np.array(list(vertices) + [self.facet_id[t] for t in facets], np.int64)

    def last_change(self, changed_at: np.ndarray) -> np.ndarray:
        """``(stencils,)`` latest change of any of each stencil's simplices."""
        if len(self.flat) == 0:
            return np.full(len(self.size), -1)
        return np.maximum.reduceat(changed_at[self.flat], self.start[:-1])

    def improvable(self, plan: SurfacePlan) -> np.ndarray:
        """``(stencils,)`` bool: stencils holding a point and a bin that costs
        that point less per unit of mass than the dearest entry it has now.

        A stencil without such a pair cannot lower its cost: every point's
        partial mass there pays at least its cheapest bin in the stencil,
        which is no less than what it pays now on average.
        """
        point, sid, unit = self._entries(plan)
        live = np.zeros(len(self.size), bool)
        if len(point) == 0:
            return live
        worst = np.zeros(len(plan.points))
        np.maximum.at(worst, point, unit)
        who = np.flatnonzero(worst > 0)
        hits = self.tree.query_ball_point(plan.points[who], np.sqrt(worst[who]))
        n_hits = np.fromiter(map(len, hits), np.int64, len(hits))
        if n_hits.sum() == 0:
            return live
        p = np.repeat(who, n_hits)
        b = self.tree_bin[np.concatenate([np.asarray(h, np.int64) for h in hits if len(h)])]
        cheaper = np.sum((plan.points[p] - self.bin_pos[b]) ** 2, axis=1) < worst[p]
        pair = np.unique(np.c_[p[cheaper], self.bin_owner[b[cheaper]]], axis=0)
        if len(pair) == 0:
            return live
        # (point, stencil holding the cheaper bin's simplex) ...
        lo, hi = self.holder_start[pair[:, 1]], self.holder_start[pair[:, 1] + 1]
        reps = hi - lo
        cand_point = np.repeat(pair[:, 0], reps)
        cand_stencil = self.holders[np.repeat(lo - np.cumsum(reps) + reps, reps) + np.arange(reps.sum())]
        # ... kept if that stencil also holds a simplex the point is on now
        src = np.unique(np.c_[point, sid], axis=0)
        s_lo = np.searchsorted(src[:, 0], cand_point)
        s_hi = np.searchsorted(src[:, 0], cand_point, side="right")
        s_reps = s_hi - s_lo
        c_stencil = np.repeat(cand_stencil, s_reps)
        c_src = src[np.repeat(s_lo - np.cumsum(s_reps) + s_reps, s_reps) + np.arange(s_reps.sum()), 1]
        keys = c_stencil * self.n_simplices + c_src
        pos = np.searchsorted(self.keys, keys)
        found = (pos < len(self.keys)) & (self.keys[np.minimum(pos, len(self.keys) - 1)] == keys)
        live[c_stencil[found]] = True
        return live

    def _entries(self, plan: SurfacePlan):
        """Every entry of the plan on a stencil simplex: point, simplex id, cost per unit mass."""
        pts, sids, units = [], [], []
        for v, e in plan.vertex_entries.items():
            pts.append(e.point)
            sids.append(np.full(len(e.point), v))
            units.append(np.sum((plan.points[e.point] - plan.complex.positions[v]) ** 2, axis=1))
        fp, fs, fb = [], [], []
        for t, e in plan.facet_entries.items():
            f = self.facet_id.get(t)
            if f is None:
                continue
            fp.append(e.point)
            fs.append(np.full(len(e.point), f))
            fb.append(self.bin_start[f - self.n_vertices] + e.bin)
        if fp:
            fp, fs, fb = np.concatenate(fp), np.concatenate(fs), np.concatenate(fb)
            pts.append(fp)
            sids.append(fs)
            units.append(np.sum((plan.points[fp] - self.bin_pos[self.n_vertices + fb]) ** 2, axis=1))
        if not pts:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        return np.concatenate(pts), np.concatenate(sids), np.concatenate(units)
