"""Transverse facets (a fin inside an open cylinder, a lid over its rim): found, and removed
with the plan kept whole."""

import functools

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from otjax.background import point_normals
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.plan import BinSettings, Entries, SurfacePlan
from otjax.surfaces.transverse import facet_alignment, find_transverse, remove_transverse

# An open cylinder of radius 1 round the z axis, z in [0, 1]: three rings of
# eight vertices (z = 0, 1/2, 1, ids K k + i), the side between them in
# triangles; a fin across the middle ring and a lid over the top rim, each
# on three consecutive vertices of its ring.
K = 8
FIN = (8, 9, 10)
LID = (16, 17, 18)


def _ring(k, i):
    return K * k + i % K


SIDES = [tuple(sorted(t)) for k in (0, 1) for i in range(K)
         for t in ((_ring(k, i), _ring(k, i + 1), _ring(k + 1, i)),
                   (_ring(k, i + 1), _ring(k + 1, i + 1), _ring(k + 1, i)))]


def _corners():
    angle = 2 * np.pi * np.arange(K) / K
    return np.concatenate([np.c_[np.cos(angle), np.sin(angle), np.full(K, z)] for z in (0.0, 0.5, 1.0)])


def _points(n=1500, seed=0):
    u, z = np.random.default_rng(seed).random((2, n))
    return np.c_[np.cos(2 * np.pi * u), np.sin(2 * np.pi * u), z]


def _side(angle, z):
    """The side facet over cylinder coordinates ``(angle, z)``."""
    cell = angle / (2 * np.pi / K)
    i, k = int(cell), min(int(z / 0.5), 1)
    s, t = cell - i, z / 0.5 - k
    return SIDES[2 * (K * k + i) + (s + t > 1)]


@functools.lru_cache(maxsize=1)
def _plan():
    """The cylinder's points on its sides, the fin and the lid: the points
    within 0.03 of the middle ring's (top rim's) first two chords on the fin
    (lid), as a transport that keeps them would put them, every other point
    on the side facet it lies over; each on its facet's nearest bin."""
    points = _points()
    c = SimplicialComplex(_corners(), np.array(SIDES + [FIN, LID]))
    plan = SurfacePlan(c, points, np.ones(len(points)), BinSettings(diagonal=float(np.sqrt(5.0))))
    angle = np.mod(np.arctan2(points[:, 1], points[:, 0]), 2 * np.pi)
    span = angle < 2 * (2 * np.pi / K)
    owner = [FIN if span[j] and abs(z - 0.5) < 0.03 else LID if span[j] and z > 0.97
             else _side(angle[j], z) for j, z in enumerate(points[:, 2])]
    entries = {}
    for t in sorted(set(owner)):
        rows = np.flatnonzero([o == t for o in owner])
        near = ((points[rows, None] - plan.bin_positions(t)[None]) ** 2).sum(-1).argmin(1)
        entries[t] = Entries(rows, near, np.ones(len(rows)))
    return SurfacePlan.from_entries(c, points, plan.masses, plan.settings, plan.bins, {}, entries)


def _copy(plan, x, points, masses):
    c = SimplicialComplex(x, np.array(sorted(plan.complex.triangles)))
    return SurfacePlan.from_entries(c, points, masses, plan.settings, plan.bins, plan.vertex_entries,
                                    plan.facet_entries)


def test_the_fin_and_the_lid_are_transverse_and_the_sides_are_not():
    plan = _plan()
    assert plan.simplex_mass(FIN) > 10 and plan.simplex_mass(LID) > 10
    align = facet_alignment(plan, point_normals(plan.points))
    assert align[FIN] < 0.2 and align[LID] < 0.2
    # a side facet spans 45 degrees of the ring: its points' normals within 22.5 degrees of its own
    assert min(align[t] for t in SIDES if t in align) > np.cos(np.radians(25))
    assert find_transverse(plan, point_normals(plan.points)) == [FIN, LID]



@pytest.mark.parametrize("alignment", [0.0, 1.0, -0.5, 2.0, float("nan"), "0.5"])
def test_an_alignment_outside_the_open_unit_interval_is_refused(alignment):
    plan = _plan()
    with pytest.raises(ValueError, match="alignment must be"):
        find_transverse(plan, point_normals(plan.points), alignment)
    with pytest.raises(ValueError, match="alignment must be"):
        remove_transverse(plan, point_normals(plan.points), alignment)
    assert FIN in plan.complex.triangles  # refused before anything was removed


def test_points_whose_normals_are_unreliable_are_no_evidence():
    plan = _plan()
    normals = point_normals(plan.points)
    assert normals.reliable.mean() > 0.99  # a smooth cylinder: nearly every neighbourhood is flat
    fin = plan.entries(FIN).point  # unit masses: a share of the points is a share of the mass

    def doubt(share):  # the fin's first points taken as straddling a crease
        reliable = np.ones(len(plan.points), bool)
        reliable[fin[:int(np.ceil(share * len(fin)))]] = False
        return normals._replace(reliable=reliable)

    # under half of the fin's mass on reliable points: no alignment, and it stays
    assert FIN not in facet_alignment(plan, doubt(0.6))
    assert find_transverse(plan, doubt(0.6)) == [LID]
    # over half: measured on those alone
    assert facet_alignment(plan, doubt(0.4))[FIN] < 0.2
    assert find_transverse(plan, doubt(0.4)) == [FIN, LID]


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(0, 2**32 - 1), st.floats(1e-3, 1e3), st.floats(1e-2, 1e2))
def test_transverse_facets_do_not_depend_on_the_frame_or_the_units(seed, scale, unit):
    """Rotating, scaling and moving the complex and its points (and scaling
    the masses) finds the same facets, with the same alignments."""
    plan = _plan()
    rng = np.random.default_rng(seed)
    rotation, shift = Rotation.random(random_state=rng), rng.normal(size=3) * 10

    def move(x):
        return rotation.apply(x) * scale + shift

    moved = _copy(plan, move(plan.complex.positions), move(plan.points), plan.masses * unit)
    before = facet_alignment(plan, point_normals(plan.points))
    after = facet_alignment(moved, point_normals(moved.points))
    assert after.keys() == before.keys()
    np.testing.assert_allclose([after[t] for t in before], list(before.values()), atol=1e-6)
    assert find_transverse(moved, point_normals(moved.points)) == [FIN, LID]


def test_removing_transverse_facets_keeps_every_point_transported_and_leaves_the_sides():
    plan = _plan()
    plan = _copy(plan, plan.complex.positions, plan.points, plan.masses)
    lost = {t: plan.simplex_mass(t) for t in (FIN, LID)}
    corners = sorted(set(FIN + LID))
    before = {v: plan.simplex_mass(v) for v in corners}
    assert remove_transverse(plan, point_normals(plan.points)) == 2
    assert plan.complex.triangles == set(SIDES)
    # the chords across the fin and the lid belonged to them alone
    assert not plan.complex.has_edge(8, 10) and not plan.complex.has_edge(16, 18)
    assert all(t not in plan.facet_entries and t not in plan.bins for t in (FIN, LID))
    np.testing.assert_allclose(plan.point_mass(), 1.0, rtol=1e-12)
    gained = sum(plan.simplex_mass(v) - before[v] for v in corners)
    assert abs(gained - sum(lost.values())) < 1e-9
    assert find_transverse(plan, point_normals(plan.points)) == []
