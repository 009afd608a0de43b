"""Vertex relocation (Digne et al. 2014, §4.3 and §5) and gradient refinement.

With the plan fixed, every simplex around a vertex ``v`` gives a closed-form
best position for it (:func:`otjax.surfaces.fixed_plan_cost.vertex_targets`);
:func:`relocate` moves ``v`` half way to their mass-weighted average (the
paper's damping), re-solves the transport on the closed star of ``v`` and
keeps the move only if that star's cost does not rise, a few times in turn.
The paper moves unconditionally; otjax also asks for no rise, because the
mass-weighted average of the per-simplex optima is not the minimiser of the
fixed-plan cost and can, for a facet whose points sit near its other
corners, overshoot. Many vertices are handled at once: their targets come
from one kernel call, and vertices whose closed stars share no vertex are
moved and re-solved together, in one solver call.

:func:`refine` is the optional gradient refinement: conjugate gradient on the
fixed-plan cost (:func:`otjax.surfaces.fixed_plan_cost.refine_positions`),
which never raises it.

No facet may degenerate (the design's one geometric rule in 3D): a move
that would flatten a star facet below :data:`MIN_ASPECT` (and flatter than
it was) is not made.
"""

from __future__ import annotations

from typing import NamedTuple, Sequence

import jax
import numpy as np

from otjax.batch.pipeline import require_x64
from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, capacity_class
from otjax.lp.problem import LocalLP
from otjax.surfaces.fixed_plan_cost import (FixedPlanEntries, TargetSegments, fixed_plan_cost,
                                            refine_positions, vertex_targets)
from otjax.surfaces.plan import Stencil, SurfacePlan
from otjax.surfaces.relaxation import GAIN, TOLERANCE, Solver, rounds_of

#: Alternations of (move half way, re-solve the star) per call of :func:`relocate`.
ROUNDS = 4
#: The paper's damping: the move goes this fraction of the way to the target.
DAMPING = 0.5
#: A facet is degenerate below this ``area / longest edge^2`` (equilateral: 0.433).
MIN_ASPECT = 1e-6
#: Conjugate-gradient steps of :func:`refine`.
REFINE_STEPS = 8
#: Halvings of a refinement step tried when the full step flattens a facet.
REFINE_HALVINGS = 8

# Smallest padded sizes (powers of two): a relocation of a one-ring or a
# refinement of a few stars fits the first class, so one shape compiles.
_MIN_ROWS = 8
_MIN_VERTICES = 32
_MIN_POINTS = 64
_MIN_ENTRIES = 256
_MIN_SHARES = 64


class PackedEntries(NamedTuple):
    """Plan entries of a list of simplices, padded, over compact vertex rows.

    Attributes:
      vertex_ids: ``(V,)`` int64 global id of each real position row.
      positions: ``(Vc, 3)`` float64 positions, rows past ``V`` are 0.
      points: ``(Pc, 3)`` float64 the entries' points, pad rows 0.
      entries: :class:`FixedPlanEntries` (NumPy), ``Ec`` rows, mass 0 past the real ones.
      segment: ``(Ec,)`` int64 index in the simplex list of each entry. Pad 0.
    """

    vertex_ids: np.ndarray
    positions: np.ndarray
    points: np.ndarray
    entries: FixedPlanEntries
    segment: np.ndarray


class RelocationStats(NamedTuple):
    """What :func:`relocate` did.

    Attributes:
      delta: change of the plan's total cost (``<= 0``).
      accepted: moves kept (the re-solved star cost no higher than before).
      rejected: moves undone (the re-solved star cost rose).
      degenerate: moves not made because a star facet would degenerate.
      solves: local LPs solved.
      rounds: alternations run.
      moved: ids of the vertices whose position changed, increasing.
      changed: ids of every vertex of a star whose entries or positions
        changed (the moved vertices and their neighbours), increasing: what
        a decimation must score again.
    """

    delta: float
    accepted: int
    rejected: int
    degenerate: int
    solves: int
    rounds: int
    moved: tuple[int, ...]
    changed: tuple[int, ...]


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


# ---------------------------------------------------------------- packing
class SimplexEntries(NamedTuple):
    """The entries of one simplex: ``point (n,)``, bin ``corners (n, 3)`` and
    ``barycentric (n, 3)`` coordinates (a vertex bin: corners all the vertex,
    weights ``(1, 0, 0)``), ``mass (n,)``."""

    point: np.ndarray
    corners: np.ndarray
    barycentric: np.ndarray
    mass: np.ndarray


