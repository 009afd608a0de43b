"""The closed-form relocation (otjax.curves.relocation.optimal_position)
against a least-squares oracle on the frozen plan."""

import jax
import numpy as np
import pytest

from otjax.curves.decimate import decimate
from otjax.curves.engine import CurveEngine
from otjax.curves.relocation import optimal_position
from otjax.curves.triangulation import Triangulation
from otjax.frame import to_canonical


def decimated(points, target, seed):
    frame, pts, mass = to_canonical(points, np.ones(len(points)))
    engine = CurveEngine(Triangulation(pts), pts, mass)
    decimate(engine, target, relocation=0, seed=seed)
    return engine


def frozen_terms(plan, v):
    """``(points, masses, other ends or -1 for v itself, lambdas)`` of what
    the plan sends to ``v`` and its solid edges, read straight from the
    plan's arrays."""
    tri = plan.tri
    ids = np.flatnonzero((plan.pt_edge == v).any(1))
    rows = []
    for i in ids:
        a, b = plan.pt_edge[i]
        u = b if a == v else a
        p = plan.points[i]
        if plan.solid_of(np.array([[a, b]]))[0]:
            d = tri.xy[u] - tri.xy[v]
            rows.append((p, plan.mass[i], u, float((p - tri.xy[v]) @ d / (d @ d))))
        elif (p - tri.xy[v]) @ (p - tri.xy[v]) <= (p - tri.xy[u]) @ (p - tri.xy[u]):
            rows.append((p, plan.mass[i], -1, 0.0))
    return rows


def least_squares_position(plan, v):
    """Minimiser of ``sum m |p - v|^2`` (points sent to v) plus ``sum m |p -
    (1 - l) v - l b|^2`` (points of solid edges, ``l`` frozen), by lstsq."""
    a, rhs = [], []
    for p, m, u, lam in frozen_terms(plan, v):
        w = np.sqrt(m)
        if u < 0:
            a.append(w * np.eye(2))
            rhs.append(w * p)
        else:
            a.append(w * (1 - lam) * np.eye(2))
            rhs.append(w * (p - lam * plan.tri.xy[u]))
    sol, *_ = np.linalg.lstsq(np.concatenate(a), np.concatenate(rhs), rcond=None)
    return sol


def solid_neighbours(plan, v):
    return sorted({u for _, _, u, _ in frozen_terms(plan, v) if u >= 0})


@pytest.mark.parametrize("seed", range(3))
def test_inner_vertices_go_to_the_least_squares_minimiser(seed):
    rng = np.random.default_rng(seed)
    t = rng.random(150) * 2 * np.pi
    points = np.c_[np.cos(t), 0.6 * np.sin(t)] + 0.01 * rng.standard_normal((150, 2))
    with jax.enable_x64(True):
        engine = decimated(points, 12, seed)
        plan = engine.plan
        checked = 0
        for v in engine.live_sources():
            if len(solid_neighbours(plan, v)) < 2:
                continue
            np.testing.assert_allclose(optimal_position(plan, v), least_squares_position(plan, v),
                                       rtol=1e-9, atol=1e-12)
            checked += 1
    assert checked >= 8
