"""Feature recovery never turns a face over: the step limit against a NumPy
oracle, a move that would fold a face, random plans pulling vertices anywhere."""

import jax
import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from otjax.surfaces.features import relocation_pass
from otjax.surfaces.plan import BinSettings
from otjax.surfaces.star_passes import FLIP_MARGIN, flip_free_steps, relocate_class
from otjax.surfaces.star_plan import StarPlan


def oracle_normals(vertices, triangles):
    """Normals of the faces as given, by NumPy's cross product."""
    a, b, c = (vertices[triangles[:, i]] for i in range(3))
    return np.cross(b - a, c - a)


def grid(n, jitter=0.0, seed=0):
    """``(n * n, 3)`` vertices of a unit grid in the plane z = 0 (jittered in x, y)
    and its ``2 (n - 1)^2`` faces, all facing +z."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(n, dtype=float), np.arange(n, dtype=float), indexing="xy")
    v = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    v[:, :2] += rng.uniform(-jitter, jitter, (n * n, 2))
    i = np.arange(n - 1)
    a = (i[None, :] + n * i[:, None]).ravel()
    tri = np.concatenate([np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]])
    return v, tri


# ------------------------------------------------------------- the step limit
@st.composite
def moves(draw):
    seed = draw(st.integers(0, 2**32 - 1))
    n = draw(st.integers(1, 20))
    rng = np.random.default_rng(seed)
    corners = rng.normal(size=(n, 3, 3))
    reference = oracle_normals(corners.reshape(-1, 3), np.arange(3 * n).reshape(n, 3))
    # the faces may already have turned a little from their reference
    corners = corners + draw(st.sampled_from([0.0, 0.1, 0.3])) * rng.normal(size=corners.shape)
    return corners, rng.integers(0, 3, n), rng.normal(size=(n, 3)) * draw(st.sampled_from([0.1, 1.0, 10.0])), \
        reference, draw(st.sampled_from([0.5, 1.0]))


def moved(corners, slot, direction, t):
    out = corners.copy()
    out[np.arange(len(slot)), slot] += t[:, None] * direction
    return out


@settings(max_examples=200, deadline=None)
@given(moves())
def test_step_limit_matches_the_oracle(move):
    corners, slot, direction, reference, limit = move
    n = len(slot)
    faces = np.arange(3 * n).reshape(n, 3)

    def along(t):  # n(t) . r by NumPy's cross product of the moved corners
        return np.einsum("fd,fd->f", oracle_normals(moved(corners, slot, direction, t).reshape(-1, 3), faces),
                         reference)

    t = flip_free_steps(corners, slot, direction, reference, limit)
    now = along(np.zeros(n))
    scale = np.linalg.norm(reference, axis=1) * (1 + np.max(np.abs(corners), axis=(1, 2))
                                                 + np.linalg.norm(direction, axis=1)) ** 2
    assert np.all((t >= 0) & (t <= limit))
    up = now > 0
    # faces facing their reference keep at least (1 - margin) of its projection
    assert np.all(along(t)[up] >= (1 - FLIP_MARGIN) * now[up] - 1e-9 * scale[up])
    # faces already turned away move no further away
    assert np.all(along(t)[~up] >= now[~up] - 1e-9 * scale[~up])
    # a limited step is the longest: at t / margin the face is on edge (n . r = 0)
    short = up & (t < limit)
    np.testing.assert_allclose(along(t / FLIP_MARGIN)[short], 0.0, atol=1e-9 * scale[short].max(initial=1))


# ------------------------------------------------------- the relocation pass
def plan_on_grid(vertices, triangles, points, bins):
    """A plan with point ``i`` wholly on vertex bin ``bins[i]``."""
    plan = StarPlan(vertices, triangles, points, np.ones(len(points)), BinSettings(diagonal=10.0))
    plan.entry_bin = np.asarray(bins, np.int64)
    return plan


def test_a_move_that_would_fold_a_face_is_shortened():
    v, tri = grid(5)
    centre = 12  # (2, 2), its ring at distance 1
    points = np.array([[2.0, 5.0, 0.0], [2.1, 5.0, 0.0], [1.9, 5.0, 0.0]])  # beyond the ring
    with jax.enable_x64(True):
        plan = plan_on_grid(v, tri, points, [centre] * 3)
        target = plan.targets(np.array([centre]))[0]
        unguarded = v.copy()
        unguarded[centre] += 0.5 * (target - v[centre])
        # the test is about something: the paper's half-way move turns faces over
        assert np.any(np.einsum("ij,ij->i", oracle_normals(v, tri), oracle_normals(unguarded, tri)) <= 0)
        stats = relocate_class(plan, np.array([centre]), "exact")
    dots = np.einsum("ij,ij->i", oracle_normals(v, tri), oracle_normals(plan.positions, tri))
    assert np.all(dots > 0)
    assert stats.shortened == 1 and stats.accepted == 1
    assert plan.positions[centre, 1] > 2.0  # it still moved towards its points


@settings(max_examples=25, deadline=None)
@given(n=st.integers(3, 5), seed=st.integers(0, 2**32 - 1), order=st.sampled_from(["colouring", "sequential"]))
def test_no_face_turns_over_under_random_plans(n, seed, order):
    """Points anywhere around a jittered grid, each on a random vertex: the
    targets pull vertices across their neighbours, yet no face turns over."""
    rng = np.random.default_rng(seed)
    v, tri = grid(n, jitter=0.25, seed=seed)
    m = int(rng.integers(10 * n, 20 * n))
    points = np.c_[rng.uniform(-1.0, n, (m, 2)), rng.normal(scale=0.3, size=m)]
    with jax.enable_x64(True):
        plan = plan_on_grid(v, tri, points, rng.integers(0, n * n, m))
        for k in range(2):
            relocation_pass(plan, "exact", order, np.random.default_rng([seed, k]))
    dots = np.einsum("ij,ij->i", oracle_normals(v, tri), oracle_normals(plan.positions, tri))
    assert np.all(dots > 0), np.sort(dots)[:3]


def test_random_plans_do_move_vertices():
    """The random-plan check above is not vacuous: vertices move, some far."""
    rng = np.random.default_rng(1)
    v, tri = grid(5, jitter=0.25, seed=1)
    points = np.c_[rng.uniform(-1.0, 5, (80, 2)), rng.normal(scale=0.3, size=80)]
    with jax.enable_x64(True):
        plan = plan_on_grid(v, tri, points, rng.integers(0, 25, 80))
        s = relocation_pass(plan, "exact", "colouring", np.random.default_rng(0))
    assert s.accepted > 5 and s.shortened > 0
    assert np.max(np.linalg.norm(plan.positions - v, axis=1)) > 0.3