def _simplex_entries(plan: SurfacePlan, simplex) -> SimplexEntries | None:
    """The :class:`SimplexEntries` of one simplex, or None when it has none."""
    e = plan.entries(simplex)
    if e is None:
        return None
    n = len(e.point)
    if isinstance(simplex, tuple):
        corners = np.broadcast_to(np.array(simplex, np.int64), (n, 3))
        return SimplexEntries(e.point, corners, plan.bins[simplex].barycentric[e.bin], e.mass)
    bary = np.zeros((n, 3))
    bary[:, 0] = 1.0
    return SimplexEntries(e.point, np.full((n, 3), int(simplex), np.int64), bary, e.mass)


def pack_entries(plan: SurfacePlan, simplices: Sequence, vertices: Sequence[int] = ()) -> PackedEntries:
    """The entries of ``simplices`` (vertex ids or facet keys; one may repeat)
    as padded arrays; ``vertices`` get position rows even if no entry uses them.

    Example:
      >>> from otjax.surfaces.complex import SimplicialComplex
      >>> from otjax.surfaces.plan import BinSettings
      >>> c = SimplicialComplex(np.eye(3), np.array([[0, 1, 2]]))
      >>> plan = SurfacePlan(c, np.eye(3) * 0.9, np.ones(3), BinSettings(diagonal=1.0))
      >>> p = pack_entries(plan, [0, 1])
      >>> p.vertex_ids.tolist(), float(p.entries.mass.sum()), p.segment[:2].tolist()
      ([0, 1], 2.0, [0, 1])
    """
    found = (_simplex_entries(plan, x) for x in simplices)
    parts = [(s, got) for s, got in enumerate(found) if got is not None]
    if parts:
        point, corners, bary, mass = (np.concatenate(column) for column in zip(*(g for _, g in parts)))
        segment = np.concatenate([np.full(len(g.point), s, np.int64) for s, g in parts])
    else:
        point, corners = np.zeros(0, np.int64), np.zeros((0, 3), np.int64)
        bary, mass, segment = np.zeros((0, 3)), np.zeros(0), np.zeros(0, np.int64)
    wanted = np.concatenate([corners.ravel(), np.asarray(vertices, np.int64).ravel()])
    ids, rows = np.unique(wanted, return_inverse=True)
    pids, prow = np.unique(point, return_inverse=True)
    n, cap = len(point), capacity_class(len(point), _MIN_ENTRIES)
    pad = (lambda a, size: np.concatenate([a, np.zeros((size - len(a),) + a.shape[1:], a.dtype)]))
    positions = pad(plan.complex.positions[ids], capacity_class(len(ids), _MIN_VERTICES))
    points = pad(plan.points[pids], capacity_class(len(pids), _MIN_POINTS))
    corner_rows = rows[:3 * n].reshape(n, 3).astype(np.int64)
    entries = FixedPlanEntries(pad(prow.astype(np.int64), cap), pad(corner_rows, cap), pad(bary, cap),
                               pad(mass, cap))
    return PackedEntries(ids, positions, points, entries, pad(segment, cap))


def _rows_of(packed: PackedEntries, vertices) -> np.ndarray:
    return np.searchsorted(packed.vertex_ids, np.asarray(vertices, np.int64))


def star_simplices(plan: SurfacePlan, v: int) -> list:
    """``[v]`` and the facets containing ``v``, sorted: the simplices whose
    bins move with ``v``."""
    return [int(v)] + sorted(plan.complex.vertex_triangles[v])


# ---------------------------------------------------------------- targets
class StarTargets(NamedTuple):
    """Targets of a batch of vertices and the shares they average.

    Attributes:
      target: ``(B, 3)`` averaged optimal position of each vertex (its
        current position if none of its simplices carries mass).
      shares: ``(S,)`` list of ``(row, simplex)``: the batch row and the
        simplex (vertex id or facet key) of each share.
      share_target: ``(S, 3)`` the minimiser of each share alone (0 where
        the share pins nothing down).
      share_mass: ``(S,)`` the mass each share carries.
    """

    target: np.ndarray
    shares: list
    share_target: np.ndarray
    share_mass: np.ndarray


