"""Export and scoring of the curve engine: flat batches, the fused kernel.

Each piece is checked against an independent reference: the fused flat
kernel (in-kernel location) against host location and the padded kernel,
the reused packed buffers against fresh ones, a packed export against one
batch per source, a copied engine against the original.
"""

import copy
import functools
import logging
import pickle

import jax
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax import datasets, reconstruct_curve
from otjax.batch.fields import PackedBuffers
from otjax.curves import export as export_module
from otjax.curves import scorer as scorer_module
from otjax.curves import scoring
from otjax.curves.batches import batch_of_located, located_jobs
from otjax.curves.engine import CurveEngine
from otjax.curves.host_location import locate_on_host
from otjax.curves.triangulation import Triangulation
from tests.curves.helpers import assert_costs_match, free_vertices, make_engine, noisy_shape, padded_reference
from tests.point_sets import make_points

log = logging.getLogger(__name__)


def packed(batch, plan, r, layout):
    """``(floats, ints)`` of ``batch`` in fresh buffers of ``layout`` at capacity ``r``."""
    buf = PackedBuffers(layout.fields, r)
    buf.fill(batch.values(plan.points, plan.mass))
    return buf.floats, buf.ints


@pytest.mark.parametrize("seed", [2, 5])
def test_fused_kernel_equals_host_location_and_the_plain_kernel(seed):
    """Flat batches located in the kernel vs host-located padded stencils."""
    engine = make_engine(np.random.default_rng(seed))
    sources = free_vertices(engine)
    located = engine.candidates(sources)
    ref = padded_reference(engine, located)
    # Small budgets: many batches, candidates of one source split across them.
    cands, delta, costs = engine.score_batches(engine.exports(sources, budget=4096))
    assert [c.plan for c in cands] == [c.plan for c in located]
    assert all(c.cand is None for c in cands)  # nothing was located on the host
    for c, h, r in zip(cands, located, costs):
        np.testing.assert_array_equal(c.point_ids, h.point_ids)
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, ref)
    # The located path (score_candidates) agrees too.
    d2, costs2 = engine.score_candidates(located)
    np.testing.assert_array_equal(d2, delta)
    assert_costs_match(located, costs2, ref)


def test_retry_rounds_locate_what_one_round_cannot_take():
    """A retry round that takes one row at a time gives the same locations."""
    engine = make_engine(np.random.default_rng(6))
    plan = engine.plan
    sources = free_vertices(engine)
    flat = next(engine.exports(sources))
    layout = engine.scorer.layout
    r = flat.need(layout)
    batch = scoring.unpack(*packed(flat, plan, r, layout), r, layout.edges_per_row)
    wide = scoring.unpack(*packed(flat, plan, 2 * r, layout), 2 * r, layout.edges_per_row)
    with jax.enable_x64(True):
        want = jax.device_get(scoring.score_flat(batch))
        got = jax.device_get(scoring.score_flat(batch, retry_per_row=r))  # rounds of one row
        padded = jax.device_get(scoring.score_flat(wide))
    n = len(flat.row_point)
    # A batch scored in a larger compiled shape (what dispatch may reuse):
    # the same outputs on its jobs, edges and rows.
    for w, p_, size in zip(want, padded, (len(flat.row_start) - 1, len(flat.edge_job), n, n, len(flat.row_start) - 1)):
        np.testing.assert_array_equal(p_[:size], w[:size])
    loc, job = want[3][:n], flat.row_job
    assert np.all(loc[flat.row_locate] >= 0)  # every region point located, in the kernel
    # Points in ears failed their sector guess: with one row per round, they
    # took one round each.
    in_ear = flat.row_locate & (loc < flat.fan_tri[np.minimum(flat.job_fan[job], len(flat.fan_tri) - 1)])
    assert in_ear.sum() >= 2
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g, w)


