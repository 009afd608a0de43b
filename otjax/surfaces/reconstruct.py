"""``reconstruct_surface``: the 3D pipeline of Digne et al. 2014 (Algorithm 1).

Points (uniform background noise discounted) -> canonical frame -> initial
complex (Delaunay of a subset, relaxed transport, facets with mass; §4.1)
-> (re-binned) -> greedy half-edge
collapses by increase of transport cost (§4.2, the shared loop of
:mod:`otjax.decimation`), relocating the remaining vertex and its
neighbours after each of the last collapses (§4.3) -> T-junctions closed
-> the final complex re-binned at a finer quadrature -> relocation passes
over every vertex -> arrays in the input's units.
"""

from __future__ import annotations

import time
from typing import NamedTuple

import jax
import numpy as np

from otjax.background import NEIGHBOURS, estimate_background, near_shape, point_normals, shape_weights
from otjax.decimation.loop import QUEUES, DecimationStats, decimate
from otjax.decimation.relocation import relocate
from otjax.frame import to_canonical
from otjax.surfaces.bins import DEFAULT_DENSITY, facet_areas
from otjax.surfaces.border_fit import fit_border
from otjax.surfaces.caps import remove_caps
from otjax.surfaces.complex import SimplicialComplex
from otjax.surfaces.crease_fit import fit_creases
from otjax.surfaces.engine import SurfaceEngine
from otjax.surfaces.fit_input import points_noise
from otjax.surfaces.initial_complex import FRACTION, initial_complex, initial_settings
from otjax.surfaces.plan import BinSettings, Entries, SurfacePlan
from otjax.surfaces.relaxation import relax
from otjax.surfaces.result import SurfaceResult
from otjax.surfaces.solvers import LocalSolver, default_solver
from otjax.surfaces.t_junctions import close_t_junctions, split_slivers
from otjax.surfaces.transverse import remove_transverse
from otjax.validation import check_number, check_points, check_target

SOLVERS = ("batched", "exact")
BACKGROUNDS = ("auto", "none")
#: Re-bin the initial complex with the default density before decimating
#: (docs/decisions.md#surface_rebin).
REBIN = False
#: Relaxation sweeps after re-binning.
REBIN_SWEEPS = 2
#: Collapses, counted from the end, after which the kept vertex and its
#: neighbours are relocated (docs/decisions.md#surface_relocation_schedule).
RELOCATE_LAST = 100
#: Relocation passes over every vertex after the decimation, at most.
FINAL_RELOCATIONS = 4
#: The final passes' bin density, in multiples of the decimation's
#: (docs/decisions.md#final_density).
FINAL_DENSITY_FACTOR = 4.0


