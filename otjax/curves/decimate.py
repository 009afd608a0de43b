"""Greedy decimation of a curve: the shared loop over a :class:`CurveEngine`,
and the tolerance mode's veto.

See :mod:`otjax.decimation.loop` for the queues.
"""

from __future__ import annotations

import numpy as np

from otjax.curves.engine import CurveEngine
from otjax.decimation.loop import QUEUES, DecimationStats
from otjax.decimation.loop import decimate as _decimate

__all__ = ["QUEUES", "DecimationStats", "decimate", "within_tolerance"]


def within_tolerance(tolerance: float):
    """Veto of the tolerance mode (paper §3.5), as a candidate filter.

    A change is admissible when, on every edge of its stencil that carries
    mass ``M_e``, the root-mean-square transport distance of each part stays
    under ``tolerance``: ``sqrt(N_e / M_e)`` and ``sqrt(T_e / M_e)`` for a
    solid edge, ``sqrt(V_e / M_e)`` (its points go to the endpoints) for a
    ghost edge. RMS distances are in the units of the input, so the
    tolerance reads like a distance, independent of how masses are scaled.

    Returns:
      ``(candidate, cost) -> bool``, ``cost`` its
      :class:`~otjax.curves.stencils.CandidateCost`.
    """
    tol2 = float(tolerance) ** 2

    def ok(cand, cost) -> bool:
        solid = cost.solid
        first = np.where(solid, cost.normal, cost.vertex)
        second = np.where(solid, cost.tangential, 0.0)
        bound = tol2 * cost.edge_mass
        return bool(np.all((first <= bound) & (second <= bound)))

    return ok


def decimate(engine: CurveEngine, n_vertices: int | None = None, *, tolerance: float | None = None,
             relocation: int = 0, queue: str = "exhaustive", choices: int = 15, switch_factor: float = 5.0,
             round_fraction: float = 0.05, seed: int = 0, progress: bool = False) -> DecimationStats:
    """Collapses greedily until ``n_vertices`` remain or no collapse is admissible.

    Args:
      engine: the :class:`CurveEngine`; modified in place.
      n_vertices: target count of vertices (pinned corners not counted), >= 1;
        ``None`` runs until the queue is empty (tolerance mode).
      tolerance: if given, collapses that would push some edge's RMS normal or
        tangential transport distance above it are discarded
        (:func:`within_tolerance`).
      relocation: relocate the vertices of the modified one-ring after each
        of the last ``relocation`` collapses. Needs ``n_vertices``.
      queue, choices, switch_factor, round_fraction, seed, progress: see
        :func:`otjax.decimation.loop.decimate`.

    Returns:
      :class:`~otjax.decimation.loop.DecimationStats`.

    Example:
      >>> import jax, numpy as np
      >>> from otjax.curves.triangulation import Triangulation
      >>> p = np.random.default_rng(0).random((50, 2))
      >>> with jax.enable_x64(True):
      ...     engine = CurveEngine(Triangulation(p), p, np.ones(50))
      ...     decimate(engine, 10).collapses
      40
    """
    if n_vertices is None and tolerance is None:
        raise ValueError("give n_vertices, tolerance, or both")
    veto = within_tolerance(tolerance) if tolerance is not None else None
    return _decimate(engine, n_vertices, queue=queue, choices=choices, switch_factor=switch_factor,
                     round_fraction=round_fraction, seed=seed, relocation=relocation, veto=veto,
                     progress=progress)