def test_exact_rounds_of_one_row_locate_what_the_filter_cannot():
    """On a lattice the filter leaves rows unsure; the exact stage locates
    them all, the same in rounds of one row, and as the host does."""
    pts = make_points("grid", 64, 0)
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, np.ones(len(pts)))
    flat = next(engine.exports(free_vertices(engine)))
    layout = engine.scorer.layout
    r = flat.need(layout)
    batch = scoring.unpack(*packed(flat, engine.plan, r, layout), r, layout.edges_per_row)
    with jax.enable_x64(True):
        filtered = jax.device_get(scoring.score_flat(batch, exact=False))
        want = jax.device_get(scoring.score_flat(batch))
        got = jax.device_get(scoring.score_flat(batch, exact_per_row=r))
    n = len(flat.row_point)
    assert (filtered.located[:n][flat.row_locate] < 0).sum() >= 10  # the case under test occurs
    loc = want.located[:n]
    assert np.all(loc[flat.row_locate] >= 0)
    for w, g in zip(want, got):
        np.testing.assert_array_equal(g, w)
    locate_on_host(flat, np.arange(len(flat.row_start) - 1), engine.plan.points, engine.plan.point_rows)
    rows = np.flatnonzero(flat.row_tri >= 0)
    np.testing.assert_array_equal(loc[rows], flat.row_tri[rows] + flat.tri_start[flat.row_job[rows]])


def test_points_in_ears_beyond_the_retry_round_are_located_in_the_kernel(monkeypatch):
    """A noise-free star with every point a vertex: collapses flip out more
    ears than the retry round tests. The kernel locates their points (no
    host location), as the host does, and costs them as the padded kernel."""
    pts, _ = datasets.star(400, noise=0.0, seed=0)
    engine = CurveEngine(Triangulation(pts), pts, np.ones(len(pts)))
    sources = free_vertices(engine)[:120]
    located = engine.candidates(sources)
    on_host = []
    for module in (scorer_module, export_module):
        monkeypatch.setattr(module, "locate_on_host", lambda *a: on_host.append(a))
    cands, _delta, costs = engine.score_batches(engine.exports(sources))
    assert not on_host
    deep = 0
    for h, r in zip(located, costs):
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
        deep += int(np.sum(r.triangle[r.triangle < len(h.plan.flipped_out)] >= scoring.MAX_EARS))
    assert deep >= 1  # the case under test occurs
    assert_costs_match(cands, costs, padded_reference(engine, located))


@pytest.mark.parametrize("exact", [True, False])
def test_fused_kernel_on_collinear_data_locates_exactly(monkeypatch, exact):
    """Points exactly on edges: the kernel's filter is unsure. Its exact
    stage locates them in the kernel; without it, the host does. Either
    way, the host's locations and the padded kernel's costs."""
    monkeypatch.setattr(scorer_module, "EXACT_IN_KERNEL", exact)
    pts = make_points("grid", 64, 0)
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, np.ones(len(pts)))
    sources = free_vertices(engine)
    located = engine.candidates(sources)
    on_host = []
    monkeypatch.setattr(scorer_module, "locate_on_host", lambda batch, jobs, *a: on_host.append(len(jobs))
                        or locate_on_host(batch, jobs, *a))
    cands, _delta, costs = engine.score_batches(engine.exports(sources))
    assert (sum(on_host) == 0) == exact  # the host located rows only without the exact stage
    for h, r in zip(located, costs):
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, padded_reference(engine, located))


def _score_grid(sources_of):
    # Host location happens only where the kernel's exact stage is off.
    pts = make_points("grid", 64, 0)
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, np.ones(len(pts)))
    calls = engine.scorer.calls
    out = engine.score_batches(engine.exports(sources_of(engine), budget=1024))
    return engine, engine.scorer.calls - calls, out


def test_locating_on_the_host_first_changes_no_score(monkeypatch):
    """Exactly collinear input: once the kernel leaves rows unlocated, later
    batches are located on the host before their call (no second call), with
    the scores of a run that always lets the kernel locate."""
    def sources_of(engine):
        return free_vertices(engine)

    monkeypatch.setattr(scorer_module, "EXACT_IN_KERNEL", False)
    engine, calls, (cands, delta, costs) = _score_grid(sources_of)
    assert engine.scorer.host_first
    monkeypatch.setattr(scorer_module, "PROBE", 1)  # every batch a probe: the kernel locates them all
    _, calls_kernel, (cands_k, delta_k, costs_k) = _score_grid(sources_of)
    assert calls < calls_kernel  # fewer batches scored twice
    assert [c.plan for c in cands] == [c.plan for c in cands_k]
    np.testing.assert_array_equal(delta, delta_k)
    for got, want in zip(costs, costs_k):
        for name, value in want._asdict().items():
            np.testing.assert_array_equal(getattr(got, name), value, err_msg=name)


