"""Fuzzing reconstruct_curve: malformed and extreme points, masses and
parameters give one ValueError naming the problem or a structurally sound
result; never another exception, never a warning.

Most examples stop right after validation (a spy replaces the pipeline's
run and checks what it would have been given); a few tiny inputs run to
the end."""

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

import otjax.curves.reconstruct as reconstruct_module
from otjax.curves.decimate import QUEUES
from otjax.frame import CENTRE_BITS
from otjax.curves.reconstruct import reconstruct_curve
from tests.fuzz.strategies import check_result, warnings_are_errors
from tests.profiles import examples


class Validated(Exception):
    """Raised by the spy in place of the run: validation passed."""


EXTREMES = [0.0, -0.0, 1.0, -1.0, 1e-300, 5e-324, -5e-324, 2.2250738585072014e-308, 1e300, -1e300,
            1.7976931348623157e308, 2.0**1022, 1e160, 1e-160, 1e12, 1e12 + 0.5, float("nan"), float("inf"),
            float("-inf")]
coordinate = st.one_of(st.floats(width=64), st.sampled_from(EXTREMES), st.integers(-3, 3).map(float))
# Finite, from ordinary to extreme: the inputs that get past the first checks.
finite_coordinate = st.one_of(st.floats(allow_nan=False, allow_infinity=False, width=64),
                              st.sampled_from([x for x in EXTREMES if np.isfinite(x)]),
                              st.floats(-10, 10), st.integers(-3, 3).map(float))


@st.composite
def point_arrays(draw):
    """Arrays of many shapes, dtypes and degeneracies; mostly ``(n, 2)`` floats."""
    kind = draw(st.sampled_from(["finite"] * 6 + ["floats"] * 2 + ["few values", "line", "grid", "shape", "dtype",
                                                                   "nested"]))
    n = draw(st.integers(0, 40))
    if kind in ("finite", "floats"):
        c = finite_coordinate if kind == "finite" else coordinate
        rows = st.lists(st.tuples(c, c), min_size=n, max_size=n, unique=kind == "finite" and draw(st.booleans()))
        return np.array(draw(rows), np.float64).reshape(-1, 2)
    if kind == "few values":  # duplicate heavy
        values = draw(st.lists(coordinate, min_size=1, max_size=3))
        return np.array(draw(st.lists(st.tuples(st.sampled_from(values), st.sampled_from(values)), min_size=n,
                                      max_size=n)), np.float64).reshape(-1, 2)
    if kind == "line":  # exactly collinear, possibly with a translation and a scale
        t = np.array(draw(st.lists(st.integers(-50, 50), min_size=n, max_size=n)), np.float64)
        a, b = draw(coordinate), draw(coordinate)
        scale = draw(st.sampled_from([1.0, 1e-300, 1e300, 3.0]))
        with np.errstate(all="ignore"):
            return np.stack([a + scale * t, b - 2 * scale * t], 1)
    if kind == "grid":  # many collinear and cocircular points
        k = draw(st.integers(2, 6))
        g = np.stack(np.meshgrid(np.arange(k), np.arange(k)), -1).reshape(-1, 2).astype(np.float64)
        return g * draw(st.sampled_from([1.0, 2.0**-1000, 2.0**1000, 1e-7]))
    if kind == "shape":
        shape = draw(st.lists(st.integers(0, 4), min_size=0, max_size=3))
        return np.zeros(shape) + draw(st.floats(-1, 1))
    if kind == "dtype":
        base = np.arange(2 * max(n, 3), dtype=np.float64).reshape(-1, 2) % 7
        dtype = draw(st.sampled_from([np.int8, np.uint64, np.float16, np.float32, bool, complex, object, str]))
        return base.astype(dtype)
    return draw(st.sampled_from([[[0, 0], [1, 0], [0, "x"]], [[0, 0], [1], [0, 1]], "points", None, 3.0,
                                 [[0, 0], [1, 0], [0, None]], [[[0, 0]]], {"a": 1}]))


