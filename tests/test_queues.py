"""The machinery of issue 4: filtered location, batching, sampling, queues.

Each piece is checked against an independent reference: the filtered JAX
location against the exact host predicate, the packed kernel against the
plain one, the fused flat kernel (in-kernel location) against host location
and the padded kernel, the vectorised packing against the reference packer, the sampler
against the uniform law (chi-square), a parallel round against the sum of its
deltas and a from-scratch recomputation.
"""

import importlib
from collections import Counter

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy import stats

import otjax
from otjax.curves import cost
from otjax.curves.decimate import IndependentSet, _LiveVertices, _lock_set, _sample_half_edges, decimate
from otjax.curves.location import CHUNK, locate_pairs
from otjax.curves.plan import TransportPlan
from otjax.curves.predicates import in_triangle_perturbed
from otjax.curves.reconstruct import vertex_and_edge_masses
from otjax.curves.triangulation import Triangulation
from otjax.stencil import Buckets, pack_edge_stencils
from tests.point_sets import make_points
from tests.test_plan import make_plan, noisy_shape, scratch_cost


def rows(tri: np.ndarray, p: np.ndarray):
    """``(N, 3, 2)``, ``(N, 2)`` -> the planar layout of :func:`locate_pairs`."""
    return np.ascontiguousarray(tri.reshape(-1, 6).T), np.ascontiguousarray(p.T)


def all_pairs(tri: Triangulation, queries: np.ndarray):
    t = tri.xy[tri.triangles()]
    i, j = np.meshgrid(np.arange(len(queries)), np.arange(len(t)), indexing="ij")
    return t[j.ravel()], queries[i.ravel()]


# ------------------------------------------------------------------ location
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(kind=st.sampled_from(["uniform", "near_collinear", "clustered", "duplicates", "grid"]),
       n=st.integers(8, 60), seed=st.integers(0, 10_000))
def test_filtered_location_equals_the_exact_predicate(kind, n, seed):
    rng = np.random.default_rng(seed)
    pts = make_points(kind, n, seed)
    tri = Triangulation(np.unique(pts, axis=0))
    # Queries on vertices, on edge midpoints (often inexact), at random.
    t = tri.triangles()
    mid = (tri.xy[t[:, 0]] + tri.xy[t[:, 1]]) / 2
    inner = tri.xy[tri.alive & ~tri.pinned]
    span = float(np.ptp(inner, axis=0).max()) or 1.0  # the box is relative to the data
    queries = np.concatenate([inner, mid, pts + 1e-3 * span * rng.standard_normal(pts.shape)])
    a, p = all_pairs(tri, queries)
    want = in_triangle_perturbed(a, p)
    got = locate_pairs(*rows(a, p))
    np.testing.assert_array_equal(got, want)
    # Each query is in exactly one triangle.
    assert np.all(got.reshape(len(queries), -1).sum(1) == 1)


def test_filtered_location_over_chunk_boundaries():
    rng = np.random.default_rng(1)
    n = 5 * CHUNK + 12_345  # several chunks, the last one padded
    a = rng.random((n, 3, 2))
    u, v = a[:, 1] - a[:, 0], a[:, 2] - a[:, 0]
    flip = u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0] < 0
    a[flip] = a[flip][:, [0, 2, 1]]
    p = rng.random((n, 2))
    p[::7] = a[::7, 1]  # exactly on a corner: the perturbation decides
    np.testing.assert_array_equal(locate_pairs(*rows(a, p)), in_triangle_perturbed(a, p))


# ------------------------------------------------------------------ batching
def padded_reference(plan, cands):
    """Scores host-located candidates with the plain padded kernel, one row each."""
    import jax

    stencils = [(c.edges, plan.points[c.point_ids], plan.mass[c.point_ids], c.cand) for c in cands]
    batch = pack_edge_stencils(stencils, Buckets(max_batch=1 << max(len(cands) - 1, 0).bit_length(),
                                                 point_budget=2**62))
    with jax.enable_x64(True):
        return jax.device_get(cost.batched_stencil_cost(batch))


