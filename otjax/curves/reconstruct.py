"""``reconstruct_curve``: the 2D pipeline of de Goes et al. 2011, end to end.

Points -> Delaunay triangulation inside a pinned box -> greedy half-edge
collapses ordered by the increase of transport cost (relocating the vertices
of each modified one-ring during the last collapses) -> final relocation
passes -> optional gradient refinement -> edge filtering by relevance ->
:class:`~otjax.curves.result.CurveResult`.
"""

from __future__ import annotations

import gc
import time
from contextlib import contextmanager
from typing import NamedTuple

import jax
import numpy as np

from otjax.background import Background, estimate_background, shape_weights
from otjax.curves.decimate import QUEUES, DecimationStats, decimate, within_tolerance
from otjax.curves.end_fit import fit_ends
from otjax.curves.engine import CurveEngine
from otjax.curves.plan import TransportPlan
from otjax.curves.plan_result import result_from_plan
from otjax.curves.refinement import refine as refine_positions
from otjax.curves.result import CurveResult
from otjax.curves.thickness import local_thickness
from otjax.curves.triangulation import Triangulation
from otjax.decimation.relocation import relocate
from otjax.frame import Frame, to_canonical
from otjax.validation import check_number, check_points, check_target


BACKGROUNDS = ("auto", "none")
# The size rules of the defaults (docs/decisions.md#default_initial_vertices, #default_queue).
INITIAL_CAP = 2000
INITIAL_FLOOR = 300
POINTS_PER_INITIAL_VERTEX = 3
INITIAL_PER_VERTEX = 20
NOISY_THICKNESS = 0.5
EXHAUSTIVE_COLLAPSES = 4000
LAZY_COLLAPSES = 1500
# During a run the youngest GC generation is collected every this many
# allocations rather than every 700: the decimation makes millions of small
# tuples, and every collection also runs JAX's GC hook and, every tenth,
# walks the older generation (about a tenth of a run's host time at 700).
GC_YOUNG = 20_000


def reconstruct_curve(points, masses=None, n_vertices: int | None = None, *, tolerance: float | None = None,
                      relevance: float = 0.0, density: float = 0.0, background: str = "auto",
                      chords: bool = True, fit_ends: bool = True, relocation: int | None = 100,
                      final_relocations: int = 4, refine: bool = False, queue: str | None = None,
                      choices: int = 15, round_fraction: float = 0.05, initial_vertices: int | None = None,
                      seed: int = 0, merge_duplicates: bool = False, progress: bool = False) -> CurveResult:
    """Reconstructs a curve (vertices and edges) from a weighted 2D point set.

    Args:
      points: ``(n, 2)`` input points.
      masses: ``(n,)`` non-negative masses (default: all ones).
      n_vertices: target vertex count of the simplification (``>= 1``).
      tolerance: tolerance mode (paper §3.5): discard every collapse that would make some edge's RMS normal
        or tangential transport distance exceed this (input units); stops when no collapse is left. May be
        combined with ``n_vertices`` (whichever stops first). It bounds the root mean square over each
        edge's points, not the maximum the paper speaks of: single points can end up farther than the
        tolerance.
      relevance: keep only solid edges whose relevance ``M_e |e|^2 / (N_e + T_e)`` (paper §3.4) is at least
        this; ``0`` keeps every solid edge.
      density: keep only solid edges whose mass per unit length ``M_e/|e|`` is at least this fraction (in
        ``[0, 1]``) of the largest one. Not in the paper: its relevance does not depend on density at all
        (``M_e`` cancels against ``N_e + T_e``), so it cannot tell a sparse outlier edge from a dense one on
        the shape (docs/benchmarks.md#outliers-relevance-against-density).
      background: ``"auto"``: estimate uniform background noise from the points
        (:func:`otjax.background.estimate_background`); where there is some, each point's mass is scaled by
        its share of shape (:func:`otjax.background.shape_weights`) before the reconstruction, and edges and isolated vertices that do
        not stand out of the background are dropped at the end
        (:func:`otjax.curves.filtering.above_background`). Without background (clean or merely noisy input)
        nothing changes. ``"none"``: no estimate.
      chords: drop the redundant chords of 3-cycles of solid edges and the spurs at junctions
        that noise leaves (:func:`otjax.curves.filtering.redundant_edges`).
      fit_ends: move each open end, last, to where its points end (:func:`otjax.curves.end_fit.fit_ends`).
      relocation: relocate the vertices of the modified one-ring after each of the last ``relocation``
        collapses (paper and default: 100); ``None``: after every collapse (as the C++ reference does);
        ``0`` disables. Ignored in pure tolerance mode, where the end is not known ahead.
      final_relocations: relocation passes over every vertex at the end (fewer if a pass moves none).
      refine: after the closed form, refine all vertex positions by L-BFGS on the fixed-assignment cost
        (kept only if the cost does not rise).
      queue: ``None``: :func:`default_queue`; ``"exhaustive"`` (the paper's default), ``"multiple-choice"``
        (paper §3.5: the best of ``choices`` random half-edges per step, exhaustive below 5x the target),
        ``"parallel"`` or ``"lazy"`` (not in the paper): see :mod:`otjax.decimation.loop`.
      choices: half-edges drawn per multiple-choice step (paper: typically 10; docs/decisions.md#choices).
      round_fraction: parallel queue: a round collapses at most this fraction of the collapses still to do
        (docs/decisions.md#round_fraction).
      initial_vertices: size of the random subset of the points that becomes the initial triangulation
        (paper §3.5); every point still carries its mass. ``None``: :func:`default_initial_vertices`.
      seed: seed of the random subset and of the multiple-choice draws; same seed, same result.
      merge_duplicates: merge repeated points by summing their masses instead of rejecting them.
      progress: show a progress bar.

    Returns:
      A :class:`CurveResult` in the input's units. The run computes in a canonical frame
      (:mod:`otjax.frame`), so an input scaled by a power of two gives the scaled result bitwise. Where the
      total cost does not fit float64's normal range in input units (coordinates near ``1e160``, tiny
      masses), ``total_cost * 2**params["cost_exponent"]`` is the cost.

    Raises:
      ValueError: invalid points, masses or parameters (the message says which and why).

    Example:
      >>> from otjax.datasets import star
      >>> pts, _ = star(400, noise=0.005)
      >>> r = reconstruct_curve(pts, n_vertices=10)
      >>> len(r.vertices), len(r.edges)
      (10, 10)
    """
    t_start = time.perf_counter()
    points, masses = check_points(points, masses, dim=2, merge_duplicates=merge_duplicates)
    params = _check_params(points, n_vertices=n_vertices, tolerance=tolerance, relevance=relevance,
                           density=density, background=background, chords=chords, fit_ends=fit_ends,
                           relocation=relocation, final_relocations=final_relocations, refine=refine,
                           queue=queue, choices=choices, round_fraction=round_fraction,
                           initial_vertices=initial_vertices, seed=seed, merge_duplicates=merge_duplicates)
    given = _in_frame(points, masses, params["background"])
    # Point location is exact float64 arithmetic: the whole run is in JAX's x64 mode, for its duration only.
    with jax.enable_x64(True), _fewer_collections():
        run = _run(given.points, given.transported, _params_in_frame(params, given.frame), progress)
    result = _filtered(run.engine.plan, params, given, time.perf_counter() - t_start)
    return _in_input_units(result, given.frame, points, _history(run, given.noise))


