"""Vertex relocation (Digne et al. 2014, §4.3 and §5): closed-form targets with
the plan fixed, damped moves with local re-solves.

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

No facet may degenerate (the design's one geometric rule in 3D): a move
that would flatten a star facet below :data:`MIN_ASPECT` (and flatter than
it was) is not made (:func:`degenerates`).

The same moves proposed one vertex at a time without changing the plan, for
the decimation engine, are :mod:`otjax.surfaces.moves`; the optional
gradient refinement is :mod:`otjax.surfaces.refinement`; the padded entries
the target kernel reads are :mod:`otjax.surfaces.packed_entries`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from otjax.batch.pipeline import require_x64
from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, capacity_class
from otjax.surfaces.fixed_plan_cost import TargetSegments, vertex_targets
from otjax.surfaces.packed_entries import pack_entries, rows_of, star_simplices
from otjax.surfaces.plan import SurfacePlan
from otjax.surfaces.relaxation import GAIN, TOLERANCE, Solver, rounds_of

#: Alternations of (move half way, re-solve the star) per call of :func:`relocate`.
ROUNDS = 4
#: The paper's damping: the move goes this fraction of the way to the target.
DAMPING = 0.5
#: A facet is degenerate below this ``area / longest edge^2`` (equilateral: 0.433).
MIN_ASPECT = 1e-6

# Smallest padded sizes (powers of two) of the targets' rows and shares: a
# relocation of a one-ring fits the first class, so one shape compiles.
_MIN_ROWS = 8
_MIN_SHARES = 64


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
    row_vertex = rows_of(packed, vertices)
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
      >>> import jax
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


def star_corners(plan: SurfacePlan, v: int, position: np.ndarray) -> np.ndarray:
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
        if degenerates(star_corners(plan, v, old), star_corners(plan, v, new)):
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
