"""Scored half-edges, valid while their source's version holds, and the heap.

The table owns the scores; the versions belong to the engine's change log
and are only read here: an entry scored at an older version of its source
is stale.
"""

from __future__ import annotations

import heapq
import itertools
from typing import Callable, NamedTuple, Sequence

import numpy as np

Key = tuple[int, int]

# Stale heap items are skipped when they surface; once the heap holds this
# many times the items left by the last sweep (plus COMPACT_MIN), a sweep
# drops them all at once: one cheap test each instead of a pop down a heap
# several times too deep. The pop order is the same (items are totally
# ordered: the tie key and stamp are unique).
COMPACT_FACTOR = 2
COMPACT_MIN = 4096


class Popped(NamedTuple):
    """An entry taken off the heap by :meth:`ScoreTable.pop_any`."""

    key: Key
    fresh: bool  # scored at its source's current version


class ScoreTable:
    """Scores keyed by half-edge ``(source, target)``, and a lazy min-heap.

    Args:
      versions: per-vertex versions, owned by the engine (read only).
      tie_rng: break exact ties by a random key drawn from this generator
        rather than by insertion order. Exact ties (zero-cost collapses along
        clean straight runs) pop in insertion order, i.e. along the run,
        neighbours first; the parallel queue wants them spread out.
    """

    def __init__(self, versions: Sequence[int], tie_rng: np.random.Generator | None = None):
        self.versions = versions
        self.entries: dict[Key, tuple[float, int, int]] = {}  # key -> (delta, version, stamp)
        self.heap: list = []
        self.use_heap = False
        self._tie = itertools.count() if tie_rng is None else iter(lambda: float(tie_rng.random()), None)
        # Each entry's stamp: a heap item of an entry replaced at the same
        # version is stale too.
        self._stamp = itertools.count()
        self._compact_at = COMPACT_MIN
        # Lazy queue: heap items of stale entries are kept (they stand for
        # their source until it is scored again).
        self.keep_stale = False

    def fresh(self, key: Key) -> bool:
        """Whether ``key`` has a score at its source's current version."""
        entry = self.entries.get(key)
        return entry is not None and entry[1] == self.versions[key[0]]

    def delta(self, key: Key) -> float:
        """The score of ``key`` (fresh or not)."""
        return self.entries[key][0]

    def enter(self, scored, order: Callable[[Key], tuple]) -> None:
        """Enters ``[(key, delta)]`` at the current versions; with the heap in
        use, pushes them in ``order`` (which decides exact ties)."""
        versions, stamp = self.versions, self._stamp
        for key, delta in scored:
            self.entries[key] = (delta, versions[key[0]], next(stamp))
        if self.use_heap:
            for key in sorted((key for key, _ in scored), key=order):
                self.push(key)
            if len(self.heap) > self._compact_at:
                self._compact()

    def push(self, key: Key) -> None:
        """Puts ``key`` on the heap at its current score."""
        delta, ver, stamp = self.entries[key]
        heapq.heappush(self.heap, (delta, next(self._tie), key, ver, stamp))

    def pop(self, live: Callable[[int], bool]) -> Key | None:
        """The cheapest fresh entry whose source is ``live`` (removed from the
        heap), or ``None``; stale ones that come up first are dropped."""
        while (item := self.pop_any(live)) is not None:
            if item.fresh:
                return item.key
        return None

    def pop_any(self, live: Callable[[int], bool]) -> Popped | None:
        """The cheapest current entry whose source is ``live`` (removed from
        the heap), or ``None``. An entry replaced since its item was pushed
        is skipped; one whose source changed since it was scored is returned
        with ``fresh`` false."""
        while self.heap:
            _, _, key, ver, stamp = heapq.heappop(self.heap)
            entry = self.entries.get(key)
            if entry is None or entry[2] != stamp or not live(key[0]):
                continue
            return Popped(key, ver == self.versions[key[0]])
        return None

    def _compact(self) -> None:
        """Drops the stale heap items (stale for good: versions and stamps only grow)."""
        entries, versions = self.entries, self.versions
        kept = []
        for item in self.heap:
            entry = entries.get(item[2])
            if entry is not None and entry[2] == item[4] and (self.keep_stale or item[3] == versions[item[2][0]]):
                kept.append(item)
        heapq.heapify(kept)
        self.heap = kept
        self._compact_at = COMPACT_FACTOR * len(kept) + COMPACT_MIN

    def discard(self, keys) -> None:
        """Drops the entries of ``keys`` (taken to be applied)."""
        for key in keys:
            self.entries.pop(key, None)
