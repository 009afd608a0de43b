"""Packing members into capacity classes, slicing them back, and input checks."""

import numpy as np
import pytest

from otjax.lp.problem import LocalLP, capacity_class, check_local, group_by_class, member, pack
from tests.lp.stencils import random_stencil


def test_pack_then_member_gives_the_member_back(rng):
    members = [random_stencil(rng, p, k, 2, 1) for p, k in ((5, 4), (30, 17), (9, 40))]
    batch = pack(members)
    assert batch.shape == (4, 32, 64, 4)
    assert not batch.point_mask[3].any() and not batch.bin_mask[3].any() and np.all(batch.mass[3] == 0)
    assert pack(members, batch=3).shape[0] == 3
    for b, lp in enumerate(members):
        back = member(batch, b)
        for got, want in zip(back, lp):
            np.testing.assert_array_equal(got, want)
        p, k = lp.cost.shape
        assert batch.point_mask[b].sum() == p and batch.bin_mask[b].sum() == k
        assert np.all(batch.mass[b, p:] == 0) and np.all(batch.cost[b, :, k:] == 0)
        assert np.all(batch.capacity[b, k:] == 0) and not batch.is_vertex[b, k:].any()
        assert batch.simplex_mask[b].tolist() == [True, True, True, False]


def test_capacity_classes_are_powers_of_two_and_group_members(rng):
    assert [capacity_class(n, 8) for n in (0, 1, 8, 9, 100, 128, 129)] == [8, 8, 8, 16, 128, 128, 256]
    members = [random_stencil(rng, p, 10, 1, 1) for p in (8, 100, 9, 120)]
    assert group_by_class(members) == {(8, 16, 4): [0], (128, 16, 4): [1, 3], (16, 16, 4): [2]}


def test_a_member_larger_than_the_shape_is_refused(rng):
    with pytest.raises(ValueError, match="exceeds the capacity"):
        pack([random_stencil(rng, 20, 10, 1, 1)], shape=(16, 16, 4))
    with pytest.raises(ValueError, match="smaller than"):
        pack([random_stencil(rng, 20, 10, 1, 1)] * 3, batch=2)


def good():
    return LocalLP(np.ones((2, 3)), np.ones(2), np.array([0.5, 0.5, 0.0]), np.array([0, 0, 1]),
                   np.array([False, False, True]))


@pytest.mark.parametrize("change, message", [
    (dict(cost=np.ones(3)), "cost must be a"),
    (dict(mass=np.ones(3)), "mass must have shape"),
    (dict(cost=np.full((2, 3), np.nan)), "finite and non-negative"),
    (dict(cost=-np.ones((2, 3))), "finite and non-negative"),
    (dict(mass=np.array([1.0, 0.0])), "mass must be finite and positive"),
    (dict(capacity=np.array([0.5, 0.0, 0.0])), "positive capacity"),
    (dict(simplex=np.array([0, -1, 1])), "ids must be >= 0"),
    (dict(simplex=np.array([0, 1, 1])), "both vertex and facet"),
])
def test_bad_members_are_named(change, message):
    check_local(good())
    with pytest.raises(ValueError, match=message):
        check_local(good()._replace(**change))
