"""The scored stencils of the latest scoring calls, kept at hand for take.

The winner of a greedy step was usually scored a few dozen calls before;
keeping the latest calls' host batches and kernel outputs lets the engine
take it without exporting and scoring it again. They are held within a byte
budget, oldest calls dropped first.
"""

from __future__ import annotations

from collections import OrderedDict
from typing import NamedTuple

# Bytes of the scoring calls whose stencils stay at hand (the latest calls':
# their host batches and kernel outputs). One not at hand is exported and
# scored again (docs/decisions.md#hot_bytes).
HOT_BYTES = 64 << 20


class HotEntry(NamedTuple):
    """One scored half-edge at hand.

    Attributes:
      stencils: the candidates of its scoring call (a sequence).
      costs: their costs (a sequence).
      index: its place in ``stencils`` and ``costs``.
      plan: its collapse plan when scored.
      version: its source's version when scored.
      call: the scoring call it came from.
    """

    stencils: object
    costs: object
    index: int
    plan: object
    version: int
    call: int


class HotStencils:
    """Scored half-edges of the latest scoring calls, by source then target.

    Args:
      budget: bytes held at most (the latest call is kept whatever its size).
    """

    def __init__(self, budget: int = HOT_BYTES):
        self.budget = budget
        self._by_source: dict[int, dict[int, HotEntry]] = {}
        self._calls: OrderedDict = OrderedDict()  # {call: (bytes, keys)}, oldest first
        self._bytes = 0
        self._last_call = 0

    def new_call(self) -> int:
        """A number for the next scoring call, increasing."""
        self._last_call += 1
        return self._last_call

    def keep(self, call: int, size: int, entries: list[tuple[tuple[int, int], HotEntry]]) -> None:
        """Keeps the ``(half-edge, entry)`` pairs of one call (``size`` bytes
        held), dropping the oldest calls' beyond the budget."""
        by_source = self._by_source
        for (s, t), entry in entries:
            targets = by_source.get(s)
            if targets is None:
                targets = by_source[s] = {}
            targets[t] = entry
        self._calls[call] = (size, [key for key, _ in entries])
        self._bytes += size
        while self._bytes > self.budget and len(self._calls) > 1:
            old, (n, old_keys) = self._calls.popitem(last=False)
            self._bytes -= n
            for s, t in old_keys:
                targets = by_source.get(s)
                entry = None if targets is None else targets.get(t)
                if entry is not None and entry.call == old:
                    del targets[t]

    def pop(self, key: tuple[int, int]) -> HotEntry | None:
        """The entry of half-edge ``key``, no longer kept; ``None`` if none."""
        return self._by_source.get(key[0], {}).pop(key[1], None)

    def forget(self, v: int) -> None:
        """Drops the half-edges leaving ``v`` (their stencils are stale)."""
        self._by_source.pop(v, None)