@st.composite
def mass_arrays(draw, n: int):
    kind = draw(st.sampled_from(["none"] * 4 + ["positive", "positive", "floats", "extreme", "shape", "zero"]))
    if kind == "none":
        return None
    if kind == "positive":
        return np.array(draw(st.lists(st.floats(1e-3, 1e6), min_size=n, max_size=n)), np.float64)
    if kind == "floats":
        return np.array(draw(st.lists(st.floats(width=64), min_size=n, max_size=n)), np.float64)
    if kind == "extreme":
        return np.array(draw(st.lists(st.sampled_from([1.0, 1e-320, 5e-324, 1e-300, 1e300, 1.7e308, 0.0, -0.0]),
                                      min_size=n, max_size=n)), np.float64)
    if kind == "zero":
        return np.zeros(n)
    return np.ones(draw(st.integers(0, n + 2)))


absurd_int = st.one_of(st.integers(-5, 60), st.just(10**30), st.floats(allow_nan=True), st.booleans(),
                       st.text(max_size=3), st.none())
absurd_float = st.one_of(st.floats(allow_nan=True), st.integers(-3, 3), st.just(10**400), st.text(max_size=3),
                         st.none(), st.booleans())


@st.composite
def parameters(draw):
    """A random subset of reconstruct_curve's keyword arguments, with valid and absurd values."""
    options = {
        "n_vertices": absurd_int,
        "tolerance": absurd_float,
        "relevance": absurd_float,
        "density": absurd_float,
        "background": st.sampled_from(["auto", "none", "AUTO", "", None, 1]),
        "chords": st.one_of(st.booleans(), st.none(), st.just("no")),
        "relocation": absurd_int,
        "final_relocations": absurd_int,
        "refine": st.booleans(),
        "queue": st.sampled_from(list(QUEUES) + [None, "Exhaustive", "", 3]),
        "choices": absurd_int,
        "round_fraction": absurd_float,
        "initial_vertices": absurd_int,
        "seed": st.one_of(st.integers(-(2**70), 2**70), absurd_int),
        "merge_duplicates": st.one_of(st.booleans(), st.just("yes")),
    }
    chosen = draw(st.lists(st.sampled_from(sorted(options)), unique=True, max_size=draw(st.sampled_from([0, 1, 6]))))
    params = {name: draw(options[name]) for name in chosen}
    if draw(st.integers(0, 3)):  # mostly a plausible target and merging, so that more inputs get past them
        params["n_vertices"] = draw(st.integers(1, 6))
    if draw(st.booleans()):
        params["merge_duplicates"] = True
    return params


@pytest.fixture
def stop_after_validation(monkeypatch):
    """Replaces the run by a spy that checks its arguments and raises :class:`Validated`."""
    seen = []

    def spy(points, masses, params, progress):
        assert points.ndim == 2 and points.shape[1] == 2 and len(points) >= 3
        assert np.isfinite(points).all() and np.abs(points).max() < 0.5 + 2.0**-CENTRE_BITS  # the canonical frame
        assert len(np.unique(points, axis=0)) == len(points)
        assert masses.shape == (len(points),) and np.isfinite(masses).all() and np.all(masses >= 0)
        assert masses.sum() > 0
        n_vertices, tolerance = params["n_vertices"], params["tolerance"]
        assert n_vertices is not None or tolerance is not None
        if n_vertices is not None:
            assert 1 <= n_vertices <= params["initial_vertices"] <= len(points)
        if tolerance is not None:
            # In canonical units: 0 where the input's tolerance is below float64 at this scale
            # (its square was 0 already), capped where it is longer than the box.
            assert np.isfinite(tolerance) and tolerance >= 0 and tolerance**2 < np.inf
        assert params["queue"] in QUEUES
        seen.append(len(points))
        raise Validated

    monkeypatch.setattr(reconstruct_module, "_run", spy)
    return seen


# The spy holds no state between examples: one monkeypatch serves them all.
@settings(max_examples=examples(400, 4000), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=st.data())
def test_validation_of_malformed_and_extreme_input(stop_after_validation, data):
    points = data.draw(point_arrays(), label="points")
    n = len(points) if isinstance(points, np.ndarray) and points.ndim >= 1 else 3
    masses = data.draw(mass_arrays(n), label="masses")
    params = data.draw(parameters(), label="params")
    try:
        with warnings_are_errors():
            reconstruct_curve(points, masses, **params, progress=False)
    except ValueError as err:
        message = str(err)
        assert message.strip() and len(message) < 1000, message  # names the problem, readably
        event("refused: " + message[:50])
        return
    except Validated:
        event("validated")
        return
    raise AssertionError("reconstruct_curve returned without running")  # the spy always raises