class SurfaceReconstruction(NamedTuple):
    """What :func:`reconstruct_surface` returns (input units).

    Attributes:
      vertices: ``(V, 3)`` float64 live vertex positions.
      triangles: ``(T, 3)`` int64 rows into ``vertices``.
      edges: ``(0, 2)`` int64: edges carry no mass (the transport has facet
        and vertex bins only), so the complex's edges of no triangle, chords
        left by collapses, are no part of the surface (``complex`` has them).
      isolated: ``(I,)`` int64 rows of vertices in no triangle that carry mass.
      triangle_mass: ``(T,)`` float64 mass transported onto each triangle.
      triangle_area: ``(T,)`` float64 area of each triangle.
      total_cost: the plan's transport cost (mass times squared length);
        the cost is ``total_cost * 2**cost_exponent``.
      cost_exponent: 0 unless the cost does not fit float64 in input units.
      plan: the :class:`SurfacePlan` (canonical frame; research use).
      complex: its :class:`SimplicialComplex` (canonical frame).
      vertex_ids: ``(V,)`` int64 id of each vertex row in ``complex``.
      stats: the :class:`DecimationStats` (``relocations``: moves
        applied during the decimation, in the final passes and by the feature fit).
      seconds: wall time of ``initial``, ``rebin``, ``decimation``,
        ``final_rebin``, ``final_relocation``, ``feature_fit``.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    edges: np.ndarray
    isolated: np.ndarray
    triangle_mass: np.ndarray
    triangle_area: np.ndarray
    total_cost: float
    cost_exponent: int
    plan: SurfacePlan
    complex: SimplicialComplex
    vertex_ids: np.ndarray
    stats: DecimationStats
    seconds: dict

    def to_result(self, params: dict | None = None) -> SurfaceResult:
        """The user-facing :class:`SurfaceResult` (files, plots, density
        filtering) of these arrays; ``params`` are recorded with it."""
        return SurfaceResult(vertices=self.vertices, triangles=self.triangles, triangle_mass=self.triangle_mass,
                             edges=self.edges, isolated=self.isolated, total_cost=self.total_cost,
                             params={**(params or {}), "cost_exponent": self.cost_exponent},
                             seconds=float(sum(self.seconds.values())), stats=self.stats)


def reconstruct_surface(points, masses=None, n_vertices: int = 100, *, queue: str = "multiple-choice",
                        choices: int = 40, switch_factor: float = 1.0, seed: int = 0, solver: str | None = None,
                        fraction: float = FRACTION, bin_density: float = DEFAULT_DENSITY, rebin: bool = REBIN,
                        max_sweeps: int = 10, background: str = "auto",
                        relocation: int | None = RELOCATE_LAST, final_relocations: int = FINAL_RELOCATIONS,
                        final_density_factor: float = FINAL_DENSITY_FACTOR, fit_features: bool = True,
                        progress: bool = False) -> SurfaceReconstruction:
    """Reconstructs a surface (triangles, plus edges and isolated vertices) from 3D points.

    Args:
      points: ``(N, 3)`` finite coordinates (distinct).
      masses: ``(N,)`` positive masses (default: ones).
      n_vertices: vertices to keep (``>= 4``, at most the initial complex's).
      queue: the decimation queue (:data:`otjax.decimation.loop.QUEUES`).
      choices: half-edges drawn per multiple-choice step (the paper's 40).
      switch_factor: multiple choice hands over to the exhaustive queue
        below this many times ``n_vertices`` (1: never, as in the paper).
      seed: seeds the subset, bins and draws; same seed, same result.
      solver: ``"batched"`` (JAX batches, HiGHS for members they do not certify) or ``"exact"`` (HiGHS
        for every local LP); ``None`` (default): :func:`surface_solver`, HiGHS on a CPU.
      fraction: share of the points in the initial Delaunay (§4.1).
      bin_density: facet bins per squared bbox diagonal of facet area (the paper's quadrature; 1 to 32 bins
        a facet). Higher: a finer cost and sharper creases at small budgets, larger LPs (docs/benchmarks.md).
      rebin: give every facet the default bins before decimating.
      max_sweeps: relaxation sweeps of the initial complex at most.
      background: ``"auto"``: uniform background noise (:func:`otjax.background.estimate_background`) discounted:
        masses times shape shares (:func:`~otjax.background.shape_weights`), points of none or off the plane
        of their neighbours (:func:`~otjax.background.near_shape`) left out; ``"none"``: all transported.
      relocation: relocate the vertex a collapse keeps and its neighbours (§4.3: alternations of the
        closed-form target, a move half way there, a re-solve of its star; kept where the cost falls) after
        each of the last ``relocation`` collapses (default :data:`RELOCATE_LAST`); ``None``: after every
        collapse, as the paper does; 0: never during the decimation.
      final_relocations: relocation passes over every vertex after the
        decimation (fewer if a pass moves none; 0: none).
      final_density_factor: the facets' bins before those passes, in multiples of ``bin_density``, the
        transport relaxed on them (the result's cost is on these; 1: the decimation's): a finer quadrature
        sharpens creases and corners (docs/decisions.md#final_density).
      fit_features: then drop facets across their points (:func:`~otjax.surfaces.remove_transverse`); with no
        background, caps too (:func:`~otjax.surfaces.remove_caps`), crease vertices (and ends) onto the
        points' planes, border ones to their end (:func:`~otjax.surfaces.fit_creases`, ``fit_border``); relax.
      progress: show a progress bar.

    Returns:
      :class:`SurfaceReconstruction` in the input's units.

    Raises:
      ValueError: bad points, masses or parameters, or ``n_vertices`` more
        than the initial complex has.

    Example:
      >>> pts = np.random.default_rng(0).random((300, 3)) * [1, 1, 0]  # doctest: +SKIP
      >>> r = reconstruct_surface(pts, n_vertices=10, solver="exact")  # doctest: +SKIP
    """
    seconds = _Laps()
    solver = surface_solver(solver)
    points, masses = _checked(points, masses, n_vertices, queue, choices, switch_factor, solver, fraction,
                              bin_density, final_density_factor, background)
    seed, relocation, final_relocations = _checked_counts(seed, relocation, final_relocations)
    shape = _shape_part(points, masses, background)
    frame, q, m = to_canonical(shape.points, shape.masses)
    method = "auto" if solver == "batched" else "exact"
    with jax.enable_x64(True):
        plan = _initial_plan(q, m, method, fraction, seed, max_sweeps, bin_density, n_vertices)
        seconds.lap("initial")
        if rebin:
            plan = rebinned(plan, BinSettings(plan.settings.diagonal, density=bin_density, seed=seed),
                            LocalSolver(method))
        seconds.lap("rebin")
        engine = SurfaceEngine(plan, method=method)
        every = plan.complex.n_vertices if relocation is None else relocation  # None: more than the collapses
        stats = decimate(engine, n_vertices, queue=queue, choices=choices, switch_factor=switch_factor, seed=seed,
                         relocation=every, progress=progress)
        seconds.lap("decimation")
        engine = _finer(engine, final_density_factor, method, changed=close_t_junctions(engine.plan) > 0)
        seconds.lap("final_rebin")
        stats.relocations += _final_passes(engine, final_relocations)
        seconds.lap("final_relocation")
        stats.relocations += _fit_features(engine.plan, q, fit_features, shape.background, method)
        seconds.lap("feature_fit")
    return _result(engine.plan, frame, stats, dict(seconds))


def _initial_plan(q, m, method, fraction, seed, max_sweeps, bin_density, n_vertices) -> SurfacePlan:
    """The plan of the initial complex (§4.1) of canonical points ``q`` and
    masses ``m``; raises where it has fewer than ``n_vertices`` vertices."""
    plan = initial_complex(q, m, LocalSolver(method), fraction=fraction, seed=seed, max_sweeps=max_sweeps,
                           settings=initial_settings(q, seed, bin_density)).plan
    if plan.complex.n_vertices < n_vertices:
        raise ValueError(f"n_vertices ({n_vertices}) exceeds the {plan.complex.n_vertices} vertices of the "
                         "initial complex; lower it or raise fraction")
    return plan


class _Laps(dict):
    """Wall time of named steps, each timed from the end of the one before
    (the first from the object's creation)."""

    def __init__(self):
        super().__init__()
        self._since = time.perf_counter()

    def lap(self, name: str) -> None:
        now = time.perf_counter()
        self[name], self._since = now - self._since, now


def _finer(engine: SurfaceEngine, factor: float, method: str, changed: bool) -> SurfaceEngine:
    """The engine on the plan re-binned at ``factor`` times its density and
    relaxed (the same engine where ``factor`` is 1 and the complex has not
    ``changed`` since the engine was made)."""
    if factor == 1 and not changed:
        return engine
    plan = engine.plan
    settings = plan.settings._replace(density=plan.settings.density * factor)
    return SurfaceEngine(rebinned(plan, settings, LocalSolver(method)), method=method)


def _final_passes(engine: SurfaceEngine, passes: int) -> int:
    """Relocation passes over every live vertex, at most ``passes``, until
    one moves none; the number of moves."""
    total = 0
    for _ in range(passes):
        moved = relocate(engine, engine.live_sources()).moved
        total += moved
        if moved == 0:
            break
    return total


def surface_solver(solver: str | None) -> str:
    """``solver``, or where it is ``None`` the default of the backend:
    ``"exact"`` on a CPU, ``"batched"`` on an accelerator
    (:func:`~otjax.surfaces.solvers.default_solver`)."""
    if solver is not None:
        return solver
    return "exact" if default_solver() == "exact" else "batched"


class ShapePart(NamedTuple):
    """The points to transport: ``points (n, 3)``, ``masses (n,)`` (``None``:
    ones) and whether uniform ``background`` noise was found and discounted."""

    points: np.ndarray
    masses: np.ndarray | None
    background: bool


def _shape_part(points: np.ndarray, masses: np.ndarray | None, background: str) -> ShapePart:
    """The :class:`ShapePart` of the input: with ``background="auto"``, where
    the points hold uniform background noise, each mass scaled by its point's
    share of shape and the points of none (or off the flat through their
    neighbours: :func:`otjax.background.near_shape`) left out; else as given."""
    if background == "none":
        return ShapePart(points, masses, False)
    found = estimate_background(points)
    if not found.found:
        return ShapePart(points, masses, False)
    weights = shape_weights(found)
    keep = (weights > 0) & near_shape(points, weights)
    return ShapePart(points[keep], (np.ones(len(points)) if masses is None else masses)[keep] * weights[keep], True)


def _fit_features(plan: SurfacePlan, points: np.ndarray, fit: bool, background: bool, method: str) -> int:
    """With ``fit``, removes the facets standing across their points'
    surface (:func:`~otjax.surfaces.transverse.remove_transverse`) and,
    without ``background``, also the caps across concave corners of the open border
    (:func:`~otjax.surfaces.caps.remove_caps`), then moves the complex's
    crease vertices and then its flat open-border vertices to the canonical
    ``points``, removes the facets the moves left lying on a line
    (:func:`~otjax.surfaces.t_junctions.split_slivers`); then relaxes the
    transport on the changed complex. Returns the number of vertices moved
    (docs/decisions.md#feature_fit)."""
    if not fit:
        return 0
    removed = remove_transverse(plan, point_normals(points, min(NEIGHBOURS, len(points) - 1)))
    moved = np.zeros(0, np.int64)
    if not background:
        removed += remove_caps(plan)
        arrays = plan.complex.to_arrays()
        noise = points_noise(points)  # one estimate for both fits
        fitted = fit_creases(arrays.vertices, arrays.triangles, points, noise=noise).vertices
        fitted = fit_border(fitted, arrays.triangles, points, noise=noise).vertices
        moved = np.flatnonzero(np.any(fitted != arrays.vertices, axis=1))
        for row in moved.tolist():
            plan.complex.move(int(arrays.vertex_ids[row]), fitted[row])
        if len(moved):
            split_slivers(plan)
    if len(moved) or removed:
        relax(plan, LocalSolver(method), max_sweeps=REBIN_SWEEPS)
    return len(moved)


def _checked_counts(seed, relocation, final_relocations) -> tuple[int, int | None, int]:
    """``(seed, relocation, final_relocations)`` checked and as ints (:func:`reconstruct_surface`)."""
    return (check_number("seed", seed, integer=True),
            check_number("relocation", relocation, minimum=0, integer=True, allow_none=True),
            check_number("final_relocations", final_relocations, minimum=0, integer=True))


def _checked(points, masses, n_vertices, queue, choices, switch_factor, solver, fraction, bin_density,
             final_density_factor, background):
    """Validated ``(points, masses)``; raises on bad parameters."""
    points, masses = check_points(points, masses, dim=3, min_points=4)
    if masses is not None and np.any(masses <= 0):
        raise ValueError(f"masses must be > 0: {int(np.sum(masses <= 0))} are not")
    if not check_number("bin_density", bin_density) > 0:
        raise ValueError(f"bin_density must be > 0, got {bin_density}")
    check_number("final_density_factor", final_density_factor, minimum=1.0)
    check_target(n_vertices, len(points), minimum=4)
    if queue not in QUEUES:
        raise ValueError(f"queue must be one of {', '.join(QUEUES)}, got {queue!r}")
    if background not in BACKGROUNDS:
        raise ValueError(f"background must be one of {', '.join(BACKGROUNDS)}, got {background!r}")
    if solver not in SOLVERS:
        raise ValueError(f"solver must be one of {', '.join(SOLVERS)}, got {solver!r}")
    check_number("choices", choices, minimum=1, integer=True)
    check_number("switch_factor", switch_factor, minimum=1.0)
    fraction = check_number("fraction", fraction)
    if not 0 < fraction <= 1:
        raise ValueError(f"fraction must be in (0, 1], got {fraction}")
    return points, masses


def rebinned(plan: SurfacePlan, settings: BinSettings, solve) -> SurfacePlan:
    """The plan on the same complex with every facet's bins made by
    ``settings``: each point's mass on a facet spread over its new bins by
    capacity (feasible), then relaxed (:data:`REBIN_SWEEPS` sweeps)."""
    facet_entries = {}
    new = SurfacePlan.from_entries(plan.complex, plan.points, plan.masses, settings, {}, plan.vertex_entries, {})
    for f, e in plan.facet_entries.items():
        cap = new.bins[f].capacity
        k = len(cap)
        facet_entries[f] = Entries(np.repeat(e.point, k), np.tile(np.arange(k), len(e.point)),
                                   np.outer(e.mass, cap).ravel())
    new.facet_entries = facet_entries
    relax(new, solve, max_sweeps=REBIN_SWEEPS)
    return new


def _result(plan: SurfacePlan, frame, stats: DecimationStats, seconds: dict) -> SurfaceReconstruction:
    c = plan.complex
    arrays = c.to_arrays()
    keys = [tuple(int(x) for x in arrays.vertex_ids[t]) for t in arrays.triangles]
    tri_mass = np.array([plan.simplex_mass(k) for k in keys])
    loose = np.setdiff1d(np.arange(len(arrays.vertices)), arrays.triangles)  # isolated or on dangling edges
    carried = np.array([plan.simplex_mass(int(arrays.vertex_ids[i])) > 0 for i in loose], bool)
    vertices = frame.points_out(arrays.vertices)
    cost, exponent = frame.cost_out(plan.total_cost())
    return SurfaceReconstruction(
        vertices=vertices, triangles=arrays.triangles, edges=np.zeros((0, 2), np.int64),
        isolated=loose[carried].astype(np.int64), triangle_mass=frame.masses_out(tri_mass),
        triangle_area=facet_areas(vertices, arrays.triangles), total_cost=cost, cost_exponent=exponent,
        plan=plan, complex=c, vertex_ids=arrays.vertex_ids, stats=stats, seconds=seconds)