def star_targets(plan: SurfacePlan, vertices: Sequence[int], quadratic: bool = False) -> StarTargets:
    """Closed-form optimal positions of ``vertices`` with the plan fixed (§4.3), in one kernel call.

    Each simplex of a vertex's star carrying mass gives ``v*(t)`` (its
    vertex bin: the mean of its points); their average is weighted by the
    simplices' masses (the paper) or, with ``quadratic``, by their curvatures
    (the exact minimiser of the vertex's fixed-plan cost).

    Args:
      plan: the plan (unchanged).
      vertices: ``B`` live vertex ids.
      quadratic: the weighting (see :func:`~otjax.surfaces.fixed_plan_cost.vertex_targets`).

    Returns:
      :class:`StarTargets`.
    """
    require_x64("star_targets")
    vertices = [int(v) for v in vertices]
    shares = [(r, s) for r, v in enumerate(vertices) for s in star_simplices(plan, v)]
    if not vertices:
        return StarTargets(np.zeros((0, 3)), [], np.zeros((0, 3)), np.zeros(0))
    packed = pack_entries(plan, [s for _, s in shares], vertices)
    share_row = np.array([r for r, _ in shares], np.int64)
    row_vertex = _rows_of(packed, vertices)
    n_rows = capacity_class(len(vertices), _MIN_ROWS)
    row = np.zeros(capacity_class(len(shares), _MIN_SHARES), np.int64)
    row[:len(shares)] = share_row
    segments = TargetSegments(row_vertex[share_row[packed.segment]], packed.segment, row,
                              np.concatenate([row_vertex, np.zeros(n_rows - len(vertices), np.int64)]))
    got = vertex_targets(packed.positions, packed.points, packed.entries, segments, quadratic=quadratic)
    n = len(shares)
    return StarTargets(np.asarray(got.target)[:len(vertices)], shares, np.asarray(got.simplex_target)[:n],
                       np.asarray(got.simplex_mass)[:n])


def relocation_targets(plan: SurfacePlan, vertices: Sequence[int], quadratic: bool = False) -> np.ndarray:
    """``(B, 3)`` float64 closed-form targets of ``vertices``: :attr:`StarTargets.target`
    of :func:`star_targets`.

    Example:
      >>> from otjax.surfaces.complex import SimplicialComplex
      >>> from otjax.surfaces.plan import BinSettings
      >>> c = SimplicialComplex(np.eye(3), np.array([[0, 1, 2]]))
      >>> points = np.array([[0.9, 0, 0], [1.1, 0, 0.2]])
      >>> plan = SurfacePlan(c, points, np.ones(2), BinSettings(diagonal=1.0))
      >>> with jax.enable_x64(True):
      ...     relocation_targets(plan, [0, 2]).round(6).tolist()
      [[1.0, 0.0, 0.1], [0.0, 0.0, 1.0]]
    """
    return star_targets(plan, vertices, quadratic).target


# --------------------------------------------------------------- geometry
def aspect(corners: np.ndarray) -> np.ndarray:
    """``(F,)`` ``area / longest edge^2`` of triangles ``(F, 3, 3)`` (0 for a flat one)."""
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = 0.5 * np.linalg.norm(cross, axis=1)
    longest = np.max(np.sum((corners - np.roll(corners, 1, axis=1)) ** 2, axis=2), axis=1)
    return np.where(longest > 0, area / np.where(longest > 0, longest, 1.0), 0.0)


def degenerates(before: np.ndarray, after: np.ndarray) -> bool:
    """Whether some triangle ``(F, 3, 3)`` is flatter than :data:`MIN_ASPECT`
    ``after`` and flatter than ``before``: a move may not flatten a facet, but
    need not mend one that already is."""
    new, old = aspect(after), aspect(before)
    return bool(np.any((new < MIN_ASPECT) & (new < old)))


def _star_corners(plan: SurfacePlan, v: int, position: np.ndarray) -> np.ndarray:
    """``(F, 3, 3)`` corners of the facets of ``v`` with ``v`` at ``position``."""
    facets = np.array(sorted(plan.complex.vertex_triangles[v]), np.int64).reshape(-1, 3)
    corners = plan.complex.positions[facets]
    corners[facets == v] = position
    return corners


