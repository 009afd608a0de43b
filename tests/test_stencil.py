"""The padded stencil batches of the public kernel (otjax.stencil): the
vectorised packer against a row-by-row reference, and the buckets."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from otjax.stencil import Buckets, pack_edge_stencils
from tests.curves.helpers import make_engine


def loop_pack(stencils, shape, dtype=np.float64):
    """Reference packer: one row at a time, written independently of the vectorised one."""
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
    engine = make_engine(np.random.default_rng(3))
    plan = engine.plan
    cands = engine.candidates(np.nonzero(plan.tri.alive & ~plan.tri.pinned)[0][:3].tolist())[:5]
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