def assert_costs_match(cands, costs, ref):
    for i, (c, r) in enumerate(zip(cands, costs)):
        e, n = len(c.keys), len(c.point_ids)
        np.testing.assert_array_equal(r.assignment, ref.assignment[i, :n])
        np.testing.assert_array_equal(r.solid, ref.solid[i, :e])
        for name in ("edge_cost", "normal", "tangential", "vertex", "edge_mass"):
            np.testing.assert_allclose(getattr(r, name), getattr(ref, name)[i, :e], rtol=1e-12, atol=1e-15,
                                       err_msg=name)
        np.testing.assert_allclose(r.delta, ref.total[i] - c.before, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("seed", [2, 5])
def test_fused_kernel_equals_host_location_and_the_plain_kernel(seed):
    """Flat batches located in the kernel vs host-located padded stencils."""
    plan = make_plan(np.random.default_rng(seed))
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    located = plan.candidates(sources)
    ref = padded_reference(plan, located)
    # Small budgets: many batches, candidates of one source split across them.
    cands, delta, costs = plan.score_batches(plan.exports(sources, budget=4096))
    assert [c.plan for c in cands] == [c.plan for c in located]
    assert all(c.cand is None for c in cands)  # nothing was located on the host
    for c, h, r in zip(cands, located, costs):
        np.testing.assert_array_equal(c.point_ids, h.point_ids)
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, ref)
    # The located path (score) agrees too.
    d2, costs2 = plan.score(located)
    np.testing.assert_array_equal(d2, delta)
    assert_costs_match(located, costs2, ref)


def test_retry_rounds_locate_what_one_round_cannot_take():
    """A retry round that takes one row at a time gives the same locations."""
    import jax

    from otjax.curves import scoring

    plan = make_plan(np.random.default_rng(6))
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    flat = next(plan.exports(sources))
    r = flat.capacity()
    batch = scoring.unpack(*flat.packed(plan.points, plan.mass, r), r)
    wide = scoring.unpack(*flat.packed(plan.points, plan.mass, 2 * r), 2 * r)
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


def test_fused_kernel_on_collinear_data_falls_back_exactly():
    """Points exactly on edges: the kernel's filter is unsure, the host decides."""
    pts = make_points("grid", 64, 0)
    plan = TransportPlan(Triangulation(np.unique(pts, axis=0)), pts, np.ones(len(pts)))
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    located = plan.candidates(sources)
    cands, _delta, costs = plan.score_batches(plan.exports(sources))
    for h, r in zip(located, costs):
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, padded_reference(plan, located))


def test_relocation_batches_equal_located_relocations():
    plan = make_plan(np.random.default_rng(4))
    rng = np.random.default_rng(0)
    vs = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0][:40]
    moves = [(int(v), plan.tri.xy[v] + 1e-3 * rng.standard_normal(2)) for v in vs]
    located = plan.relocation_candidates(moves)
    assert located
    cands, _delta, costs = plan.score_batches(plan.relocation_exports(moves, budget=4096))
    for h, r in zip(located, costs):
        np.testing.assert_array_equal(r.triangle, h.triangle_of_point[:h.n_inside])
    assert_costs_match(cands, costs, padded_reference(plan, located))


@settings(max_examples=60, deadline=None)
@given(data=st.data())
def test_sort_order_equals_lexsort_with_near_ties(data):
    """The quantised one-sort path (with its exact fallback) vs np.lexsort."""
    import jax

    n = data.draw(st.integers(2, 300))
    rng = np.random.default_rng(data.draw(st.integers(0, 2**31)))
    edge = rng.integers(0, data.draw(st.integers(1, 8)), n).astype(np.int32)
    base = rng.choice([-1.0, 0.0, 0.3, 1e-300, 2.5], n) if data.draw(st.booleans()) else rng.random(n)
    # Neighbouring floats: far below any quantisation step.
    t = base + np.where(rng.random(n) < 0.5, 0.0, np.spacing(base) * rng.integers(-3, 4, n))
    t[rng.random(n) < 0.1] = -0.0
    with jax.enable_x64(True):
        got = np.asarray(jax.jit(cost.sort_order, static_argnums=2)(edge, t, 8))
    np.testing.assert_array_equal(got, np.lexsort((np.arange(n), np.where(t == 0, 0.0, t), edge)))