def test_host_first_turns_off_once_a_probe_batch_is_settled_by_the_kernel():
    """A probe batch whose rows the kernel all located turns host location off."""
    engine = make_engine(np.random.default_rng(3))  # noisy: the kernel's filter is sure
    engine.scorer.host_first = True
    sources = free_vertices(engine)
    engine.score_batches(engine.exports(sources, budget=1024))
    assert not engine.scorer.host_first


def test_located_jobs_are_the_batch_of_their_located_candidates():
    """located_jobs cuts jobs out of an exported batch: the batch (and the
    candidates) that batch_of_located makes of them, located."""
    pts = make_points("grid", 64, 1)
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, np.ones(len(pts)))
    batch = engine.export(free_vertices(engine))
    jobs = np.arange(1, len(batch.cands), 3)
    locate_on_host(batch, jobs, engine.plan.points, engine.plan.point_rows)
    got = located_jobs(batch, jobs)
    want = batch_of_located([batch.cands[j]._replace(
        cand=batch.row_cand[batch.row_start[j]:batch.row_start[j + 1]] - batch.edge_start[j],
        triangle_of_point=batch.row_tri[batch.row_start[j]:batch.row_start[j + 1]]) for j in jobs.tolist()])
    for name, value in vars(want).items():
        if isinstance(value, np.ndarray):
            assert getattr(got, name).dtype == value.dtype, name
            np.testing.assert_array_equal(getattr(got, name), value, err_msg=name)
    assert len(got.cands) == len(want.cands) == len(jobs)
    for c, w in zip(got.cands, want.cands):
        assert c.plan == w.plan and c.n_inside == w.n_inside and c.before == w.before
        for name in ("keys", "edges", "point_ids", "cand", "triangle_of_point"):
            np.testing.assert_array_equal(getattr(c, name), getattr(w, name), err_msg=name)


def test_relocation_batches_equal_located_relocations():
    engine = make_engine(np.random.default_rng(4))
    tri = engine.plan.tri
    rng = np.random.default_rng(0)
    vs = np.nonzero(tri.alive & ~tri.pinned)[0][:40]
    moves = [(int(v), tri.xy[v] + 1e-3 * rng.standard_normal(2)) for v in vs]
    located = engine.relocation_candidates(moves)
    assert located
    cands, _delta, costs = engine.score_batches(engine.relocation_exports(moves, budget=4096))
    for h, r in zip(located, costs):
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, padded_reference(engine, located))
    # A move's plan is a MovePlan: its source is its target, nothing flips.
    assert all(c.plan.source == c.plan.target == c.plan.vertex and c.plan.flipped_out == () for c in cands)


@settings(max_examples=100, deadline=None)
@given(rows=st.integers(0, 300_000), edges=st.integers(0, 80_000), tris=st.integers(0, 80_000),
       jobs=st.integers(0, 20_000), per=st.sampled_from([2, 4]))
