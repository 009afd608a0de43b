"""Grouping variable-size jobs into kernel batches of a few capacities.

A job's size is ``(rows, second, third)``: its rows and the two other
extents the kernel sizes its arrays by (edges and triangles for the curve
kernel); a kernel's ``capacity(rows, second, third, n_jobs)`` maps the
totals of a batch to the row capacity that fits them. A kernel's
cost is its batch's capacity (padding rows cost about as much as real
ones), so batches should fill their capacity and their shapes be few.
"""

from __future__ import annotations

from typing import Callable

# Jobs of at most 1/SMALL_JOB of the row budget are packed in order (next
# fit): a batch then wastes less than 1/SMALL_JOB of its rows
# (docs/decisions.md#small_job).
SMALL_JOB = 32
# One more kernel call, counted in padded rows (docs/decisions.md#call_rows).
CALL_ROWS = 1 << 11


class _Bin:
    __slots__ = ("members", "rows", "second", "third", "limit")

    def __init__(self, members, rows, second, third, limit):
        self.members = members
        self.rows = rows
        self.second = second
        self.third = third
        self.limit = limit


def pack_first_fit(sizes, budget: int, capacity: Callable[..., int]) -> list[list[int]]:
    """Batches by first fit, jobs taken by decreasing rows.

    Args:
      sizes: ``(rows, second, third)`` extents of each job (the kernel sizes
        its arrays by rows and two more extents, e.g. edges and triangles).
      budget: row capacity of a batch; a job that needs more opens a batch
        of its own capacity, which smaller jobs then fill.
      capacity: ``capacity(rows, second, third, n_jobs) -> rows`` of the
        kernel, non-decreasing in each argument.

    Returns:
      Batches as lists of job indices, each increasing; every job in exactly
      one. A batch holds jobs while the capacity of its totals stays within
      its limit (the larger of ``budget`` and its first job's own capacity);
      a job goes to the first batch with room.

    Example:
      >>> pack_first_fit([(3, 0, 0), (5, 0, 0), (2, 0, 0)], 6, lambda r, e, t, n: r)
      [[1], [0, 2]]
    """
    order = sorted(range(len(sizes)), key=lambda i: -sizes[i][0])
    # The smallest extents among the jobs from each position on: a batch
    # that cannot take them is full for every job after (capacity grows
    # with its arguments) and is no longer tried.
    low = [(0, 0, 0)] * (len(order) + 1)
    for k in range(len(order) - 1, -1, -1):
        r, e, t = sizes[order[k]]
        if k + 1 < len(order):
            r2, e2, t2 = low[k + 1]
            r, e, t = min(r, r2), min(e, e2), min(t, t2)
        low[k] = (r, e, t)
    bins: list[_Bin] = []
    open_bins: list[_Bin] = []
    for k, i in enumerate(order):
        r, e, t = sizes[i]
        full = []
        for b in open_bins:
            # Rows bind first: skip the capacity call for batches without room.
            if b.rows + r <= b.limit and capacity(b.rows + r, b.second + e, b.third + t,
                                                  len(b.members) + 1) <= b.limit:
                b.members.append(i)
                b.rows += r
                b.second += e
                b.third += t
                break
            lr, le, lt = low[k]
            if b.rows + lr > b.limit or capacity(b.rows + lr, b.second + le, b.third + lt,
                                                 len(b.members) + 1) > b.limit:
                full.append(b)
        else:
            b = _Bin([i], r, e, t, max(budget, capacity(r, e, t, 1)))
            bins.append(b)
            open_bins.append(b)
        if full:
            open_bins = [b for b in open_bins if b not in full]
    return [sorted(b.members) for b in bins]


def pack_next_fit(sizes, budget: int, capacity: Callable[..., int]) -> list[list[int]]:
    """Batches in job order, each closed when the next job does not fit it
    (sizes and limits as in :func:`pack_first_fit`).

    For many small jobs: a batch then wastes less than one job, where first
    fit would test every job against every batch.

    Example:
      >>> pack_next_fit([(3, 0, 0), (5, 0, 0), (2, 0, 0)], 6, lambda r, e, t, n: r)
      [[0], [1], [2]]
    """
    batches: list[list[int]] = []
    rows = second = third = limit = 0
    for i, (r, e, t) in enumerate(sizes):
        alone = capacity(r, e, t, 1)
        if not batches or capacity(rows + r, second + e, third + t, len(batches[-1]) + 1) > max(limit, alone):
            batches.append([])
            rows = second = third = 0
            limit = budget
        batches[-1].append(i)
        rows, second, third, limit = rows + r, second + e, third + t, max(limit, alone)
    return batches


def padded_rows(packing, sizes, capacity: Callable[..., int], shape_for: Callable[[int], int],
                call_rows: int = CALL_ROWS) -> int:
    """Rows the kernel calls of ``packing`` pad to, plus ``call_rows`` per call."""
    total = 0
    for members in packing:
        r, e, t = (sum(sizes[i][k] for i in members) for k in range(3))
        total += shape_for(capacity(r, e, t, len(members))) + call_rows
    return total


def choose_packing(sizes, budget: int, capacity: Callable[..., int], shape_for: Callable[[int], int],
                   min_rows: int) -> list[list[int]]:
    """The packing of ``sizes`` a pipeline should dispatch.

    Next fit when every job is small against the budget (first fit is
    quadratic in the batches), first fit otherwise. A batch of a few times
    ``min_rows`` pads to the budget's shape, so when everything fits in two
    budgets, the first fit into ``min_rows`` batches is tried too, and the
    packing with the fewer padded rows (:func:`padded_rows`) is kept.

    Example:
      >>> cap = lambda rows, e, t, n: max(4, 1 << (rows - 1).bit_length())
      >>> choose_packing([(3, 0, 0), (3, 0, 0), (3, 0, 0)], 16, cap, lambda need: need, 4)
      [[0, 1, 2]]
    """
    if not sizes:
        return []
    totals = [sum(col) for col in zip(*sizes)]
    one = min(min_rows, budget)
    if totals[0] <= one and capacity(*totals, len(sizes)) <= one:
        # Everything fits one smallest batch: every packing below is that
        # one batch (capacities grow with the totals), found without a
        # capacity call per job.
        return [list(range(len(sizes)))]
    small = max(s[0] for s in sizes) <= budget // SMALL_JOB
    packing = (pack_next_fit if small else pack_first_fit)(sizes, budget, capacity)
    if min_rows < budget and sum(s[0] for s in sizes) <= 2 * budget:
        other = pack_first_fit(sizes, min_rows, capacity)
        if padded_rows(other, sizes, capacity, shape_for) < padded_rows(packing, sizes, capacity, shape_for):
            packing = other
    return packing
