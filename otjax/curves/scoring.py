"""Fused scoring of candidate changes laid end to end: locate, assign, cost.

The decimation loop scores thousands of candidate collapses whose stencils
hold from ten to several thousand points. Padding each stencil to a batch
row (:class:`otjax.stencil.EdgeStencil`) wasted half the rows on this
heavy-tailed mix, and locating every point of a star among the new triangles
on the host was the largest single cost of a run (~300 ns a point with
NumPy). Here the candidates of one call are laid end to end instead: ``R``
(point, candidate) rows, ``E`` edges, ``T`` new triangles and ``J``
candidates ("jobs"), each padded once to a capacity fixed by one number (see
:func:`capacity`), so a compiled shape does not depend on the input's size.

One jitted call then

1. locates each point of a changed region among its job's new triangles: a
   guess from the angular sector around the fan's apex (the new triangles of
   a collapse are a fan around the target plus a few flipped-out "ears"),
   confirmed by the filtered exact predicate of :mod:`otjax.curves.location`;
   rows whose guess fails are compacted and tested against the neighbouring
   sectors and the ears. A row is located only when the filter is *sure*
   that it is inside, so the answer is the exact perturbed location. Rows
   still unlocated (unsure, or in an ear the retry does not test) are
   tested against every triangle of their job, in exact arithmetic where
   the filter is unsure (:func:`_locate_exactly`); a row left undecided
   after that (rare) is reported and the caller locates it on the host;
2. assigns each point to the nearest edge of its triangle and computes the
   transport cost of every edge with :func:`otjax.curves.cost.stencil_cost`
   on the flat stencil (a point only ever names edges of its own job, so
   laying the jobs end to end changes no per-edge sum);
3. sums the edge costs of each job.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from otjax.batch.fields import Dims, Field, FieldSpec
from otjax.batch.pipeline import ShapePolicy
from otjax.curves.cost import stencil_cost
from otjax.curves.location import INSIDE, UNSURE, in_triangle_adaptive, in_triangle_rows
from otjax.stencil import EdgeStencil

# Per-edge outputs, in the order of the kernel's (E, 6) array.
EDGE_FIELDS = ("edge_cost", "normal", "tangential", "vertex", "edge_mass", "solid")
# Row capacities: every array of a batch is a fixed fraction of one number
# (see capacity), which therefore names a compiled shape. The smallest
# shape, for the few candidates of a step on a small input
# (docs/decisions.md#tiny_rows); the shape most calls of a large run use; the
# rows per call in the decimation loop (docs/decisions.md#row_budget).
TINY_ROWS = 1 << 10
MIN_ROWS = 1 << 12
ROW_BUDGET = 1 << 15
# The compiled shapes: TINY_ROWS, MIN_ROWS and ROW_BUDGET, above that a capacity class.
SHAPES = ShapePolicy(MIN_ROWS, ROW_BUDGET, TINY_ROWS)
# Inputs of at most this many points fill their calls to MIN_ROWS only
# (docs/decisions.md#small_input_rows).
SMALL_INPUT_POINTS = 20_000
# Runs starting from at most this many points per vertex shape their calls
# for stencils of about two rows per edge (docs/decisions.md#EDGES_PER_ROW).
DENSE_VERTICES = 2
JOBS_PER_ROW = 16  # J = R / 16
RETRY_PER_ROW = 4  # rows whose guess fails: at most R / 4 get the second test
# Rows the first tests leave unlocated go through the exact round,
# R / EXACT_PER_ROW rows at a time (docs/decisions.md#exact_in_kernel).
EXACT_PER_ROW = 64
# Flipped-out triangles ("ears") tested in the retry round; a point in one
# of a job's further ears is found by the exact round, which tests every
# triangle (measured on a 50k-point run: 0.2% of jobs have more than 4, none
# more than 7; on the noise-free 3000-point star 4.9%, up to 17).
MAX_EARS = 4
# Steps of the per-job binary search for the sector: fans of up to 256
# triangles (a longer fan, only ever around a relocated hub, gets a wrong
# guess, which the exact test rejects: the host then locates its points).
SECTOR_STEPS = 8


class FlatBatch(NamedTuple):
    """Candidates laid end to end, padded to one capacity (see :func:`capacity`).

    Shapes: ``R`` rows, ``E = T = R / k`` edges and triangles (``k`` the
    :class:`Layout`'s ``edges_per_row``), ``J = R / 16``
    jobs. Indices are flat (into this batch's arrays); padding rows, edges
    and jobs are masked or point at the last (padding) job.

    Attributes:
      row_xy: ``(R, 2)`` float64 the row's point.
      row_mass: ``(R,)`` float64 its mass (``0`` on padding).
      row_job: ``(R,)`` int32 job of the row.
      row_cand: ``(R, 3)`` int32 flat candidate edges, increasing in global
        key (see :class:`~otjax.stencil.EdgeStencil`), for rows not located
        here: a point outside the changed region (its edge repeated) or one
        located on the host.
      row_locate: ``(R,)`` bool: locate this row among its job's triangles.
      row_valid: ``(R,)`` bool.
      tri_xy: ``(6, T)`` float64 rows ``x0, y0, x1, y1, x2, y2`` of the new
        triangles (counter-clockwise).
      tri_edges: ``(T, 3)`` int32 flat edges of each triangle, increasing.
      fan_key: ``(T,)`` float64, sorted: ``8 job + angle`` of the first
        spoke of each fan triangle (pseudo-angle in ``[0, 4)``, relative to
        the job's first spoke); padding ``+inf``.
      fan_tri: ``(T,)`` int32 triangle of each fan key.
      job_fan: ``(J + 1,)`` int32 offsets of each job's fan keys.
      job_apex: ``(J, 2)`` float64 apex of each job's fan.
      job_theta: ``(J,)`` float64 pseudo-angle of each job's first spoke.
      job_ears: ``(J, MAX_EARS)`` int32 flat ears of each job (its first
        ``MAX_EARS``), ``-1`` padding.
      job_tri: ``(J + 1,)`` int32 offsets of each job's triangles (ears, then fan).
      edge_xy: ``(E, 2, 2)`` float endpoints, lower global id first.
      edge_valid: ``(E,)`` bool.
      edge_job: ``(E,)`` int32 job of each edge (``J - 1`` on padding).
    """

    row_xy: np.ndarray
    row_mass: np.ndarray
    row_job: np.ndarray
    row_cand: np.ndarray
    row_locate: np.ndarray
    row_valid: np.ndarray
    tri_xy: np.ndarray
    tri_edges: np.ndarray
    fan_key: np.ndarray
    fan_tri: np.ndarray
    job_fan: np.ndarray
    job_apex: np.ndarray
    job_theta: np.ndarray
    job_ears: np.ndarray
    job_tri: np.ndarray
    edge_xy: np.ndarray
    edge_valid: np.ndarray
    edge_job: np.ndarray


# From this capacity on, three quarters of each power of two is a capacity
# too: a large batch is mostly one big star's candidates, scored alone, and
# a power of two left a third of such batches' rows as padding (1M points,
# last collapses: 65536-row batches 62-66% full).
THREE_QUARTER_FROM = 1 << 15


def capacity(rows: int, edges: int, triangles: int, jobs: int, edges_per_row: int = 4) -> int:
    """Row capacity ``R`` that fits a batch of these sizes when a call holds
    ``R / edges_per_row`` edges and triangles: a power of two, or above
    :data:`THREE_QUARTER_FROM` also ``3/4`` of one.

    Jobs get ``R / 16`` slots and one of them is kept for padding, hence the
    ``jobs + 1``.
    """
    need = max(rows, edges_per_row * max(edges, triangles), JOBS_PER_ROW * (jobs + 1), TINY_ROWS)
    r = 1 << (need - 1).bit_length()
    if r > THREE_QUARTER_FROM and need <= 3 * r // 4:
        return 3 * r // 4
    return r


def _pad_job(r: int) -> int:
    return r // JOBS_PER_ROW - 1


def _fields(edges_per_row: int) -> FieldSpec:
    """The layout of a packed :class:`FlatBatch` with ``R / edges_per_row``
    edges and triangles, written once: field order, dtype kind, shape at row
    capacity ``r``, pad value (padding rows and edges belong to the last job,
    which no batch uses), and the axis a batch fills."""
    per = edges_per_row
    return FieldSpec([
        Field("row_xy", "float", Dims(tail=(2,))),
        Field("row_mass", "float", Dims()),
        Field("row_job", "int", Dims(), pad=_pad_job),
        Field("row_cand", "int", Dims(tail=(3,))),
        Field("row_locate", "bool", Dims()),
        Field("row_valid", "bool", Dims()),
        Field("tri_xy", "float", Dims(per, head=(6,))),
        Field("tri_edges", "int", Dims(per, tail=(3,))),
        Field("fan_key", "float", Dims(per), pad=np.inf),
        Field("fan_tri", "int", Dims(per)),
        Field("job_fan", "int", Dims(JOBS_PER_ROW, plus=1)),
        Field("job_apex", "float", Dims(JOBS_PER_ROW, tail=(2,))),
        Field("job_theta", "float", Dims(JOBS_PER_ROW)),
        Field("job_ears", "int", Dims(JOBS_PER_ROW, tail=(MAX_EARS,)), pad=-1),
        Field("job_tri", "int", Dims(JOBS_PER_ROW, plus=1)),
        Field("edge_xy", "float", Dims(per, tail=(2, 2))),
        Field("edge_valid", "bool", Dims(per)),
        Field("edge_job", "int", Dims(per), pad=_pad_job),
    ])


# The two layouts' fields, by edges per row.
FIELDS = {per: _fields(per) for per in (2, 4)}
assert all(tuple(f.name for f in spec.fields) == FlatBatch._fields for spec in FIELDS.values())


class Layout(NamedTuple):
    """How a run's scoring calls are shaped (their row capacities are
    :data:`SHAPES`'s).

    Attributes:
      edges_per_row: a call of ``R`` rows holds ``E = T = R / edges_per_row``
        edges and triangles (and ``J = R / 16`` jobs).
      budget: the rows a call of the decimation loop is filled to.
    """

    edges_per_row: int
    budget: int

    @property
    def fields(self) -> FieldSpec:
        """The packed layout of this shape's batches."""
        return FIELDS[self.edges_per_row]

    def capacity(self, rows: int, edges: int, triangles: int, jobs: int) -> int:
        """:func:`capacity` in this layout."""
        return capacity(rows, edges, triangles, jobs, self.edges_per_row)


def layout_for(n_points: int, n_vertices: int) -> Layout:
    """The :class:`Layout` of a run on ``n_points`` input points from
    ``n_vertices`` initial vertices.

    Calls are filled to :data:`MIN_ROWS` rows up to
    :data:`SMALL_INPUT_POINTS` points, so that a small run skips the
    :data:`ROW_BUDGET` shape unless one candidate needs it, and to
    :data:`ROW_BUDGET` above. They hold ``R / 2`` edges when the run starts
    from at most :data:`DENSE_VERTICES` points a vertex (its stencils hold
    about one point a triangle, two rows an edge), ``R / 4`` otherwise.

    Example:
      >>> [tuple(layout_for(n, v)) for n, v in ((1000, 1000), (10_000, 2000), (50_000, 2000))]
      [(2, 4096), (4, 4096), (4, 32768)]
    """
    budget = MIN_ROWS if n_points <= SMALL_INPUT_POINTS else ROW_BUDGET
    return Layout(2 if n_points <= DENSE_VERTICES * n_vertices else 4, budget)


def unpack(floats, ints, r: int, edges_per_row: int = 4) -> FlatBatch:
    """The :class:`FlatBatch` views of a batch packed by ``FIELDS[edges_per_row]`` at capacity ``r``."""
    return FlatBatch(**FIELDS[edges_per_row].unpack(floats, ints, r))


def pseudo_angle(dx, dy, xp=np):
    """Monotone stand-in for ``atan2(dy, dx)`` mod ``2 pi``, in ``[0, 4)``.

    ``dy / (|dx| + |dy|)`` per quadrant: a few flops instead of an ``atan2``.
    Only ever used for guesses that an exact test then confirms.
    """
    s = xp.abs(dx) + xp.abs(dy)
    r = xp.where(s > 0, dy / xp.where(s > 0, s, 1), 0)
    return xp.where(dx < 0, 2 - r, xp.where(dy < 0, 4 + r, r))


def _locate(batch: FlatBatch, px, py, need, retry_per_row: int = RETRY_PER_ROW):
    """Flat triangle holding each row's point (``-1``: not located)."""
    job = batch.row_job
    ax, ay = batch.job_apex[job, 0], batch.job_apex[job, 1]
    phi = jnp.mod(pseudo_angle(px - ax, py - ay, jnp) - batch.job_theta[job], 4.0)
    lo, hi = batch.job_fan[job], batch.job_fan[job + 1] - 1
    # Last fan key <= the row's key, searched within the job's own keys only
    # (a search over all keys took twice the steps).
    key = 8.0 * job + phi

    def step(_, bounds):
        below, above = bounds
        mid = (below + above) // 2
        go = (mid < above) & (batch.fan_key[lo + mid] <= key)
        return jnp.where(go, mid + 1, below), jnp.where(go, above, mid)

    # A loop, not unrolled: unrolled, the search alone took 0.5 s to compile.
    below, _ = jax.lax.fori_loop(0, SECTOR_STEPS, step, (jnp.zeros_like(lo), hi - lo + 1))
    g = lo + jnp.maximum(below - 1, 0)
    guess = batch.fan_tri[g]
    ok = need & (hi >= lo) & (in_triangle_rows(batch.tri_xy[:, guess], px, py) == INSIDE)
    loc = jnp.where(ok, guess, -1)

    # Second test, on the rows whose guess failed: the sectors on either side
    # (rounding of the pseudo-angles) and the ears. In rounds of at most
    # R / RETRY_PER_ROW compacted rows until every failed row had its test:
    # one round almost always; more when ears hold over a quarter of the
    # points (large stars late in a 1M-point run: a single retry had 10.5M
    # rows fall back on the host there). Compacted by a cumulative sum
    # (jnp.nonzero compiled 0.2 s slower), one candidate triangle per loop
    # step (a (K, 6) block compiled 0.3 s slower per shape, same work).
    k_rows = max(need.shape[0] // retry_per_row, 1)

    def find(r, _live):
        rj, rg, qx, qy = job[r], g[r], px[r], py[r]
        rlo, rhi = batch.job_fan[rj], batch.job_fan[rj + 1] - 1
        width = jnp.maximum(rhi - rlo + 1, 1)
        sides = [batch.fan_tri[rlo + jnp.mod(rg - rlo + k, width)] for k in (-1, 1)]
        tris = jnp.stack(sides + [batch.job_ears[rj, k] for k in range(MAX_EARS)], 1)  # (K, 2 + MAX_EARS)
        tris = jnp.where((rhi >= rlo)[:, None], tris, -1)

        def test(k, found):
            t = jax.lax.dynamic_index_in_dim(tris, k, 1, keepdims=False)
            hit = (t >= 0) & (in_triangle_rows(batch.tri_xy[:, jnp.maximum(t, 0)], qx, qy) == INSIDE)
            return jnp.where((found < 0) & hit, t, found)

        return jax.lax.fori_loop(0, tris.shape[1], test, jnp.full(k_rows, -1, tris.dtype))

    return _in_rounds(loc, need & ~ok, k_rows, find)


def _in_rounds(loc, waiting, k_rows: int, find):
    """``loc`` with ``find``'s answers for the ``waiting`` rows, compacted
    ``k_rows`` to a round until each had its round.

    Args:
      loc: ``(R,)`` flat triangle of each row (``-1``: not located).
      waiting: ``(R,)`` bool, the rows to locate.
      k_rows: rows a round.
      find: ``find(r, live) -> (k_rows,)`` triangles (``-1``: not found) of
        the rows ``r (k_rows,)``, ``live`` marking the real ones.
    """
    n_rows = loc.shape[0]

    def one_round(state):
        loc, waiting = state
        slot = jnp.where(waiting, jnp.cumsum(waiting) - 1, k_rows)
        retry = jnp.full(k_rows, n_rows, jnp.int32).at[slot].set(jnp.arange(n_rows, dtype=jnp.int32),
                                                                 mode="drop")
        found = find(jnp.minimum(retry, n_rows - 1), retry < n_rows)
        return loc.at[retry].set(found, mode="drop"), waiting & (slot >= k_rows)

    loc, _ = jax.lax.while_loop(lambda state: state[1].any(), one_round, (loc, waiting))
    return loc


def _locate_exactly(batch: FlatBatch, px, py, loc, per_row: int = EXACT_PER_ROW):
    """``loc`` with the rows the first tests left unlocated located by exact arithmetic.

    Each such row is tested against every new triangle of its job: by the
    float filter, and where some lane of the round is unsure, by
    :func:`~otjax.curves.location.in_triangle_adaptive`, which decides all
    but the orientations within ``~1e-32`` relative of zero with inexact
    coordinate differences. This locates nearly every row the filter could
    not (exactly collinear input: points lie within rounding of the new
    spokes) and the points in ears beyond the first :data:`MAX_EARS`; a row
    it cannot decide stays ``-1``. In rounds of at most ``R / per_row``
    compacted rows, as the retries of :func:`_locate`.
    """
    k_rows = max(loc.shape[0] // per_row, 1)

    def find(r, live_row):
        rj, qx, qy = batch.row_job[r], px[r], py[r]
        first = batch.job_tri[rj]
        count = jnp.where(live_row, batch.job_tri[rj + 1] - first, 0)

        def test(k, found):
            live = k < count
            tri = batch.tri_xy[:, jnp.where(live, first + k, 0)]
            code = in_triangle_rows(tri, qx, qy)
            unsure = live & (found < 0) & (code == UNSURE)
            # The adaptive stages cost ~10x the filter: only where a lane needs them.
            code = jax.lax.cond(unsure.any(), lambda: jnp.where(unsure, in_triangle_adaptive(tri, qx, qy), code),
                                lambda: code)
            return jnp.where(live & (found < 0) & (code == INSIDE), first + k, found)

        return jax.lax.fori_loop(0, jnp.max(count), test, jnp.full(k_rows, -1, loc.dtype))

    return _in_rounds(loc, batch.row_locate & batch.row_valid & (loc < 0), k_rows, find)


class Scores(NamedTuple):
    """What :func:`score_flat` returns (a pytree).

    Attributes:
      total: ``(J,)`` each job's cost after the change.
      per_edge: ``(E, 6)`` per edge, the fields :data:`EDGE_FIELDS`.
      assignment: ``(R,)`` each row's flat edge (``-1`` on padding).
      located: ``(R,)`` each located row's flat triangle (``-1`` elsewhere).
      unresolved: ``(J,)`` per job, how many of its rows the kernel could not
        locate (its costs are then meaningless).
    """

    total: jax.Array
    per_edge: jax.Array
    assignment: jax.Array
    located: jax.Array
    unresolved: jax.Array


# Its calls are kept as exported modules (otjax.batch.exported).
jax.export.register_namedtuple_serialization(Scores, serialized_name="otjax.curves.scoring.Scores")


@functools.partial(jax.jit, static_argnames=("dtype", "retry_per_row", "exact", "exact_per_row"))
def score_flat(batch: FlatBatch, dtype=jnp.float64, retry_per_row: int = RETRY_PER_ROW, exact: bool = True,
               exact_per_row: int = EXACT_PER_ROW):
    """Locates, assigns and costs a flat batch; see the module docstring.

    Args:
      batch: a :class:`FlatBatch` of capacity ``R``.
      dtype: float type of the cost arithmetic (location is always float64).
      retry_per_row: a retry round takes at most ``R / retry_per_row`` of
        the rows whose guess failed (tests set it high to force rounds).
      exact: locate the rows the guess and retry leave (filter unsure, or
        in an ear the retry does not test) in the exact round
        (:func:`_locate_exactly`); off, they are all left to the host.
      exact_per_row: an exact round takes at most ``R / exact_per_row`` rows.

    Returns:
      :class:`Scores`.
    """
    p = batch.row_xy
    px, py = p[:, 0], p[:, 1]
    need = batch.row_locate & batch.row_valid
    loc = _locate(batch, px, py, need, retry_per_row)
    if exact:
        loc = _locate_exactly(batch, px, py, loc, exact_per_row)
    unresolved = need & (loc < 0)
    cand = jnp.where(need[:, None], batch.tri_edges[jnp.maximum(loc, 0)], batch.row_cand)
    m = jnp.where(batch.row_valid, batch.row_mass, 0).astype(dtype)
    res = stencil_cost(EdgeStencil(batch.edge_xy.astype(dtype), batch.edge_valid, p.astype(dtype), m,
                                   batch.row_valid, cand), "sort")
    n_jobs = batch.job_theta.shape[0]
    total = jax.ops.segment_sum(res.edge_cost, batch.edge_job, num_segments=n_jobs)
    per_edge = jnp.stack([getattr(res, k).astype(dtype) for k in EDGE_FIELDS], -1)
    bad = jax.ops.segment_sum(unresolved.astype(jnp.int32), batch.row_job, num_segments=n_jobs)
    return Scores(total, per_edge, res.assignment, loc, bad)


@functools.partial(jax.jit, static_argnames=("rows", "dtype", "edges_per_row", "exact"))
def score_packed(floats: jax.Array, ints: jax.Array, rows: int, dtype=jnp.float64, edges_per_row: int = 4,
                 exact: bool = True):
    """:func:`score_flat` of the batch packed by ``FIELDS[edges_per_row]`` at capacity ``rows``."""
    return score_flat.__wrapped__(unpack(floats, ints, rows, edges_per_row), dtype, exact=exact)