def loop_pack(stencils, shape, dtype=np.float64):
    """Reference packer: one row at a time (the pre-issue-4 implementation)."""
    b_cap, e_cap, p_cap = shape
    edges = np.zeros((b_cap, e_cap, 2, 2), dtype)
    edge_mask = np.zeros((b_cap, e_cap), bool)
    points = np.zeros((b_cap, p_cap, 2), dtype)
    mass = np.zeros((b_cap, p_cap), dtype)
    point_mask = np.zeros((b_cap, p_cap), bool)
    cand = np.zeros((b_cap, p_cap, 3), np.int32)
    for i, (e, p, m, c) in enumerate(stencils):
        edges[i, :len(e)] = e
        edge_mask[i, :len(e)] = True
        points[i, :len(p)] = p
        mass[i, :len(p)] = m
        point_mask[i, :len(p)] = True
        cand[i, :len(p)] = c
    return edges, edge_mask, points, mass, point_mask, cand


def test_vectorised_packing_equals_a_row_by_row_reference():
    plan = make_plan(np.random.default_rng(3))
    cands = plan.candidates(np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0][:3].tolist())[:5]
    stencils = [(c.edges, plan.points[c.point_ids], plan.mass[c.point_ids], c.cand) for c in cands]
    got = pack_edge_stencils(stencils, Buckets(), np.float64)
    want = loop_pack(stencils, got.shape)
    for name, w in zip(got._fields, want):
        np.testing.assert_array_equal(getattr(got, name), w, err_msg=name)


@given(st.lists(st.integers(1, 40_000), min_size=1, max_size=200))
def test_batches_cover_every_stencil_once_and_fit(sizes):
    buckets = Buckets()
    batches = buckets.batches(sizes)
    flat = np.concatenate(batches)
    assert sorted(flat.tolist()) == list(range(len(sizes)))
    for b in batches:
        cap = buckets.point_capacity(max(sizes[i] for i in b))
        assert len(b) <= buckets.batch_capacity(cap)
        assert all(sizes[i] <= cap for i in b)


def test_point_capacity_follows_the_batch_not_history():
    buckets = Buckets(min_points=32)
    assert buckets.fit(1, 3, 5000)[2] == 8192
    assert buckets.fit(8, 3, 40)[2] == 64  # a large batch earlier does not pad later ones
    assert buckets.batch_capacity(8192) * 8192 <= max(buckets.point_budget, 8192)


@settings(max_examples=40, deadline=None)
@given(rows=st.integers(0, 300_000), edges=st.integers(0, 80_000), tris=st.integers(0, 80_000),
       jobs=st.integers(0, 20_000))