@contextmanager
def _fewer_collections():
    """The youngest generation's GC threshold raised to :data:`GC_YOUNG`
    for the duration, restored after (left alone where it is 0: off)."""
    old = gc.get_threshold()
    if old[0]:
        gc.set_threshold(max(old[0], GC_YOUNG), *old[1:])
    try:
        yield
    finally:
        gc.set_threshold(*old)


class _InFrame(NamedTuple):
    """The validated input in the canonical frame (:mod:`otjax.frame`).

    Attributes:
      frame: the frame.
      points: ``(n, 2)`` the points in it.
      masses: ``(n,)`` their masses in it.
      noise: the estimated background, or ``None``.
      transported: ``masses`` scaled by :func:`otjax.background.shape_weights`.
    """

    frame: Frame
    points: np.ndarray
    masses: np.ndarray
    noise: Background | None
    transported: np.ndarray


def _in_frame(points: np.ndarray, masses: np.ndarray, background: str) -> _InFrame:
    """Validated input moved to the canonical frame, so that nothing below
    depends on the input's units, and its background discounted."""
    frame, points, masses = to_canonical(points, masses)
    noise, transported = _discount_background(points, masses, background)
    return _InFrame(frame, points, masses, noise, transported)


def _discount_background(points, masses, mode: str):
    """``(background or None, masses scaled by their shape weights)``."""
    if mode != "auto":
        return None, masses
    noise = estimate_background(points)
    return noise, masses * shape_weights(noise) if noise.found else masses