# ------------------------------------------------------------- relocation
def relocate(plan: SurfacePlan, vertices: Sequence[int], solve: Solver, rounds: int = ROUNDS, *,
             damping: float = DAMPING, quadratic: bool = False) -> RelocationStats:
    """Relocates ``vertices`` in place by alternating closed-form moves and local re-solves (§4.3).

    Each round, for each group of vertices whose closed stars share no vertex
    (first fit in the given order): targets by :func:`relocation_targets`,
    every vertex moved ``damping`` of the way there, the transport on each
    closed star (its vertices, its facets) re-solved by ``solve`` in one
    call, and a move kept only if its star's cost after the re-solve is no
    higher than before the move; otherwise the vertex goes back and its
    entries stay as they were. Groups see the moves of earlier groups: the
    paper's one vertex after the other, batched where the stars are apart.

    Args:
      plan: the plan; its complex's positions and its entries change.
      vertices: live vertex ids to relocate (duplicates and dead ids are ignored).
      solve: the local LP solver (:data:`~otjax.surfaces.relaxation.Solver`).
      rounds: at most this many alternations; stops after a round that
        lowers the cost of the stars it moves by less than
        :data:`~otjax.surfaces.relaxation.TOLERANCE` of it.
      damping: the fraction of the way to the target a move goes.
      quadratic: the targets' weighting (:func:`relocation_targets`).

    Returns:
      :class:`RelocationStats`; the plan's total cost changes by ``delta <= 0``.
    """
    require_x64("relocate")
    c = plan.complex
    vertices = sorted({int(v) for v in vertices if c.alive[v]})
    stencil = {v: (c.vertex_closure(v).vertices, c.star(v).triangles) for v in vertices}
    groups = [[vertices[i] for i in g] for g in rounds_of([stencil[v][0] for v in vertices])]
    tally = dict(delta=0.0, accepted=0, rejected=0, degenerate=0, solves=0, star_cost=0.0)
    moved: set[int] = set()
    done = 0
    for _ in range(rounds):
        done += 1
        delta, tally["star_cost"] = tally["delta"], 0.0
        for group in groups:
            _relocate_group(plan, group, stencil, solve, damping, quadratic, tally, moved)
        if delta - tally["delta"] <= TOLERANCE * tally["star_cost"]:
            break
    changed = sorted({u for v in moved for u in stencil[v][0]})
    return RelocationStats(tally["delta"], tally["accepted"], tally["rejected"], tally["degenerate"],
                           tally["solves"], done, tuple(sorted(moved)), tuple(changed))


def _relocate_group(plan, group, stencil, solve, damping, quadratic, tally, moved) -> None:
    """One move and re-solve of vertices with disjoint closed stars; adds
    to ``tally`` and ``moved``."""
    c = plan.complex
    targets = relocation_targets(plan, group, quadratic)
    trial = []  # (vertex, old position, cost of its star before the move)
    for v, target in zip(group, targets):
        old = c.positions[v].copy()
        new = old + damping * (target - old)
        if np.array_equal(new, old):
            continue
        if degenerates(_star_corners(plan, v, old), _star_corners(plan, v, new)):
            tally["degenerate"] += 1
            continue
        trial.append((v, old, plan.stencil(*stencil[v]).cost))
        tally["star_cost"] += trial[-1][2]
        c.move(v, new)
    if not trial:
        return
    cut = [plan.stencil(*stencil[v]) for v, _, _ in trial]
    solvable = [i for i, s in enumerate(cut) if len(s.points)]
    solutions = dict(zip(solvable, solve([cut[i].lp for i in solvable]) if solvable else []))
    tally["solves"] += len(solvable)
    for i, ((v, old, before), s) in enumerate(zip(trial, cut)):
        best, written = s.cost, None
        sol = solutions.get(i)
        if sol is not None and sol.status in (CONVERGED, ITERATION_LIMIT):
            candidate = plan.sparsified(s, sol.plan)
            cost = float(np.sum(candidate * s.lp.cost))
            if cost < s.cost * (1.0 - GAIN):
                best, written = cost, candidate
        if best <= before:
            if written is not None:
                plan.assign(s, written)
            tally["delta"] += best - before
            tally["accepted"] += 1
            moved.add(v)
        else:
            c.move(v, old)
            tally["rejected"] += 1


# ------------------------------------------------------- proposed moves
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
    same as :func:`relocation_targets` on the plan the local one is written
    into); ``None`` if no simplex of the star carries mass."""
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
    (:func:`degenerates`); the first that does not ends the vertex's moves.
    Each round solves the stencils of every vertex still moving in one
    ``solve`` call. Proposals are independent of one another: applying two
    whose closed stars share a vertex is not what visiting them in turn does.

    Args:
      plan: the plan (not changed).
      vertices: ``B`` live vertex ids.
      solve: the local LP solver.
      rounds, damping: as :func:`relocate`.

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
            if np.array_equal(new, x) or degenerates(_star_corners(plan, v, x), _star_corners(plan, v, new)):
                continue
            trials.append((v, new, moved_lp(plan, st, v, new)))
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


# ------------------------------------------------------------- refinement
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
    free_mask[_rows_of(packed, free)] = True
    got = refine_positions(packed.positions, free_mask, packed.points, packed.entries, steps)
    costs = tuple(float(x) for x in np.asarray(got.costs))
    start, end = packed.positions, np.asarray(got.positions)
    unchanged = RefineStats(costs[0], costs[0], costs, 0.0, ())
    if not costs[-1] < costs[0]:
        return unchanged
    rows = _rows_of(packed, corners)
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
