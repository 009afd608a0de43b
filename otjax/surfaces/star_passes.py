"""Relaxation and relocation of a :class:`~otjax.surfaces.star_plan.StarPlan`
over vertex closed stars, a class of vertices at a time (§3.3, §4.3, §5).

A class is a set of vertices whose closed stars share no vertex (a colour
class of :func:`otjax.surfaces.features.star_colouring`, or one vertex in
the paper's sequential order). Its problems are cut out together
(:meth:`StarPlan.cut`) and solved together by :func:`solve_stars`:

- a star whose lower bound ``sum_i m_i min_j C_ij`` is not below its current
  cost cannot improve and is not solved;
- a star whose every point has a cheapest bin free of uniformity
  constraints is solved in closed form;
- with ``"exact"`` the others go to HiGHS one at a time, on their real
  points and bins (:func:`otjax.lp.exact.solve_member`: no padded batch to
  build and unpack);
- otherwise to :func:`otjax.lp.solve.solve` in padded batches of a few
  fixed shapes (:data:`BATCH`, :data:`MIN_POINTS` ...), so that JAX compiles
  few shapes however the class sizes vary; with ``"auto"`` HiGHS re-solves
  only the members the batched solver did not certify, and solves the
  groups too small for a batch (:data:`AUTO_MIN_BATCH`: a class of one
  vertex in the sequential order, the few stencils of an unusual size).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from otjax.lp.batched import NewtonOptions
from otjax.lp.exact import solve_member
from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, LocalLP, TransportLP
from otjax.lp.solve import solve
from otjax.surfaces.mesh_stencils import Stencils
from otjax.surfaces.relaxation import GAIN, MAX_SWEEPS, TOLERANCE, RelaxationStats
from otjax.surfaces.relocation import DAMPING, MIN_ASPECT, aspect
from otjax.surfaces.star_plan import StarBatch, StarPlan, face_normals, sparsify, width

#: Members per batched solver call, whatever the class size, so that each
#: stencil shape compiles once: members past a class are empty and the
#: solver's chunks of them stop at once (docs/decisions.md#feature_recovery_batches).
BATCH = 256
#: With ``"auto"``, a shape group of fewer members goes to HiGHS: one
#: batched call costs about as much as this many HiGHS solves.
AUTO_MIN_BATCH = 8
#: Smallest padded points, bins and simplices of a star problem: a valence-6
#: star on a mesh with a few points per vertex fits, so most stars share one shape.
MIN_POINTS = 64
MIN_BINS = 32
MIN_SIMPLICES = 16
#: The batched solver's settings here: half its default step budget. A chunk
#: of members runs until its slowest is done, and a few star problems in a
#: hundred need three times the median steps; with ``"auto"`` HiGHS solves
#: those instead (docs/decisions.md#feature_recovery_batches).
OPTIONS = NewtonOptions(steps=24)


class StarSolution(NamedTuple):
    """What :func:`solve_stars` returns for a :class:`StarBatch` of ``B`` stars.

    Attributes:
      plan: ``(B, P, K)`` float64 sparsified optimal plans (0 where ``better`` is False).
      cost: ``(B,)`` float64 their costs (the current cost where ``better`` is False).
      better: ``(B,)`` bool a plan costing less than ``(1 - GAIN)`` of the current one was found.
      solved: stars with an LP solved (closed forms included).
      closed_form: of those, solved in closed form.
      bounded: stars not solved, their lower bound showing no gain.
      unconverged: plans used although the solver did not certify them.
      exact: members solved by HiGHS (all of them with ``"exact"``; the
        uncertified ones with ``"auto"``).
    """

    plan: np.ndarray
    cost: np.ndarray
    better: np.ndarray
    solved: int
    closed_form: int
    bounded: int
    unconverged: int
    exact: int


def _batch_size(n: int, method: str) -> int:
    return n if method == "exact" else BATCH  # HiGHS solves one member at a time: nothing compiles


def _transport_lp(batch: StarBatch, rows: np.ndarray, shape: tuple[int, int, int], size: int) -> TransportLP:
    """Members ``rows`` of ``batch`` as a :class:`TransportLP` of ``size`` members and ``(P, K, S)`` ``shape``."""
    p, k, s = shape
    n = len(rows)

    def fit(a, cols, fill=0):
        out = np.full((size, cols) + a.shape[2:], fill, a.dtype)
        width_ = min(cols, a.shape[1])
        out[:n, :width_] = a[rows, :width_]
        return out

    cost = np.zeros((size, p, k))
    pp, kk = min(p, batch.cost.shape[1]), min(k, batch.cost.shape[2])
    cost[:n, :pp, :kk] = batch.cost[rows, :pp, :kk]
    point_mask = fit(batch.point >= 0, p, False)
    bin_mask = fit(batch.bin >= 0, k, False)
    simplex_mask = np.zeros((size, s), bool)
    simplex_mask[:n] = np.arange(s)[None, :] < batch.n_simplices[rows][:, None]
    return TransportLP(cost=cost, mass=fit(batch.mass, p), capacity=fit(batch.capacity, k),
                       simplex=fit(batch.simplex, k), is_vertex=fit(batch.is_vertex, k, False),
                       point_mask=point_mask, bin_mask=bin_mask, simplex_mask=simplex_mask)


def _solve_member(batch: StarBatch, m: int) -> tuple[int, np.ndarray]:
    """``(status, (P, K) plan)`` of star ``m`` of ``batch`` by HiGHS, on its
    real points and bins only (the plan is 0 elsewhere and when not converged)."""
    p, k = int(batch.n_points[m]), int(batch.n_bins[m])
    lp = LocalLP(batch.cost[m, :p, :k], batch.mass[m, :p], batch.capacity[m, :k], batch.simplex[m, :k],
                 batch.is_vertex[m, :k])
    sol = solve_member(lp)
    plan = np.zeros(batch.cost.shape[1:])
    if sol.status == CONVERGED:
        plan[:p, :k] = sol.plan
    return sol.status, plan


def _solve_padded(batch: StarBatch, rest: np.ndarray, method: str, options: NewtonOptions, plans: np.ndarray,
                  todo: np.ndarray) -> tuple[int, int]:
    """Solves stars ``rest`` of ``batch`` in padded batches of a few shapes,
    writing their plans into ``plans`` and clearing ``todo`` where no plan
    is usable; ``(unconverged, exact)`` as in :class:`StarSolution`."""
    _, p_cap, k_cap = plans.shape
    unconverged = exact = 0
    shapes = np.c_[[width(int(n), MIN_POINTS) for n in batch.n_points[rest]],
                   [width(int(n), MIN_BINS) for n in batch.n_bins[rest]],
                   [width(int(n), MIN_SIMPLICES) for n in batch.n_simplices[rest]]].astype(np.int64)
    for shape in {tuple(s) for s in shapes.tolist()}:
        members = rest[np.all(shapes == shape, axis=1)]
        how = "exact" if method == "auto" and len(members) < AUTO_MIN_BATCH else method
        size = _batch_size(len(members), how)
        for lo in range(0, len(members), size):
            part = members[lo:lo + size]
            got = solve(_transport_lp(batch, part, shape, size), how, options)
            sol = got.solution
            exact += len(part) if how == "exact" else got.exact_resolves
            status = np.asarray(sol.status)[:len(part)]
            usable = (status == CONVERGED) | (status == ITERATION_LIMIT)
            unconverged += int(np.sum(usable & (status != CONVERGED)))
            pp, kk = min(shape[0], p_cap), min(shape[1], k_cap)
            got_plan = np.zeros((len(part), p_cap, k_cap))
            got_plan[:, :pp, :kk] = np.asarray(sol.plan)[:len(part), :pp, :kk]
            plans[part[usable]] = got_plan[usable]
            todo[part[~usable]] = False
    return unconverged, exact


def solve_stars(batch: StarBatch, method: str, options: NewtonOptions = OPTIONS) -> StarSolution:
    """The best plan of each star of ``batch`` that lowers its cost (see the module docstring).

    Args:
      batch: the stars (:meth:`StarPlan.cut`).
      method: ``"exact"`` (HiGHS), ``"batched"`` or ``"auto"`` (:func:`otjax.lp.solve.solve`).
      options: the batched solver's settings.

    Returns:
      :class:`StarSolution`; every plan in it is feasible for its star.
    """
    nb, p_cap, k_cap = batch.cost.shape
    plans = np.zeros((nb, p_cap, k_cap))
    cost = batch.current.copy()
    better = np.zeros(nb, bool)
    goal = batch.current * (1.0 - GAIN)
    todo = (batch.n_points > 0) & (batch.lower < goal)
    bounded = int(np.sum((batch.n_points > 0) & ~todo))
    closed = todo & batch.closed_form
    rows = np.flatnonzero(closed)
    if len(rows):
        fb = np.maximum(batch.free_best[rows], 0)
        one_hot = np.zeros((len(rows), p_cap, k_cap))
        np.put_along_axis(one_hot, fb[..., None], batch.mass[rows][..., None], axis=2)
        plans[rows] = one_hot
    rest = np.flatnonzero(todo & ~closed)
    unconverged = 0
    if method == "exact":
        # one member at a time, as cut: no padded batch to build and unpack
        for m in rest.tolist():
            status, plans[m] = _solve_member(batch, m)
            todo[m] &= status == CONVERGED
        exact = len(rest)
    else:
        unconverged, exact = _solve_padded(batch, rest, method, options, plans, todo)
    plans = sparsify(batch.mass, plans)
    candidate = np.einsum("bpk,bpk->b", plans, batch.cost)
    better = todo & (candidate < goal)
    cost = np.where(better, candidate, batch.current)
    plans[~better] = 0.0
    return StarSolution(plans, cost, better, int(np.sum(closed)) + len(rest), int(np.sum(closed)), bounded,
                        unconverged, exact)


# --------------------------------------------------------------- relaxation
def relax_stencils(plan: StarPlan, stencils: Stencils, classes_of, method: str,
                   options: NewtonOptions = OPTIONS, *, tolerance: float = TOLERANCE,
                   max_sweeps: int = MAX_SWEEPS) -> RelaxationStats:
    """Relaxes ``plan`` in place by sweeps of local re-solves (Algorithm 2).

    Args:
      plan: the plan; only its entries change.
      stencils: the stencils swept (e.g. :attr:`StarPlan.rings`, the paper's).
      classes_of: ``classes_of(rows (n,) int64) -> list of (k,) int64``
        splits the stencils due for a solve into classes with no vertex in common.
      method, options: as :func:`solve_stars`.
      tolerance: stop when a sweep lowers the cost by less than this fraction.
      max_sweeps: at most this many sweeps.

    Returns:
      :class:`RelaxationStats` (``rounds``: solver calls, one per class;
      ``ruled_out``: stencils not cut, nothing on them having changed since
      their last solve; ``bounded``: cut but not solved, their lower bound
      showing no gain). The total cost never rises: a stencil's plan is
      replaced only by a cheaper one.
    """
    n = len(stencils.vertices.ptr) - 1
    holders_of_vertex = stencils.incidence(plan.n_vertices).T.tocsr()
    holders_of_facet = stencils.incidence(len(plan.bins.keys), facets=True).T.tocsr()
    total = plan.total_cost()
    costs = [total]
    due = np.ones(n, bool)
    solves = accepted = rounds = unconverged = ruled_out = bounded = 0
    for _ in range(max_sweeps):
        if not due.any():
            break
        ruled_out += int(np.sum(~due))
        for group in classes_of(np.flatnonzero(due)):
            due[group] = False
            batch = plan.cut(stencils, group, MIN_POINTS, MIN_BINS)
            got = solve_stars(batch, method, options)
            rounds += 1
            solves += got.solved
            bounded += got.bounded
            unconverged += got.unconverged
            rows = np.flatnonzero(got.better)
            accepted += len(rows)
            plan.replace(batch, rows, got.plan[rows])
            # due again: every stencil holding a simplex whose entries changed
            changed = stencils.take(group[rows])
            due[holders_of_vertex[changed.vertices.index].indices] = True
            due[holders_of_facet[changed.facets.index].indices] = True
        previous, total = total, plan.total_cost()
        costs.append(total)
        if previous - total <= tolerance * previous:
            break
    return RelaxationStats(tuple(costs), solves, accepted, rounds, unconverged, ruled_out, bounded)


# --------------------------------------------------------------- relocation
#: A move is shortened so that each face around the vertex keeps at least
#: this share of its normal's projection on the input face's normal: no face
#: turns over, and none is brought to the edge of turning in one move.
FLIP_MARGIN = 0.5


def flip_free_steps(corners: np.ndarray, slot: np.ndarray, direction: np.ndarray, reference: np.ndarray,
                    limit: float, margin: float = FLIP_MARGIN) -> np.ndarray:
    """The longest step along ``direction`` each face allows its moving corner.

    Args:
      corners: ``(F, 3, 3)`` triangles, corners in the order ``reference`` was made in.
      slot: ``(F,)`` int which corner moves (0, 1 or 2).
      direction: ``(F, 3)`` the moving corner goes to ``corner + t * direction``.
      reference: ``(F, 3)`` the normals the faces must not turn away from
        (the input mesh's, in the same corner order).
      limit: the longest step asked for.
      margin: the share of the way to turning over a step may go.

    Returns:
      ``(F,)`` the largest ``t`` in ``[0, limit]`` with
      ``n(t) . r >= (1 - margin) n(0) . r`` (``n(t) . r`` is linear in ``t``:
      the normal is linear in each corner); 0 where ``n(0) . r <= 0`` and the
      move would lower it further.
    """
    f = np.arange(len(slot))
    u = corners[f, (slot + 1) % 3]
    w = corners[f, (slot + 2) % 3]
    # with the moving corner x: n = u x w + x x (u - w), so n . r = n(0) . r + t d . ((u - w) x r)
    now = np.einsum("fd,fd->f", face_normals(corners), reference)
    slope = np.einsum("fd,fd->f", direction, np.cross(u - w, reference))
    falling = slope < 0
    turn = np.where(falling, np.maximum(now, 0.0) / np.where(falling, -slope, 1.0), np.inf)
    return np.minimum(limit, margin * turn)


class MoveStats(NamedTuple):
    """What :func:`relocate_class` did: moves ``accepted``, ``rejected`` (the
    star's cost rose; undone), ``degenerate`` (not made: a facet would
    flatten), ``shortened`` (made shorter so that no face turns over), LPs
    ``solved`` and ``exact`` (HiGHS), ``calls`` to the solver (0 or 1)."""

    accepted: int
    rejected: int
    degenerate: int
    shortened: int
    solved: int
    exact: int
    calls: int


def relocate_class(plan: StarPlan, group: np.ndarray, method: str,
                   options: NewtonOptions = OPTIONS, damping: float = DAMPING) -> MoveStats:
    """Moves the vertices ``group`` ``(k,)`` (disjoint closed stars) ``damping``
    of the way to their targets and re-solves their stars, in place (§4.3).

    As :func:`otjax.surfaces.relocation.relocate` with one round: the targets
    with the plan fixed (:meth:`StarPlan.targets`); a move is shortened so
    that no face around the vertex turns away from its input normal
    (:func:`flip_free_steps`: a full move can fold a face over its
    neighbour where the noise is comparable to the edges); a move that would
    flatten a facet of its star below :data:`~otjax.surfaces.relocation.MIN_ASPECT`
    (and flatter than it was) is not made; each moved star is re-solved, and
    a move is kept only if the star's best cost after it is no higher than
    its cost before; otherwise the vertex goes back and its entries stay.
    So the plan's total cost never rises, and no face turns over.
    """
    group = np.asarray(group, np.int64)
    old = plan.positions[group].copy()
    direction = plan.targets(group) - old
    facets, row, _ = plan.star_facets.take(group)
    keys = plan.bins.keys[facets]
    corners = plan.positions[keys]
    at = keys == group[row][:, None]
    allowed = flip_free_steps(corners, np.argmax(at, axis=1), direction[row], plan.reference_normals[facets],
                              damping)
    step = np.full(len(group), float(damping))
    np.minimum.at(step, row, allowed)
    new = old + step[:, None] * direction
    moving = np.any(new != old, axis=1)
    shortened = moving & (step < damping)
    before_aspect = aspect(corners)
    corners[at] = new[row[np.nonzero(at)[0]]]
    after_aspect = aspect(corners)
    flat = (after_aspect < MIN_ASPECT) & (after_aspect < before_aspect)
    degenerate = moving & (np.bincount(row[flat], minlength=len(group)) > 0)
    trial = moving & ~degenerate
    if not trial.any():
        return MoveStats(0, 0, int(degenerate.sum()), 0, 0, 0, 0)
    who = group[trial]
    before = plan.costs(plan.stars.take(who))
    plan.positions[who] = new[trial]
    batch = plan.cut(plan.stars, who, MIN_POINTS, MIN_BINS)
    got = solve_stars(batch, method, options)
    keep = got.cost <= before
    plan.replace(batch, np.flatnonzero(keep & got.better), got.plan[keep & got.better])
    plan.positions[who[~keep]] = old[trial][~keep]
    return MoveStats(int(keep.sum()), int((~keep).sum()), int(degenerate.sum()), int(np.sum(shortened & trial)),
                     got.solved, got.exact, 1)