def test_capacity_is_the_smallest_class_that_fits(rows, edges, tris, jobs):
    """Classes: powers of two from MIN_ROWS, and above THREE_QUARTER_FROM also
    three quarters of one; the capacity is the least class whose slots hold
    the batch (R rows, R/4 edges and triangles, R/16 jobs, one kept)."""
    from otjax.curves import scoring

    classes = sorted({scoring.MIN_ROWS << k for k in range(12)}
                     | {3 * (scoring.MIN_ROWS << k) // 4 for k in range(12)
                        if 3 * (scoring.MIN_ROWS << k) // 4 > scoring.THREE_QUARTER_FROM})
    fits = [c for c in classes if rows <= c and max(edges, tris) <= c // 4 and jobs + 1 <= c // 16]
    assert scoring.capacity(rows, edges, tris, jobs) == fits[0]


def test_reused_buffers_hold_what_fresh_ones_would():
    """Batches of every size filled one after another into the same buffers:
    after each fill the buffers equal fresh ones holding that batch alone."""
    from otjax.curves.plan import PackedBuffers

    plan = make_plan(np.random.default_rng(4), n=400)
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    rng = np.random.default_rng(0)
    flats = [next(plan.exports(sorted(rng.choice(sources, k, replace=False).tolist())))
             for k in (40, 1, 12, 3, 25, 1, 40)]
    flats.append(next(plan.relocation_exports([(v, plan.tri.xy[v] * (1 + 1e-9)) for v in sources[:5]])))
    r = max(f.capacity() for f in flats)
    assert len({len(f.row_point) for f in flats}) >= 6  # they do differ in size
    reused = PackedBuffers(r)
    for flat in flats:
        got = flat.packed(plan.points, plan.mass, r, out=reused)
        want = flat.packed(plan.points, plan.mass, r)
        np.testing.assert_array_equal(got[0], want[0])
        np.testing.assert_array_equal(got[1], want[1])
    # A fresh one holds zeros but for the padding values.
    fresh = PackedBuffers(r)
    assert fresh.floats.ctypes.data % 64 == 0 and fresh.ints.ctypes.data % 64 == 0
    with pytest.raises(ValueError, match="capacity"):
        next(plan.exports(sources, budget=1 << 20)).packed(plan.points, plan.mass, r // 2, out=PackedBuffers(r // 2))


def test_a_copied_plan_scores_like_the_original():
    """Copies (deepcopy, pickle) of a plan whose buffer pool is in use get
    fresh buffers, not copies whose field views no longer alias them."""
    import copy
    import pickle

    plan = make_plan(np.random.default_rng(8), n=400)
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    _, first, _ = plan.score_batches(plan.exports(sources[:20]))
    _, second, _ = plan.score_batches(plan.exports(sources[20:]))
    assert plan._buffers  # buffers went back to the pool, holding the second call's batch
    for twin in (copy.deepcopy(plan), pickle.loads(pickle.dumps(plan))):
        _, got, _ = twin.score_batches(twin.exports(sources[:20]))
        np.testing.assert_array_equal(got, first)
        _, got, _ = twin.score_batches(twin.exports(sources[20:]))
        np.testing.assert_array_equal(got, second)


def test_batches_fill_the_capacity_of_their_largest_candidate():
    """A candidate over the budget does not leave its batch mostly padding:
    later candidates join it up to its capacity; no batch outgrows the larger
    of the budget and its largest candidate's own capacity."""
    from otjax.curves import scoring

    plan = make_plan(np.random.default_rng(3), n=30_000, subset=0.0015)
    sources = np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist()
    budget = scoring.MIN_ROWS
    alone = {}
    for c in plan.candidates(sources):
        alone[c.plan.source, c.plan.target] = scoring.capacity(len(c.point_ids), 2 * len(c.plan.new_triangles) + 1,
                                                              len(c.plan.new_triangles), 1)
    assert max(alone.values()) > budget  # the case under test
    flats = list(plan.exports(sources, budget=budget))
    merged = 0
    for flat in flats:
        own = max(alone[c.plan.source, c.plan.target] for c in flat.cands)
        assert flat.capacity() <= max(budget, own)
        merged += own > budget and len(flat.cands) > 1
    assert merged >= 1
    # Same candidates as one batch per source, each once; seq gives their
    # place in source then ring order.
    packed = [c.plan for f in flats for c in f.cands]
    order = np.argsort(np.concatenate([f.seq for f in flats]))
    assert [packed[i] for i in order] == [c.plan for v in sources for c in plan.export([v]).cands]
    # score_batches puts them back in that order, with their own scores.
    cands, delta, _ = plan.score_batches(plan.exports(sources, budget=budget))
    assert [c.plan for c in cands] == [packed[i] for i in order]
    for v in sources[:10]:
        mine = [d for c, d in zip(cands, delta) if c.plan.source == v]
        np.testing.assert_array_equal(mine, plan.score_batches([plan.export([v])])[1])


@settings(max_examples=80, deadline=None)
@given(sizes=st.lists(st.tuples(st.integers(0, 3000), st.integers(1, 60)), min_size=0, max_size=400),
       budget=st.sampled_from([4096, 1 << 15]))
def test_next_fit_packing_keeps_order_within_limits(sizes, budget):
    """Consecutive runs of the jobs, in order; each within the larger of the
    budget and its largest job's capacity; each closed only when the next
    job would not fit it."""
    from otjax.curves import scoring
    from otjax.curves.plan import pack_next_fit

    jobs = [(r, 2 * t + 1, t) for r, t in sizes]
    batches = pack_next_fit(jobs, budget)
    assert [i for b in batches for i in b] == list(range(len(jobs)))
    assert all(b for b in batches)

    def fits(b):
        total = [sum(jobs[i][k] for i in b) for k in range(3)]
        limit = max(budget, max(scoring.capacity(*jobs[i], 1) for i in b))
        return scoring.capacity(*total, len(b)) <= limit

    for b, nxt in zip(batches, batches[1:]):
        assert fits(b) and not fits(b + nxt[:1])
    assert not batches or fits(batches[-1])


@settings(max_examples=80, deadline=None)
@given(sizes=st.lists(st.tuples(st.integers(1, 70_000), st.integers(1, 60)), min_size=0, max_size=120),
       budget=st.sampled_from([4096, 8192, 1 << 15]))
def test_first_fit_packing_is_a_partition_within_limits(sizes, budget):
    """Every job in one batch; a batch within the larger of the budget and
    its largest job's own capacity; and first fit: no job of a later batch
    would have fitted an earlier one (batches only grow, so it did not fit
    then either)."""
    from otjax.curves import scoring
    from otjax.curves.plan import pack_first_fit

    jobs = [(r, 2 * t + 1, t) for r, t in sizes]
    batches = pack_first_fit(jobs, budget)
    assert sorted(i for b in batches for i in b) == list(range(len(jobs)))
    assert all(b == sorted(b) for b in batches)

    def total(b):
        return [sum(jobs[i][k] for i in b) for k in range(3)] + [len(b)]

    limits = [max(budget, max(scoring.capacity(*jobs[i], 1) for i in b)) for b in batches]
    for b, limit in zip(batches, limits):
        assert scoring.capacity(*total(b)) <= limit
    for j, later in enumerate(batches):
        for i in range(j):
            rows, edges, tris, n = total(batches[i])
            for x in later:
                r, e, t = jobs[x]
                assert scoring.capacity(rows + r, edges + e, tris + t, n + 1) > limits[i]


# ------------------------------------------------------------------ sampling
def eligible_half_edges(plan):
    tri = plan.tri
    out = []
    for u in np.nonzero(tri.alive & ~tri.pinned)[0]:
        ring = tri.star(int(u))[0]
        if len(ring) <= plan.max_source_degree:
            out += [(int(u), w) for w in ring if not tri.pinned[w]]
    return out


def test_sampled_half_edges_are_uniform_and_eligible():
    rng = np.random.default_rng(4)
    pts = rng.random((25, 2))
    plan = TransportPlan(Triangulation(pts), pts, np.ones(len(pts)))
    everything = eligible_half_edges(plan)
    live = _LiveVertices(plan.tri)
    counts = Counter()
    for _ in range(3000):
        got = _sample_half_edges(plan, live, rng, 3)
        assert len(set(got)) == len(got) == 3
        assert set(got) <= set(everything)
        counts.update(got[:1])  # the first draw of each sample is one uniform draw
    observed = np.array([counts[h] for h in everything])
    assert stats.chisquare(observed).pvalue > 1e-3, "first draws are not uniform over half-edges"


# ------------------------------------------------------------------ queues
def independent_round(plan):
    """The parallel queue's selection rule, applied to every candidate."""
    cands = plan.candidates(np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0].tolist())
    delta, rows_ = plan.score(cands)
    chosen, independent = [], IndependentSet()
    for i in np.argsort(delta, kind="stable"):
        lock = _lock_set(plan, cands[i].plan.source)
        if independent.admits(lock):
            chosen.append(i)
            independent.add(lock)
    return cands, delta, rows_, chosen


@pytest.mark.parametrize("seed", [5, 6, 7])
def test_an_independent_round_changes_the_cost_by_the_sum_of_its_deltas(seed):
    plan = make_plan(np.random.default_rng(seed), n=200)
    before = plan.total_cost()
    cands, delta, rows_, chosen = independent_round(plan)
    assert len(chosen) >= 5
    for i in chosen:
        plan.apply(cands[i], rows_[i])
    plan.tri.check()
    after = plan.total_cost()
    assert after - before == pytest.approx(delta[chosen].sum(), rel=1e-9, abs=1e-12)
    assert after == pytest.approx(scratch_cost(plan.tri, plan.points, plan.mass), rel=1e-9, abs=1e-15)


@pytest.mark.parametrize("queue", ["multiple-choice", "parallel"])
def test_queues_keep_the_embedding_and_an_exact_plan(queue):
    rng = np.random.default_rng(8)
    pts = noisy_shape(rng, 600)
    mass = rng.uniform(0.5, 2.0, len(pts))
    keep = np.sort(rng.choice(len(pts), 300, replace=False))  # a random subset as vertices
    plan = TransportPlan(Triangulation(pts[keep]), pts, mass)
    stats_ = decimate(plan, 12, queue=queue, relocation=20, seed=1)
    plan.tri.check()
    assert int((plan.tri.alive & ~plan.tri.pinned).sum()) == 12
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, pts, mass), rel=1e-9)
    if queue == "parallel":
        assert stats_.rounds < stats_.collapses
    else:
        assert stats_.switched_at == 60  # 5 x the target
    # Every point is located in a live triangle that holds it.
    faces = plan.pt_face
    assert all(plan.tri.tri[f] is not None for f in np.unique(faces))


# ------------------------------------------------------------- link updates
# The stencils of these small cases are below the size that makes an update
# worth it; the property under test holds for any threshold.
decimate_module = importlib.import_module("otjax.curves.decimate")


@pytest.fixture
def update_everything(monkeypatch):
    monkeypatch.setattr(decimate_module, "UPDATE_MIN_ROWS", 0)


def run_queue(plan, queue, incremental, target=8, relocation=15):
    """``decimate``, recording each collapse and relocation in order."""
    applied = []
    apply = plan.apply

    def recording(cand, scored):
        applied.append((cand.plan.source, cand.plan.target, None if cand.moved is None else tuple(cand.moved)))
        return apply(cand, scored)

    plan.apply = recording
    stats_ = decimate(plan, target, queue=queue, relocation=relocation, seed=2, incremental=incremental)
    return applied, stats_


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(queue=st.sampled_from(["exhaustive", "parallel"]), n=st.integers(60, 220), seed=st.integers(0, 10_000),
       subset=st.sampled_from([0.5, 1.0]))
def test_link_updates_make_the_same_greedy_as_full_rescoring(queue, n, seed, subset):
    # (hypothesis reuses the fixture's state across examples; patched here)
    decimate_module.UPDATE_MIN_ROWS, saved = 0, decimate_module.UPDATE_MIN_ROWS
    try:
        check_same_greedy(queue, n, seed, subset)
    finally:
        decimate_module.UPDATE_MIN_ROWS = saved


def check_same_greedy(queue, n, seed, subset):
    def plan():
        rng = np.random.default_rng(seed)
        pts = noisy_shape(rng, n)
        mass = rng.uniform(0.2, 2.0, n)
        keep = rng.random(n) < subset
        return TransportPlan(Triangulation(np.unique(pts[keep], axis=0) if subset < 1 else pts), pts, mass)

    full, full_stats = run_queue(plan(), queue, incremental=False)
    updated, stats_ = run_queue(plan(), queue, incremental=True)
    # The same changes in the same order: every score, exact ties included,
    # is the same as a full re-scoring's.
    assert updated == full
    assert full_stats.updated == 0 < stats_.updated
    assert full_stats.partial == 0 < stats_.partial
    assert stats_.scored < full_stats.scored


@pytest.mark.parametrize("seed", [12, 13])
def test_each_link_update_equals_a_full_scoring(seed, monkeypatch, update_everything):
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, 500)
    mass = rng.uniform(0.5, 2.0, len(pts))
    plan = TransportPlan(Triangulation(pts[::2]), pts, mass)
    checked = []
    link_updates = TransportPlan.link_updates

    def checking(self, items, budget=None):
        out = link_updates(self, items) if budget is None else link_updates(self, items, budget)
        for (rec, changed), (new, delta) in zip(items, out):
            v, w = rec.plan.source, rec.plan.target
            # The star kept its triangles; what changed lies on its link.
            ring = self.tri.star(v)[0]
            link = {tuple(sorted((ring[k], ring[(k + 1) % len(ring)]))) for k in range(len(ring))}
            assert changed and changed <= link
            cands = self.candidates([v], {v: [w]})  # located on the host: another path
            _, (cost,) = self.score(cands)
            np.testing.assert_array_equal(new.keys, cands[0].keys)
            np.testing.assert_allclose(new.edge_cost, cost.edge_cost, rtol=1e-12, atol=1e-15)
            assert delta == pytest.approx(cost.delta, rel=1e-12, abs=1e-14)
            checked.append(delta)
        return out

    monkeypatch.setattr(TransportPlan, "link_updates", checking)
    stats_ = decimate(plan, 10, queue="exhaustive", relocation=20)
    assert stats_.updated == len(checked) > 100
    plan.tri.check()
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, pts, mass), rel=1e-9)