@st.composite
def plausible_inputs(draw):
    """Distinct finite points anywhere in float64's range (scaled, translated, clustered),
    masses from subnormal to huge, sane parameters: what should mostly pass validation."""
    n = draw(st.integers(3, 40))
    seed = draw(st.integers(0, 2**32 - 1))
    rng = np.random.default_rng(seed)
    shape = draw(st.sampled_from(["uniform", "line", "cluster", "grid"]))
    pts = rng.random((n, 2))
    if shape == "line":
        pts[:, 1] = 0.5 * pts[:, 0]
    elif shape == "cluster":
        pts[: n // 2] = 0.5 + 1e-9 * pts[: n // 2]
    elif shape == "grid":
        pts = np.floor(pts * 5)
    with np.errstate(all="ignore"):
        pts = pts * draw(st.sampled_from([1.0, 2.0**-1000, 2.0**1000, 1e-300, 1e300, 1e-160, 1e160]))
        pts = pts + draw(st.sampled_from([0.0, 0.0, 1e12, -3e15, 1e300]))
    masses = draw(st.sampled_from([None, "ones", "random", "tiny", "huge", "mixed"]))
    masses = {None: None, "ones": np.ones(n), "random": rng.random(n), "tiny": np.full(n, 1e-320),
              "huge": np.full(n, 1e307), "mixed": rng.choice([0.0, 1e-300, 1.0, 1e300], n)}[masses]
    params = {"n_vertices": draw(st.integers(1, n)), "merge_duplicates": True,
              "tolerance": draw(st.sampled_from([None, 1e-300, 1e-3, 0.5, 1e300])),
              "queue": draw(st.sampled_from([None, *QUEUES])), "background": draw(st.sampled_from(["auto", "none"])),
              "initial_vertices": draw(st.sampled_from([None, n]))}
    return pts, masses, params


@settings(max_examples=examples(300, 3000), suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=plausible_inputs())
def test_validation_of_plausible_input_anywhere_in_float64(stop_after_validation, data):
    points, masses, params = data
    try:
        with warnings_are_errors():
            reconstruct_curve(points, masses, **params, progress=False)
    except ValueError as err:
        event("refused: " + str(err)[:50])
        assert str(err).strip() and len(str(err)) < 1000
        return
    except Validated:
        event("validated")
        return
    raise AssertionError("reconstruct_curve returned without running")


@st.composite
def tiny_inputs(draw):
    """3-10 points on a small integer grid (duplicates, lines, cocircular sets), scaled anywhere."""
    n = draw(st.integers(3, 10))
    pts = np.array(draw(st.lists(st.tuples(st.integers(0, 4), st.integers(0, 4)), min_size=n, max_size=n)),
                   np.float64)
    scale = draw(st.sampled_from([1.0, 2.0**-900, 2.0**900, 1e-300, 1e300, 7.0]))
    shift = draw(st.sampled_from([0.0, 1e9, -3.5]))
    masses = draw(st.one_of(st.none(), st.lists(st.sampled_from([0.0, 1.0, 2.5, 1e-300]), min_size=n, max_size=n)
                            .map(lambda m: np.array(m) if sum(m) > 0 else None)))
    return pts * scale + shift * scale, masses


@settings(max_examples=examples(12, 120))
@given(data=tiny_inputs(), n_vertices=st.integers(1, 6), background=st.sampled_from(["auto", "none"]),
       queue=st.sampled_from(QUEUES), tolerance=st.sampled_from([None, 0.3, 1e-9]))
def test_tiny_inputs_run_to_a_sound_result(data, n_vertices, background, queue, tolerance):
    points, masses = data
    total = float(np.sum(masses)) if masses is not None else float(len(points))
    try:
        with warnings_are_errors():
            result = reconstruct_curve(points, masses, n_vertices, tolerance=tolerance, background=background,
                                       queue=queue, merge_duplicates=True)
    except ValueError as err:
        assert str(err)
        return
    scale = float(np.max(np.abs(points))) or 1.0
    check_result(result, len(points), total)
    assert np.abs(result.vertices).max() <= 4 * scale  # near the points, in the input's units