def _check_params(points: np.ndarray, *, n_vertices, tolerance, relevance, density, background, chords, fit_ends,
                  relocation, final_relocations, refine, queue, choices, round_fraction, initial_vertices, seed,
                  merge_duplicates) -> dict:
    """The validated parameters of :func:`reconstruct_curve`, as its result's ``params``
    (``points``: the validated input, read for the default initial subset)."""
    n_points = len(points)
    if n_vertices is None and tolerance is None:
        raise ValueError("give n_vertices (a target vertex count) or tolerance (or both)")
    if n_vertices is not None:
        check_target(n_vertices, n_points, minimum=1)
        n_vertices = int(n_vertices)
    tolerance = check_number("tolerance", tolerance, allow_none=True)
    if tolerance is not None and tolerance <= 0:
        raise ValueError(f"tolerance must be > 0, got {tolerance}")
    relevance = check_number("relevance", relevance)
    density = check_number("density", density)
    if density > 1:
        raise ValueError(f"density must be in [0, 1], got {density}")
    if background not in BACKGROUNDS:
        raise ValueError(f"background must be one of {', '.join(BACKGROUNDS)}, got {background!r}")
    relocation = check_number("relocation", relocation, integer=True, allow_none=True)
    final_relocations = check_number("final_relocations", final_relocations, integer=True)
    seed = check_number("seed", seed, integer=True)
    if queue is not None and queue not in QUEUES:
        raise ValueError(f"queue must be one of {', '.join(QUEUES)}, got {queue!r}")
    choices = check_number("choices", choices, minimum=1, integer=True)
    round_fraction = check_number("round_fraction", round_fraction)
    if not 0 < round_fraction <= 1:
        raise ValueError(f"round_fraction must be in (0, 1], got {round_fraction}")
    if initial_vertices is None:
        exact = default_initial_vertices(n_points, n_vertices, noisy=False)
        initial_vertices = default_initial_vertices(n_points, n_vertices)
        # The thickness is measured only where the two rules differ.
        if initial_vertices != exact and local_thickness(points) <= NOISY_THICKNESS:
            initial_vertices = exact
    initial_vertices = check_number("initial_vertices", initial_vertices, minimum=1, integer=True)
    if n_vertices is not None and initial_vertices < n_vertices:
        raise ValueError(f"initial_vertices ({initial_vertices}) must be >= n_vertices ({n_vertices})")
    initial_vertices = min(initial_vertices, n_points)
    if queue is None:
        queue = default_queue(initial_vertices, n_vertices)
    return {"n_vertices": n_vertices, "tolerance": tolerance, "relevance": relevance, "density": density,
            "background": background, "chords": bool(chords), "fit_ends": bool(fit_ends),
            "relocation": relocation, "final_relocations": final_relocations, "refine": bool(refine),
            "queue": queue, "choices": choices, "round_fraction": round_fraction,
            "initial_vertices": initial_vertices,
            "seed": seed, "merge_duplicates": bool(merge_duplicates), "n_points": n_points}


class _Outcome(NamedTuple):
    """What the pipeline's steps leave: the engine and what they did."""

    engine: CurveEngine
    stats: DecimationStats
    seconds: dict
    relocations: int
    refined: dict | None
    ends: int


def _run(points, masses, params: dict, progress: bool) -> _Outcome:
    """The pipeline's steps on validated input (``params``): initial
    triangulation, decimation, final relocation passes, refinement, end fit."""
    timings = {}
    t0 = time.perf_counter()
    rng = np.random.default_rng(params["seed"])
    engine = _triangulate(points, masses, params["initial_vertices"], rng)
    timings["init"] = time.perf_counter() - t0
    relocation = params["relocation"]
    stats = decimate(engine, params["n_vertices"], tolerance=params["tolerance"],
                     relocation=len(points) if relocation is None else relocation,
                     queue=params["queue"], choices=params["choices"], round_fraction=params["round_fraction"],
                     seed=int(rng.integers(2**63)), progress=progress)
    timings.update(stats.seconds)
    t0 = time.perf_counter()
    moved = stats.relocations + _final_relocations(engine, params["tolerance"], params["final_relocations"])
    timings["final_relocation"] = time.perf_counter() - t0
    stats.kernel_calls = engine.scorer.calls
    refined = None
    if params["refine"]:
        t0 = time.perf_counter()
        before = engine
        engine, refined = refine_positions(engine)
        if engine is not before:
            stats.kernel_calls += engine.scorer.calls
        timings["refine"] = time.perf_counter() - t0
    ends = 0
    if params["fit_ends"]:
        t0 = time.perf_counter()
        tolerance = params["tolerance"]
        ends = fit_ends(engine, within_tolerance(tolerance) if tolerance is not None else None)
        timings["end_fit"] = time.perf_counter() - t0
    return _Outcome(engine, stats, timings, moved, refined, ends)


def _triangulate(points: np.ndarray, masses: np.ndarray, initial_vertices: int,
                 rng: np.random.Generator) -> CurveEngine:
    """The engine over the initial triangulation: a random subset of
    ``initial_vertices`` of the points (all of them if that is all)."""
    if initial_vertices < len(points):
        subset = np.sort(rng.choice(len(points), initial_vertices, replace=False))
        vertices = points[subset]
    else:
        vertices = points
    return CurveEngine(Triangulation(vertices), points, masses)