@pytest.mark.parametrize("seed", [12, 16])
def test_each_partial_update_equals_a_full_scoring(seed, monkeypatch, update_everything):
    """After a ring vertex moved, the collapse re-scored on the part the move
    reaches has the full kernel scoring's edge costs bit for bit, and its
    record the full scoring's triangle and edge of every point."""
    rng = np.random.default_rng(seed)
    pts = noisy_shape(rng, 500)
    mass = rng.uniform(0.5, 2.0, len(pts))
    plan = TransportPlan(Triangulation(pts[::2]), pts, mass)
    checked, smaller = [], []
    finish = TransportPlan.finish_partial

    def checking(self, pending, cand, scored):
        rec, delta = finish(self, pending, cand, scored)
        v, w = rec.plan.source, rec.plan.target
        rows = len(rec.inside) + len(self._region(v)[3])
        assert len(cand.point_ids) <= rows
        smaller.append(len(cand.point_ids) < rows)
        _, full_delta, (cost,) = self.score_batches(self.exports([v], {v: [w]}))
        np.testing.assert_array_equal(rec.edge_cost, cost.edge_cost)
        n = len(rec.inside)
        np.testing.assert_array_equal(rec.triangle, cost.triangle[:n])
        np.testing.assert_array_equal(rec.edge, cost.assignment[:n])
        assert delta == pytest.approx(full_delta[0], rel=1e-12, abs=1e-14)
        checked.append(delta)
        return rec, delta

    monkeypatch.setattr(TransportPlan, "finish_partial", checking)
    stats_ = decimate(plan, 10, queue="exhaustive", relocation=40)
    assert stats_.partial == len(checked) > 50
    assert sum(smaller) > len(smaller) / 2  # most are a part of the stencil only
    plan.tri.check()
    assert plan.total_cost() == pytest.approx(scratch_cost(plan.tri, pts, mass), rel=1e-9)


