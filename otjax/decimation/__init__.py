"""The greedy decimation loop, shared by every dimension: no JAX, no geometry.

- :mod:`otjax.decimation.score_table` -- scored half-edges, their versions
  and the priority queue.
- :mod:`otjax.decimation.sampling` -- the live vertex set, uniform sampling
  of half-edges, independent sets of collapses.
- :mod:`otjax.decimation.loop` -- the exhaustive, multiple-choice and
  parallel queues over an *engine* (see :class:`~otjax.decimation.loop.Engine`).
"""

from otjax.decimation.loop import QUEUES, DecimationStats, Engine, decimate
from otjax.decimation.score_table import ScoreTable

__all__ = ["QUEUES", "DecimationStats", "Engine", "ScoreTable", "decimate"]
