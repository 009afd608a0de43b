"""Packing variable-size jobs into batches: first fit, next fit, the choice.

Checked with the curve kernel's capacity classes (otjax.curves.scoring) and
with a plain power-of-two capacity.
"""

from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.batch import packing
from otjax.batch.packing import choose_packing, pack_first_fit, pack_next_fit, padded_rows
from otjax.batch.pipeline import ShapePolicy
from otjax.curves import scoring


def pow2(rows, second, third, n):
    """A toy kernel's capacity: a power of two from 4 holding the rows,
    ``2 x second``, ``third`` and one job slot more than ``n``; monotone,
    >= rows."""
    need = max(4, rows, 2 * second, third, n + 1)
    return 1 << (need - 1).bit_length()


def limits(batches, jobs, budget, capacity):
    return [max(budget, max(capacity(*jobs[i], 1) for i in b)) for b in batches]


def total(jobs, b):
    return [sum(jobs[i][k] for i in b) for k in range(len(jobs[b[0]]))] + [len(b)]


def check_first_fit(jobs, budget, capacity):
    batches = pack_first_fit(jobs, budget, capacity)
    assert sorted(i for b in batches for i in b) == list(range(len(jobs)))
    assert all(b and b == sorted(b) for b in batches)
    lim = limits(batches, jobs, budget, capacity)
    for b, limit in zip(batches, lim):
        assert capacity(*total(jobs, b)) <= limit
    # First fit: no job of a later batch would have fitted an earlier one
    # (batches only grow, so it did not fit then either).
    for j, later in enumerate(batches):
        for i in range(j):
            *sums, n = total(jobs, batches[i])
            for x in later:
                assert capacity(*[s + e for s, e in zip(sums, jobs[x])], n + 1) > lim[i]
    return batches


def check_next_fit(jobs, budget, capacity):
    batches = pack_next_fit(jobs, budget, capacity)
    assert [i for b in batches for i in b] == list(range(len(jobs)))
    assert all(b for b in batches)

    def fits(b):
        return capacity(*total(jobs, b)) <= max(budget, max(capacity(*jobs[i], 1) for i in b))

    for b, nxt in zip(batches, batches[1:]):
        assert fits(b) and not fits(b + nxt[:1])
    assert not batches or fits(batches[-1])
    return batches


@settings(max_examples=100, deadline=None)
@given(sizes=st.lists(st.tuples(st.integers(1, 70_000), st.integers(1, 60)), min_size=0, max_size=120),
       budget=st.sampled_from([4096, 8192, 1 << 15]))
def test_first_fit_packing_is_a_partition_within_limits(sizes, budget):
    """Every job in one batch; a batch within the larger of the budget and
    its largest job's own capacity; and first fit: no job of a later batch
    would have fitted an earlier one (batches only grow, so it did not fit
    then either)."""
    jobs = [(r, 2 * t + 1, t) for r, t in sizes]
    check_first_fit(jobs, budget, scoring.capacity)


@settings(max_examples=100, deadline=None)
@given(sizes=st.lists(st.tuples(st.integers(0, 3000), st.integers(1, 60)), min_size=0, max_size=400),
       budget=st.sampled_from([4096, 1 << 15]))
def test_next_fit_packing_keeps_order_within_limits(sizes, budget):
    """Consecutive runs of the jobs, in order; each within the larger of the
    budget and its largest job's capacity; each closed only when the next
    job would not fit it."""
    jobs = [(r, 2 * t + 1, t) for r, t in sizes]
    check_next_fit(jobs, budget, scoring.capacity)


toy_jobs = st.lists(st.tuples(st.integers(0, 80), st.integers(0, 30), st.integers(0, 40)), max_size=40)


@settings(max_examples=300, deadline=None)
@given(jobs=toy_jobs, budget=st.sampled_from([4, 8, 16, 64]))
def test_first_and_next_fit_with_a_toy_capacity(jobs, budget):
    check_first_fit(jobs, budget, pow2)
    check_next_fit(jobs, budget, pow2)


def test_the_documented_examples():
    assert pack_first_fit([(3, 0, 0), (5, 0, 0), (2, 0, 0)], 6, lambda r, e, t, n: r) == [[1], [0, 2]]
    assert pack_next_fit([(3, 0, 0), (5, 0, 0), (2, 0, 0)], 6, lambda r, e, t, n: r) == [[0], [1], [2]]
    cap = lambda r, e, t, n: max(4, 1 << (r - 1).bit_length())  # noqa: E731
    assert choose_packing([(3, 0, 0)] * 3, 16, cap, lambda need: need, 4) == [[0, 1, 2]]
    assert pack_first_fit([], 8, pow2) == pack_next_fit([], 8, pow2) == choose_packing([], 8, pow2, int, 4) == []