def test_changed_links_reports_star_changes_as_none():
    rng = np.random.default_rng(14)
    plan = make_plan(rng, n=200)
    tri = plan.tri
    version = list(plan._region_version)
    stars = {v: tri.star(v) for v in range(len(tri.xy)) if tri.alive[v] and not tri.pinned[v]}
    s, t = next((s, t) for s, t in tri.half_edges() if plan.candidate(s, t) is not None)
    cand = plan.candidate(s, t)
    _, (cost,) = plan.score([cand])
    dirty = plan.apply(cand, cost)
    for v in dirty:
        changed = plan.changed_links(v, version[v])
        if v in cand.plan.ring:
            assert changed is None
        else:
            assert tri.star(v) == stars[v]  # same ring, same faces
            ring = stars[v][0]
            link = {tuple(sorted((ring[k], ring[(k + 1) % len(ring)]))) for k in range(len(ring))}
            assert changed and changed <= link
            assert plan.changed_links(v, plan._region_version[v]) == set()
    for v in set(stars) - dirty - {s}:
        assert tri.star(v) == stars[v]


def test_prefetching_the_next_draw_changes_nothing_but_the_caches(monkeypatch):
    def run():
        rng = np.random.default_rng(15)
        pts = noisy_shape(rng, 500)
        plan = TransportPlan(Triangulation(pts[::2]), pts, np.ones(len(pts)))
        return run_queue(plan, "multiple-choice", incremental=True, target=10, relocation=10)

    prefetched = []
    prefetch = TransportPlan.prefetch

    def counting(self, half_edges):
        prefetched.extend(half_edges)
        prefetch(self, half_edges)

    monkeypatch.setattr(TransportPlan, "prefetch", counting)
    with_prefetch, stats_ = run()
    monkeypatch.setattr(TransportPlan, "prefetch", lambda self, half_edges: None)
    without, _ = run()
    assert with_prefetch == without
    assert len(prefetched) > 5 * stats_.switched_at  # it did read ahead, most steps