def _final_relocations(engine: CurveEngine, tolerance: float | None, passes: int) -> int:
    """Relocation passes over every live vertex, until one moves none; the
    vertices moved."""
    veto = within_tolerance(tolerance) if tolerance is not None else None
    moved = 0
    for _ in range(passes):
        m = relocate(engine, engine.live_sources(), veto).moved
        moved += m
        if m == 0:
            break
    return moved


def _filtered(plan: TransportPlan, params: dict, given: _InFrame, seconds: float) -> CurveResult:
    """The result of the finished ``plan``: its edges filtered as ``params`` say
    (:func:`~otjax.curves.plan_result.result_from_plan`), in the canonical frame."""
    return result_from_plan(plan, params["relevance"], params, seconds, params["density"],
                            background=given.noise, input_mass=given.masses, chords=params["chords"])


def _history(run: _Outcome, noise: Background | None) -> dict:
    """The result's ``history``: what the run did."""
    stats = run.stats
    return {"collapses": stats.collapses, "relocations": run.relocations, "scored": stats.scored,
            "updated": stats.updated, "kernel_calls": stats.kernel_calls, "seconds": run.seconds,
            "rounds": stats.rounds, "switched_at": stats.switched_at,
            "compiled_shapes": run.engine.compiled_shapes,
            "refine": run.refined, "ends_fitted": run.ends,
            "background_fraction": noise.fraction if noise is not None else 0.0}


def default_initial_vertices(n_points: int, n_vertices: int | None, noisy: bool = True) -> int:
    """Initial vertex count used when ``initial_vertices`` is not given.

    Given a target and noisy points: a random subset of a third of the
    points, at least 300 and at most 2000 (every point up to 300 points).
    Exact samples (``noisy`` false) and tolerance mode (no target): every
    point up to 2000 points, else 2000. Either way 20 per target vertex
    where that is more. On noisy points a larger subset mostly adds
    collapses and ends less accurate; on exact samples it keeps the corners'
    own points (docs/decisions.md#default_initial_vertices). In tolerance
    mode every point keeps the bound from the start: no edge carries a point.
    :func:`reconstruct_curve` calls points noisy where their
    :func:`~otjax.curves.thickness.local_thickness` exceeds
    :data:`NOISY_THICKNESS`.
    """
    subset = INITIAL_CAP
    if noisy and n_vertices is not None:
        share = -(-n_points // POINTS_PER_INITIAL_VERTEX)
        subset = min(INITIAL_CAP, max(INITIAL_FLOOR, share))
    return min(n_points, max(subset, INITIAL_PER_VERTEX * (n_vertices or 0)))


def default_queue(initial_vertices: int, n_vertices: int | None) -> str:
    """Queue used when ``queue`` is not given, by the run's collapses
    (``initial_vertices - n_vertices``; tolerance mode counts all of them):
    ``"exhaustive"`` up to :data:`LAZY_COLLAPSES`, ``"lazy"`` (its last
    collapses exhaustive) up to :data:`EXHAUSTIVE_COLLAPSES` given a target
    (``"exhaustive"`` without one), ``"multiple-choice"`` above, where it is
    about twice as fast for the same cost (docs/decisions.md#default_queue)."""
    collapses = initial_vertices - (n_vertices or 0)
    if collapses > EXHAUSTIVE_COLLAPSES:
        return "multiple-choice"
    return "lazy" if n_vertices is not None and collapses > LAZY_COLLAPSES else "exhaustive"


# Canonical distances are below the pinned box's diagonal (< 4): any larger tolerance vetoes
# nothing, and capping it keeps its square finite.
_TOLERANCE_CAP = 2.0**32


def _params_in_frame(params: dict, frame: Frame) -> dict:
    """``params`` with the tolerance (a length) in canonical units."""
    if params["tolerance"] is None:
        return params
    return {**params, "tolerance": min(frame.length_in(params["tolerance"]), _TOLERANCE_CAP)}


def _in_input_units(result: CurveResult, frame: Frame, points: np.ndarray, history: dict) -> CurveResult:
    """``result`` (computed in ``frame``) with vertices, masses and cost in
    the input's units, and ``history``."""
    cost, exponent = frame.cost_out(result.total_cost)
    params = result.params if exponent == 0 else {**result.params, "cost_exponent": exponent}
    return CurveResult(vertices=frame.points_out(result.vertices), edges=result.edges, isolated=result.isolated,
                       edge_mass=frame.masses_out(result.edge_mass), edge_relevance=result.edge_relevance,
                       total_cost=cost, params=params, seconds=result.seconds, points=points,
                       masses=frame.masses_out(result.masses), history=history)