def test_a_job_over_the_budget_opens_a_batch_that_smaller_jobs_fill():
    jobs = [(10, 0, 0), (40, 0, 0), (20, 0, 0), (3, 0, 0)]
    # By decreasing rows: 40 opens a 64-row batch, 20 joins it, 10 does not
    # fit (70 rows) and opens a 16-row one; 3 goes to the first with room.
    assert pack_first_fit(jobs, 16, pow2) == [[1, 2, 3], [0]]
    # In order: 10 + 40 fit the 64 rows 40 needs alone; 20 does not (70),
    # and opens a 32-row batch that 3 joins.
    assert pack_next_fit(jobs, 16, pow2) == [[0, 1], [2, 3]]


def test_padded_rows_counts_each_call_at_its_shape():
    shapes = ShapePolicy(8, 32).shape_for
    jobs = [(3, 0, 0), (9, 0, 0), (40, 0, 0)]
    assert padded_rows([[0], [1], [2]], jobs, pow2, shapes, call_rows=100) == 8 + 32 + 64 + 300
    assert padded_rows([[0, 1], [2]], jobs, pow2, shapes, call_rows=0) == 32 + 64
    assert padded_rows([], jobs, pow2, shapes) == 0


def considered(sizes, budget, capacity, min_rows):
    """The packings :func:`choose_packing` weighs, by its documented rule."""
    small = not sizes or max(s[0] for s in sizes) <= budget // packing.SMALL_JOB
    out = [(pack_next_fit if small else pack_first_fit)(sizes, budget, capacity)]
    if min_rows < budget and sum(s[0] for s in sizes) <= 2 * budget:
        out.append(pack_first_fit(sizes, min_rows, capacity))
    return out


@settings(max_examples=150, deadline=None)
@given(sizes=st.lists(st.tuples(st.integers(1, 40_000), st.integers(1, 40)), max_size=60),
       budget=st.sampled_from([1 << 13, 1 << 15]))
def test_choose_packing_never_pads_more_than_what_it_considered(sizes, budget):
    jobs = [(r, 2 * t + 1, t) for r, t in sizes]
    shape_for = ShapePolicy(scoring.MIN_ROWS, budget).shape_for
    got = choose_packing(jobs, budget, scoring.capacity, shape_for, scoring.MIN_ROWS)
    assert sorted(i for b in got for i in b) == list(range(len(jobs)))
    options = considered(jobs, budget, scoring.capacity, scoring.MIN_ROWS)
    assert got in options
    cost = padded_rows(got, jobs, scoring.capacity, shape_for)
    assert all(cost <= padded_rows(o, jobs, scoring.capacity, shape_for) for o in options)


@settings(max_examples=300, deadline=None)
@given(jobs=st.lists(st.tuples(st.integers(1, 80), st.integers(0, 30), st.integers(0, 40)), max_size=30),
       budget=st.sampled_from([16, 64, 256]), min_rows=st.sampled_from([4, 8, 16]))
def test_choose_packing_with_a_toy_capacity(jobs, budget, min_rows):
    shape_for = ShapePolicy(min_rows, budget).shape_for
    got = choose_packing(jobs, budget, pow2, shape_for, min_rows)
    options = considered(jobs, budget, pow2, min_rows)
    assert got in options
    assert all(padded_rows(got, jobs, pow2, shape_for) <= padded_rows(o, jobs, pow2, shape_for) for o in options)


def test_small_batches_go_to_the_small_shape_when_that_pads_less():
    """Two jobs of 2500 rows: one budget-shaped call (32768 rows) or two
    MIN_ROWS calls (2 x 4096 rows plus a call each): the latter."""
    jobs = [(2500, 11, 5), (2500, 11, 5)]
    shape_for = ShapePolicy(scoring.MIN_ROWS, 1 << 15).shape_for
    assert pack_first_fit(jobs, 1 << 15, scoring.capacity) == [[0, 1]]
    assert choose_packing(jobs, 1 << 15, scoring.capacity, shape_for, scoring.MIN_ROWS) == [[0], [1]]
    # Many small jobs over two budgets: next fit in order, nothing else tried.
    many = [(100, 5, 2)] * 800
    got = choose_packing(many, 1 << 15, scoring.capacity, shape_for, scoring.MIN_ROWS)
    assert got == pack_next_fit(many, 1 << 15, scoring.capacity)


@settings(max_examples=200, deadline=None)
@given(jobs=st.lists(st.tuples(st.integers(1, 60), st.integers(0, 10), st.integers(0, 10)), min_size=1, max_size=12),
       budget=st.sampled_from([64, 256]), min_rows=st.sampled_from([64, 128]))
def test_jobs_fitting_one_smallest_batch_are_one_batch(jobs, budget, min_rows):
    """The shortcut for a few small jobs gives what the full choice would:
    next fit (or first fit) puts them all in one batch."""
    shape_for = ShapePolicy(min_rows, budget).shape_for
    got = choose_packing(jobs, budget, pow2, shape_for, min_rows)
    if pow2(*total(jobs, list(range(len(jobs))))) <= min(min_rows, budget):
        assert got == [list(range(len(jobs)))]
        assert got == pack_next_fit(jobs, budget, pow2)
    assert got in considered(jobs, budget, pow2, min_rows)
