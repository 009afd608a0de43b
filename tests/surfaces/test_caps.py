"""Caps across a concave corner of an open border: found, and removed with the plan kept whole."""

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from otjax.surfaces.caps import find_caps, remove_caps
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.plan import BinSettings, SurfacePlan
from otjax.surfaces.relaxation import relax
from otjax.surfaces.solvers import exact_solver

# A tread (z = 0, x in [0, 1]) and a riser (x = 1, z in [0, 1]), both y in
# [0, 1], meeting at the concave crease x = 1, z = 0; the cap (0, 1, 4)
# closes the corner in the border's plane y = 0.
CORNERS = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [1, 0, 1], [1, 1, 1]], float)
SHEETS = [(0, 1, 2), (1, 2, 3), (1, 3, 4), (3, 4, 5)]
CAP = (0, 1, 4)


def masses(cap_mass):
    return {**{t: 1.0 for t in SHEETS}, CAP: cap_mass}


def test_only_the_sparse_facet_across_the_corner_with_a_free_edge_is_a_cap():
    c = SimplicialComplex(CORNERS, np.array(SHEETS + [CAP]))
    assert find_caps(c, masses(0.2)) == [CAP]
    # as dense as the mean (mass 1 on each facet of area 1/2): kept
    assert find_caps(c, masses(1.0)) == []
    # without the cap, the sheets' own border facets are no caps (a coplanar neighbour each)
    assert find_caps(SimplicialComplex(CORNERS, np.array(SHEETS)), masses(0.2)) == []
    # a facet closing the border edge (0, 4) too has no free edge
    closed = SimplicialComplex(np.r_[CORNERS, [[0.5, -1, 0.5]]], np.array(SHEETS + [CAP, (0, 4, 6)]))
    assert find_caps(closed, {**masses(0.2), (0, 4, 6): 3.0}) == []


def test_a_facet_folded_over_its_neighbour_is_no_cap():
    # (0, 1, 6) lies over the tread on the edge (0, 1), 3 degrees off it: a fold, not a corner
    x = np.r_[CORNERS, [[0.5, 0.5, np.tan(np.radians(3)) * 0.5]]]
    c = SimplicialComplex(x, np.array(SHEETS + [(0, 1, 6)]))
    assert find_caps(c, {**masses(0.0), (0, 1, 6): 0.1}) == []


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.floats(1e-3, 1e3), st.floats(0.0, 0.9))
def test_caps_do_not_depend_on_the_frame_or_the_units(seed, scale, cap_share):
    """Rotating, scaling and moving the complex (and scaling the masses)
    finds the same caps; a cap is found exactly when it is less dense than
    the mean."""
    # every facet has area 1/2: the mean density is (4 + 2 share) / 2.5, the cap's 4 share
    cap, mean = 4 * cap_share, (4 + 2 * cap_share) / 2.5
    assume(abs(cap - mean) > 1e-9 * mean)  # at a tie rounding decides
    rng = np.random.default_rng(seed)
    x = Rotation.random(random_state=rng).apply(CORNERS) * scale + rng.normal(size=3) * 10
    c = SimplicialComplex(x, np.array(SHEETS + [CAP]))
    k = float(rng.uniform(0.01, 100))
    found = find_caps(c, {t: k * m for t, m in masses(cap_share * 2).items()})
    assert found == ([CAP] if cap < mean else [])


def test_removing_a_cap_keeps_every_point_transported_and_leaves_the_sheets():
    rng = np.random.default_rng(1)
    u, v = rng.random((2, 300))
    tread = np.c_[u[:150], v[:150], np.zeros(150)]
    riser = np.c_[np.ones(150), v[150:], u[150:]]
    # a few points in the cap's plane y = 0, spread over it (x >= z)
    a, b = rng.random((2, 30))
    border = np.c_[np.maximum(a, b), np.zeros(30), np.minimum(a, b)]
    points = np.r_[tread, riser, border]
    plan = SurfacePlan(SimplicialComplex(CORNERS, np.array(SHEETS + [CAP])), points, np.ones(len(points)),
                       BinSettings(diagonal=float(np.sqrt(3.0))))
    relax(plan, exact_solver, max_sweeps=4)
    cap_mass = plan.simplex_mass(CAP)
    assert cap_mass > 0  # the border points went to the cap
    before = {v: plan.simplex_mass(v) for v in CAP}
    assert remove_caps(plan) == 1
    assert plan.complex.triangles == set(SHEETS)
    assert not plan.complex.has_edge(0, 4)
    assert CAP not in plan.facet_entries and CAP not in plan.bins
    np.testing.assert_allclose(plan.point_mass(), 1.0, rtol=1e-12)
    gained = sum(plan.simplex_mass(v) - before[v] for v in CAP)
    assert abs(gained - cap_mass) < 1e-9