def test_capacity_is_the_smallest_class_that_fits(rows, edges, tris, jobs, per):
    """Classes: powers of two from TINY_ROWS, and above THREE_QUARTER_FROM also
    three quarters of one; the capacity is the least class whose slots hold
    the batch (R rows, R/per edges and triangles, R/16 jobs, one kept)."""
    classes = sorted({scoring.TINY_ROWS << k for k in range(14)}
                     | {3 * (scoring.TINY_ROWS << k) // 4 for k in range(14)
                        if 3 * (scoring.TINY_ROWS << k) // 4 > scoring.THREE_QUARTER_FROM})
    fits = [c for c in classes if rows <= c and max(edges, tris) <= c // per and jobs + 1 <= c // 16]
    assert scoring.Layout(per, scoring.MIN_ROWS).capacity(rows, edges, tris, jobs) == fits[0]


def test_reused_buffers_hold_what_fresh_ones_would():
    """Batches of every size filled one after another into the same buffers:
    after each fill the buffers equal fresh ones holding that batch alone."""
    engine = make_engine(np.random.default_rng(4), n=400)
    plan = engine.plan
    sources = free_vertices(engine)
    rng = np.random.default_rng(0)
    flats = [next(engine.exports(sorted(rng.choice(sources, k, replace=False).tolist())))
             for k in (40, 1, 12, 3, 25, 1, 40)]
    flats.append(next(engine.relocation_exports([(v, plan.tri.xy[v] * (1 + 1e-9)) for v in sources[:5]])))
    layout = engine.scorer.layout
    r = max(f.need(layout) for f in flats)
    assert len({len(f.row_point) for f in flats}) >= 6  # they do differ in size
    reused = PackedBuffers(layout.fields, r)
    for flat in flats:
        reused.fill(flat.values(plan.points, plan.mass))
        want = packed(flat, plan, r, layout)
        np.testing.assert_array_equal(reused.floats, want[0])
        np.testing.assert_array_equal(reused.ints, want[1])
    # A fresh one holds zeros but for the padding values.
    fresh = PackedBuffers(layout.fields, r)
    assert fresh.floats.ctypes.data % 64 == 0 and fresh.ints.ctypes.data % 64 == 0
    with pytest.raises(ValueError, match="capacity"):
        PackedBuffers(layout.fields, r // 2).fill(
            next(engine.exports(sources, budget=1 << 20)).values(plan.points, plan.mass))


def scores_of_two_calls(engine, sources):
    _, first, _ = engine.score_batches(engine.exports(sources[:20]))
    _, second, _ = engine.score_batches(engine.exports(sources[20:]))
    return first, second


def assert_pool_in_use(engine, sources):
    """The engine's pool holds buffers (public behaviour: a call waited for
    hands its buffers to the next call of its shape), and scoring again from
    the pool gives the same scores."""
    scorer = engine.scorer
    batch = engine.export(sources[:20])
    h1 = scorer.dispatch(batch)
    d1, _ = scorer.collect(batch, h1)
    h2 = scorer.dispatch(batch)
    d2, _ = scorer.collect(batch, h2)
    assert h2.buffers is h1.buffers
    np.testing.assert_array_equal(d2, d1)
    return h1.buffers


def assert_buffers_are_their_own(buffers):
    """Each field view of a :class:`PackedBuffers` views its own buffers."""
    for name, view in buffers.views.items():
        assert np.shares_memory(view, buffers.floats) or np.shares_memory(view, buffers.ints), name
    assert buffers.floats.ctypes.data % 64 == 0 and buffers.ints.ctypes.data % 64 == 0


def test_a_deep_copied_engine_scores_like_the_original():
    """Copies of an engine whose buffer pool is in use get fresh buffers, not
    copies whose field views no longer alias them."""
    engine = make_engine(np.random.default_rng(8), n=400)
    sources = free_vertices(engine)
    first, second = scores_of_two_calls(engine, sources)
    pooled = assert_pool_in_use(engine, sources)  # buffers went back to the pool
    twin = copy.deepcopy(engine)
    _, got, _ = twin.score_batches(twin.exports(sources[:20]))
    np.testing.assert_array_equal(got, first)
    _, got, _ = twin.score_batches(twin.exports(sources[20:]))
    np.testing.assert_array_equal(got, second)
    assert_buffers_are_their_own(assert_pool_in_use(twin, sources))
    assert assert_pool_in_use(twin, sources) is not pooled


def test_a_pickled_engine_scores_like_the_original():
    """As for deepcopy: a pickled engine scores like the original."""
    engine = make_engine(np.random.default_rng(8), n=400)
    sources = free_vertices(engine)
    first, second = scores_of_two_calls(engine, sources)
    assert_pool_in_use(engine, sources)
    twin = pickle.loads(pickle.dumps(engine))
    _, got, _ = twin.score_batches(twin.exports(sources[:20]))
    np.testing.assert_array_equal(got, first)
    _, got, _ = twin.score_batches(twin.exports(sources[20:]))
    np.testing.assert_array_equal(got, second)
    assert_buffers_are_their_own(assert_pool_in_use(twin, sources))


def test_batches_fill_the_capacity_of_their_largest_candidate():
    """A candidate over the budget does not leave its batch mostly padding:
    later candidates join it up to its capacity; no batch outgrows the larger
    of the budget and its largest candidate's own capacity."""
    engine = make_engine(np.random.default_rng(3), n=30_000, subset=0.0015)
    sources = free_vertices(engine)
    budget = scoring.MIN_ROWS
    layout = engine.scorer.layout
    alone = {}
    for c in engine.candidates(sources):
        alone[c.plan.source, c.plan.target] = layout.capacity(
            len(c.point_ids), 2 * len(c.plan.new_triangles) + 1, len(c.plan.new_triangles), 1)
    assert max(alone.values()) > budget  # the case under test
    flats = list(engine.exports(sources, budget=budget))
    merged = 0
    for flat in flats:
        own = max(alone[c.plan.source, c.plan.target] for c in flat.cands)
        assert flat.need(layout) <= max(budget, own)
        merged += own > budget and len(flat.cands) > 1
    assert merged >= 1
    # Same candidates as one batch per source, each once; seq gives their
    # place in source then ring order.
    packed_plans = [c.plan for f in flats for c in f.cands]
    order = np.argsort(np.concatenate([f.seq for f in flats]))
    assert [packed_plans[i] for i in order] == [c.plan for v in sources for c in engine.export([v]).cands]
    # score_batches puts them back in that order, with their own scores.
    cands, delta, _ = engine.score_batches(engine.exports(sources, budget=budget))
    assert [c.plan for c in cands] == [packed_plans[i] for i in order]
    for v in sources[:10]:
        mine = [d for c, d in zip(cands, delta) if c.plan.source == v]
        np.testing.assert_array_equal(mine, engine.score_batches([engine.export([v])])[1])


def test_compiled_shapes_stay_few_over_2000_collapses():
    """2000 collapses, dirty candidates re-scored in one batch after each."""
    rng = np.random.default_rng(7)
    n = 2300
    pts = noisy_shape(rng, n)
    engine = CurveEngine(Triangulation(np.unique(pts, axis=0)), pts, np.ones(n))
    dirty = {int(v) for v in free_vertices(engine)[:64]}
    calls = engine.scorer.calls
    for _ in range(2000):
        cands, _delta, rows = engine.score_batches(engine.exports(sorted(dirty)))  # every half-edge out of them
        pick = int(rng.integers(len(cands)))
        dirty = engine.apply(cands[pick], rows[pick]).dirty
    shapes = engine.scorer.pipeline.shapes_seen
    log.info("compiled shapes: %s", sorted(shapes))
    print("distinct compiled shapes:", len(shapes), sorted(shapes))
    assert len(shapes) <= 12
    assert engine.scorer.calls >= calls + 2000  # one call at least per scoring
    assert engine.compiled_shapes in (len(shapes), len(shapes) + 1)  # + the location kernel, if used


def test_small_inputs_fill_calls_to_the_smaller_shape_and_score_the_same(monkeypatch):
    """Up to SMALL_INPUT_POINTS points, calls are filled to MIN_ROWS rows
    (more calls than at ROW_BUDGET); from at most two points a vertex they
    hold R/2 edges, not R/4. The reconstruction is the same bit for bit."""
    most = scoring.SMALL_INPUT_POINTS
    cases = [(10, 10), (most, most // 2), (most, most // 2 - 1), (most + 1, most + 1), (most + 1, 2000)]
    assert [tuple(scoring.layout_for(n, v)) for n, v in cases] == [
        (2, scoring.MIN_ROWS), (2, scoring.MIN_ROWS), (4, scoring.MIN_ROWS), (2, scoring.ROW_BUDGET),
        (4, scoring.ROW_BUDGET)]
    pts, _ = datasets.star(900, noise=0.01, seed=3)
    run = functools.partial(reconstruct_curve, pts, n_vertices=10, seed=1, initial_vertices=900)  # one point a vertex
    small = run()
    monkeypatch.setattr(scoring, "DENSE_VERTICES", 0)
    quarter = run()
    monkeypatch.setattr(scoring, "SMALL_INPUT_POINTS", 0)
    large = run()
    # The layouts did differ: fewer calls with more edges per call, fewer with a larger budget.
    assert quarter.history["kernel_calls"] > small.history["kernel_calls"]
    assert quarter.history["kernel_calls"] > large.history["kernel_calls"]
    for other in (quarter, large):
        np.testing.assert_array_equal(small.vertices, other.vertices)
        np.testing.assert_array_equal(small.edges, other.edges)
        assert small.total_cost == other.total_cost