def test_multiple_choice_scores_far_fewer_candidates():
    pts, _ = otjax.datasets.star(1500, noise=0.01, seed=9)
    mc = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", relocation=0)
    ex = otjax.reconstruct_curve(pts, n_vertices=10, queue="exhaustive", relocation=0)
    assert mc.history["switched_at"] == 50
    # A step scores at most `choices` half-edges until the switch. Updates
    # on changed link edges (exhaustive loop) count as evaluations too.
    def evaluated(r):
        return r.history["scored"] + r.history["updated"]

    assert evaluated(mc) < evaluated(ex) / 3


def test_same_seed_same_multiple_choice_result_and_seed_matters():
    pts, _ = otjax.datasets.star(800, noise=0.01, seed=10)
    a = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=400, seed=3)
    b = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=400, seed=3)
    c = otjax.reconstruct_curve(pts, n_vertices=10, queue="multiple-choice", initial_vertices=400, seed=4)
    np.testing.assert_array_equal(a.vertices, b.vertices)
    np.testing.assert_array_equal(a.edges, b.edges)
    assert a.total_cost == b.total_cost
    assert not np.array_equal(a.vertices, c.vertices)  # another subset, other draws


def test_subset_initialisation_transports_every_point():
    rng = np.random.default_rng(11)
    pts, _ = otjax.datasets.star(1200, noise=0.01, seed=11)
    mass = rng.uniform(0.5, 1.5, len(pts))
    keep = np.sort(rng.choice(len(pts), 300, replace=False))
    plan = TransportPlan(Triangulation(pts[keep]), pts, mass)
    decimate(plan, 10, queue="multiple-choice", seed=0)
    edge_mass, vertex_mass = vertex_and_edge_masses(plan)
    # Every point is sent somewhere: to a solid edge or to a vertex.
    assert sum(edge_mass.values()) + sum(vertex_mass.values()) == pytest.approx(mass.sum(), rel=1e-12)
    r = otjax.reconstruct_curve(pts, mass, n_vertices=10, initial_vertices=300, relocation=0,
                                final_relocations=0)
    assert r.params["initial_vertices"] == 300
    assert r.history["collapses"] == 300 - 10


@pytest.mark.parametrize("bad, message", [
    ({"queue": "random"}, "queue"),
    ({"choices": 0}, "choices"),
    ({"initial_vertices": 5}, "initial_vertices"),
    ({"initial_vertices": 2.5}, "initial_vertices"),
])
def test_bad_queue_parameters_are_named(bad, message):
    pts, _ = otjax.datasets.star(200, noise=0.01)
    with pytest.raises(ValueError, match=message):
        otjax.reconstruct_curve(pts, n_vertices=10, **bad)
