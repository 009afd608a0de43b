"""Feature recovery (Digne et al. 2014, §5, Algorithm 4) without remeshing.

A smooth mesh (e.g. a screened Poisson reconstruction) rounds the creases of
the points it was made from and covers their holes. Recovery keeps its
connectivity and pulls its vertices onto the points' features:

1. the input is validated (:func:`validate_input`) and moved to the canonical
   frame (:mod:`otjax.frame`), where everything is computed;
2. bins are sampled on the mesh's facets, every point goes to its nearest
   vertex and the plan is relaxed by sweeps over the paper's facet
   stencils (§3.3, :data:`RELAX_SWEEPS`);
3. ``passes`` times, every vertex moves half way to its relocation target
   (§4.3), or less where a face around it would turn over, and the
   transport on its closed star is re-solved (as
   :func:`otjax.surfaces.relocation.relocate` with one round,
   :func:`otjax.surfaces.star_passes.relocate_class`); the order of the
   vertices is a fresh permutation each pass (the paper suggests it, to avoid
   a bias from a fixed order);
4. the facets are filtered by mass density (§4.4,
   :mod:`otjax.surfaces.filtering`): a facet over a hole receives little mass.

Batching. The paper handles one vertex after the other. Two vertices whose
closed stars share no vertex touch disjoint parts of the plan, so their
moves and re-solves commute: ``order="colouring"`` splits each pass's
permutation into colour classes of such vertices (a greedy distance-2
colouring, :func:`star_colouring`) and relocates a class with one solver
call; the relaxation's facet stencils are split alike. ``order="sequential"``
keeps the paper's one vertex (one stencil) at a time. The connectivity never
changes, so the plan is held as flat arrays
(:class:`~otjax.surfaces.star_plan.StarPlan`) and a class is cut out, priced,
solved and written back by array operations
(:mod:`otjax.surfaces.star_passes`); the result carries the same plan as a
:class:`SurfacePlan`.

Relocation keeps a move only if its star's cost does not rise, so the plan's
total cost never rises over a pass; no face's normal ever turns 90 degrees
or more from the input face's
(:func:`~otjax.surfaces.star_passes.flip_free_steps`).
"""

from __future__ import annotations

import sys
import time
from typing import NamedTuple

import jax
import numpy as np
import scipy.sparse
import scipy.spatial
from tqdm.auto import tqdm

from otjax.frame import Frame, to_canonical
from otjax.lp.batched import NewtonOptions
from otjax.surfaces.filtering import check_threshold, facet_density, keep_facets
from otjax.surfaces.mesh_stencils import distance2_graph
from otjax.surfaces.plan import BinSettings, SurfacePlan
from otjax.surfaces.relaxation import RelaxationStats
from otjax.surfaces.result import SurfaceResult
from otjax.surfaces.solvers import default_solver
from otjax.surfaces.star_passes import OPTIONS, relax_stencils, relocate_class
from otjax.surfaces.star_plan import StarPlan, surface_plan
from otjax.validation import _as_float_array, check_number, check_points

#: Default relative density (a multiple of the mean facet density) below which
#: a facet is dropped (docs/decisions.md#feature_recovery).
DENSITY_THRESHOLD = 0.1
#: Passes over the vertices (docs/decisions.md#feature_recovery).
PASSES = 3
#: Relaxation sweeps of the initial plan: the passes re-solve every star
#: again (docs/decisions.md#feature_recovery_batches).
RELAX_SWEEPS = 1
#: Points and mesh whose bounding-box diagonals differ by more than this
#: factor are at different scales (e.g. millimetres against metres).
SCALE_RATIO = 4.0
#: Points are far from the mesh when their median distance to the nearest
#: vertex exceeds this share of the mesh's diagonal plus its median edge length.
FAR = 0.1
#: A face whose area is below this share of its longest edge squared is degenerate.
MIN_FACE_ASPECT = 1e-12


class PassStats(NamedTuple):
    """One pass over the vertices.

    Attributes:
      cost_before, cost_after: the plan's total cost (user units) around the pass.
      accepted: moves kept; rejected: moves undone (the star's cost rose);
      degenerate: moves not made (a facet would degenerate); shortened:
      moves tried shorter so that no face turns over.
      solves: local LPs solved; calls: solver calls (colour classes, or vertices).
      seconds: wall time.
    """

    cost_before: float
    cost_after: float
    accepted: int
    rejected: int
    degenerate: int
    shortened: int
    solves: int
    calls: int
    seconds: float


class FeatureRecovery(NamedTuple):
    """The arrays of a :func:`recover_features` run, its result's ``stats``
    (user units throughout, except ``plan``).

    Attributes:
      vertices: ``(V, 3)`` float64 the moved vertices (every input row).
      triangles: ``(T', 3)`` int64 the input faces kept by the filter, as given.
      keep: ``(T,)`` bool which input faces are kept.
      triangle_mass: ``(T,)`` float64 mass transported onto each input face,
        plus its share of its corners' mass (:func:`facet_masses`).
      density: ``(T,)`` float64 relative mass density of each face
        (:func:`otjax.surfaces.filtering.facet_density`; 1 is the mean).
      sorted_density: ``(T,)`` the relative densities, decreasing: the
        thresholds at which the kept set changes.
      cost_before: total transport cost of the relaxed plan before relocation.
      cost_after: total transport cost after the last pass.
      passes: one :class:`PassStats` per pass.
      relaxation: the initial relaxation's :class:`RelaxationStats` (canonical units).
      plan: the final :class:`SurfacePlan`, in the canonical frame (``frame``).
      frame: the :class:`~otjax.frame.Frame` of the computation.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    keep: np.ndarray
    triangle_mass: np.ndarray
    density: np.ndarray
    sorted_density: np.ndarray
    cost_before: float
    cost_after: float
    passes: tuple[PassStats, ...]
    relaxation: RelaxationStats
    plan: SurfacePlan
    frame: Frame

    def to_result(self, params: dict | None = None, seconds: float = 0.0, points=None,
                  masses=None) -> SurfaceResult:
        """The kept faces as a :class:`SurfaceResult` (files, plots).

        ``params`` and ``seconds`` are recorded with it, ``points (N, 3)`` and
        ``masses (N,)`` (optional) go to its plots; its ``stats`` is this
        :class:`FeatureRecovery` (passes, relaxation, plan).
        """
        return SurfaceResult(vertices=self.vertices, triangles=self.triangles,
                             triangle_mass=self.triangle_mass[self.keep], total_cost=self.cost_after,
                             params=dict(params or {}), seconds=seconds, points=points, masses=masses, stats=self)


class CheckedInput(NamedTuple):
    """Validated input: ``points (N, 3)``, ``masses (N,)``, ``vertices (V, 3)``, ``triangles (T, 3)``."""

    points: np.ndarray
    masses: np.ndarray
    vertices: np.ndarray
    triangles: np.ndarray


# ---------------------------------------------------------------- validation
def check_mesh(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices (V, 3) float64, triangles (T, 3) int64)`` of a valid mesh.

    Raises:
      ValueError: wrong shapes, non-finite vertices, no faces, non-integer or
        out-of-range indices, a face repeating a vertex, a face of zero area,
        or the same face twice.
    """
    v = _as_float_array(vertices, "vertices")
    if v.ndim != 2 or v.shape[1] != 3:
        raise ValueError(f"vertices must have shape (V, 3), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ValueError(f"vertices must be finite: row {int(np.flatnonzero(~np.isfinite(v).all(1))[0])} is not")
    t = np.asarray(triangles)
    if t.size == 0:
        raise ValueError("the mesh has no faces: feature recovery moves the vertices of a triangle mesh")
    if t.ndim != 2 or t.shape[1] != 3:
        raise ValueError(f"triangles must have shape (T, 3), got {t.shape}")
    if t.dtype.kind == "f" and np.all(np.isfinite(t)) and np.all(t == np.round(t)):
        t = t.astype(np.int64)  # whole numbers read from a text file
    if t.dtype.kind not in "iu":
        raise ValueError(f"triangles must hold integer vertex indices, got dtype {t.dtype}")
    t = t.astype(np.int64)
    bad = np.flatnonzero(np.any((t < 0) | (t >= len(v)), axis=1))
    if len(bad):
        raise ValueError(f"face {int(bad[0])} {t[bad[0]].tolist()} indexes outside the {len(v)} vertices")
    s = np.sort(t, axis=1)
    bad = np.flatnonzero(np.any(s[:, 1:] == s[:, :-1], axis=1))
    if len(bad):
        raise ValueError(f"face {int(bad[0])} {t[bad[0]].tolist()} repeats a vertex (degenerate face)")
    c = v[t]
    area2 = np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    longest = np.max(np.sum((c - np.roll(c, 1, axis=1)) ** 2, axis=2), axis=1)
    bad = np.flatnonzero(~(area2 > MIN_FACE_ASPECT * longest))
    if len(bad):
        raise ValueError(f"face {int(bad[0])} {t[bad[0]].tolist()} has zero area (degenerate face)")
    _, first, count = np.unique(s, axis=0, return_index=True, return_counts=True)
    if np.any(count > 1):
        row = s[first[np.flatnonzero(count > 1)[0]]]
        raise ValueError(f"face {row.tolist()} appears more than once")
    return v, t


def check_placement(points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray) -> None:
    """Raises ValueError if the points are at another scale than the mesh
    (:data:`SCALE_RATIO`) or far from it (:data:`FAR`)."""
    used = vertices[np.unique(triangles)]
    # Both scaled by one power of two, so that norms of coordinates near the
    # ends of float64's range neither overflow nor lose their ratio.
    exponent = int(np.frexp(max(np.abs(used).max(), np.abs(points).max()))[1])
    used, points, vertices = (np.ldexp(a, -exponent) for a in (used, points, vertices))

    def out(length):  # a canonical length in the input's units, for the message
        with np.errstate(over="ignore"):
            return float(np.ldexp(length, exponent))

    d_mesh = float(np.linalg.norm(np.ptp(used, axis=0)))
    d_points = float(np.linalg.norm(np.ptp(points, axis=0)))
    ratio = d_points / d_mesh if d_mesh > 0 else float("inf")  # 0 here: the mesh is 2^-1000 of the points
    if not 1 / SCALE_RATIO <= ratio <= SCALE_RATIO:
        raise ValueError(
            f"the points and the mesh are at different scales: bounding-box diagonals {out(d_points):.4g} and "
            f"{out(d_mesh):.4g} (ratio {ratio:.3g}, more than {SCALE_RATIO:g}); are they in the same units?")
    edges = vertices[triangles] - vertices[np.roll(triangles, 1, axis=1)]
    edge = float(np.median(np.linalg.norm(edges, axis=2)))
    distance, _ = scipy.spatial.cKDTree(used).query(points)
    median = float(np.median(distance))
    if median > FAR * d_mesh + edge:
        raise ValueError(
            f"the points are far from the mesh: their median distance to the nearest mesh vertex is "
            f"{out(median):.4g}, more than {FAR:g} of the mesh's diagonal plus its median edge "
            f"({out(FAR * d_mesh + edge):.4g}); "
            "are they in the same coordinate frame?")


def validate_input(points, vertices, triangles, masses=None) -> CheckedInput:
    """Checks everything :func:`recover_features` needs (see its Raises)."""
    pts = _as_float_array(points, "points")
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ValueError(f"points must have shape (N, 3), got {pts.shape}")
    pts, m = check_points(pts, masses, dim=3, min_points=4, merge_duplicates=True)
    v, t = check_mesh(vertices, triangles)
    check_placement(pts, v, t)
    return CheckedInput(pts, m, v, t)


# ------------------------------------------------------------------ colouring
def star_colouring(triangles: np.ndarray, n_vertices: int, order: np.ndarray,
                   graph: scipy.sparse.csr_matrix | None = None) -> list[np.ndarray]:
    """Greedy colouring of the vertices ``order`` so that no two of a colour
    have closed stars sharing a vertex (they are at least 3 edges apart).

    Args:
      triangles: ``(T, 3)`` int64 faces.
      n_vertices: ``V``; ids are ``0 .. V-1``.
      order: ``(K,)`` int64 the vertices to colour, in the order they are
        coloured (each takes the smallest colour its distance-2 neighbours lack).
      graph: the faces' :func:`~otjax.surfaces.mesh_stencils.distance2_graph`, if
        already made.

    Returns:
      The colour classes, each ``(k,)`` int64 in the order of ``order``.

    Example:
      >>> [c.tolist() for c in star_colouring(np.array([[0, 1, 2], [1, 2, 3]]), 5, np.arange(5))]
      [[0, 4], [1], [2], [3]]
    """
    two = distance2_graph(triangles, n_vertices) if graph is None else graph
    return greedy_classes(two, order)


def greedy_classes(graph: scipy.sparse.csr_matrix, order: np.ndarray) -> list[np.ndarray]:
    """Greedy colouring of the rows ``order`` ``(K,)`` of a symmetric conflict
    ``graph`` ``(n, n)`` (CSR): each takes the smallest colour none of its
    neighbours has; the classes, each ``(k,)`` int64 in the order of ``order``."""
    order = np.asarray(order, np.int64)
    colour = np.full(graph.shape[0], -1, np.int64)
    indptr, indices = graph.indptr, graph.indices
    for v in order.tolist():
        taken = colour[indices[indptr[v]:indptr[v + 1]]]
        used = np.zeros(len(taken) + 1, bool)
        used[taken[(taken >= 0) & (taken <= len(taken))]] = True
        colour[v] = int(np.argmin(used))
    return [order[colour[order] == k] for k in range(int(colour.max(initial=-1)) + 1)]


def stencil_classes(conflicts: scipy.sparse.csr_matrix, order: str, rng: np.random.Generator):
    """``classes_of(rows) -> [(k,) int64]``: the stencils ``rows`` in a fresh
    random order, as classes with no conflict (``"colouring"``, conflicts:
    the stencils sharing a vertex) or one by one (``"sequential"``)."""

    def classes_of(rows: np.ndarray) -> list[np.ndarray]:
        perm = np.asarray(rows, np.int64)[rng.permutation(len(rows))]
        if order == "sequential":
            return [perm[i:i + 1] for i in range(len(perm))]
        return greedy_classes(conflicts, perm)

    return classes_of


# --------------------------------------------------------------------- steps
def initial_plan(frame_vertices: np.ndarray, triangles: np.ndarray, points: np.ndarray, masses: np.ndarray,
                 method: str, seed: int, order: str = "colouring",
                 options: NewtonOptions = OPTIONS) -> tuple[StarPlan, RelaxationStats]:
    """The relaxed plan of canonical ``points (N, 3)`` with ``masses (N,)`` onto
    the mesh ``frame_vertices (V, 3)``, ``triangles (T, 3)`` (§5): bins on every
    face, each point on its nearest vertex of a face, then at most
    :data:`RELAX_SWEEPS` sweeps of re-solves of the paper's facet stencils
    (:func:`relax_stencils` over :attr:`StarPlan.rings`), in ``order``
    (classes of stencils with no vertex in common, or one at a time)."""
    settings = BinSettings(diagonal=float(np.linalg.norm(np.ptp(points, axis=0))), seed=seed)
    plan = StarPlan(frame_vertices, triangles, points, masses, settings)
    incidence = plan.rings.incidence(plan.n_vertices)
    conflicts = (incidence @ incidence.T).tocsr()
    classes = stencil_classes(conflicts, order, np.random.default_rng(seed))
    return plan, relax_stencils(plan, plan.rings, classes, method, options, max_sweeps=RELAX_SWEEPS)


def relocation_pass(plan: StarPlan, method: str, order: str, rng: np.random.Generator,
                    options: NewtonOptions = OPTIONS, bar=None) -> PassStats:
    """One pass over the plan's face vertices in a random order (canonical costs):
    each class of ``order`` relocated and re-solved by :func:`relocate_class`.
    ``bar``: a tqdm bar advanced by the vertices done."""
    t0 = time.perf_counter()
    before = plan.total_cost()
    tally = np.zeros(6, np.int64)
    for group in stencil_classes(plan.two, order, rng)(np.unique(plan.bins.keys)):
        s = relocate_class(plan, group, method, options)
        tally += (s.accepted, s.rejected, s.degenerate, s.shortened, s.solved, s.calls)
        if bar is not None:
            bar.update(len(group))
    after = plan.total_cost()
    return PassStats(before, after, *map(int, tally), time.perf_counter() - t0)


def facet_masses(plan: StarPlan, triangles: np.ndarray) -> np.ndarray:
    """``(T,)`` mass on each face ``(T, 3)`` of the plan (canonical units),
    each vertex's own mass shared among its faces in proportion to their areas.

    On a fine mesh (a few points per face) much of the mass sits on vertex
    bins and a face's own mass is noisy: faces on the surface get none at
    times. A vertex's mass belongs to the faces around it, so a face over a
    hole still gets little (its corners carry little), while a face on the
    surface gets a share of its corners' mass (docs/decisions.md#feature_recovery).
    """
    pos = plan.positions
    c = pos[triangles]
    area = 0.5 * np.linalg.norm(np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]), axis=1)
    star = np.zeros(len(pos))
    np.add.at(star, triangles.ravel(), np.repeat(area, 3))
    own = plan.facet_mass()[plan.facet_rows(triangles)]
    return own + np.sum(plan.vertex_mass()[triangles] * area[:, None] / star[triangles], axis=1)


# ---------------------------------------------------------------- entry point
def recover_features(points, mesh, masses=None, *, passes: int = PASSES, order: str = "colouring",
                     density_threshold: float = DENSITY_THRESHOLD, solver: str | None = None, seed: int = 0,
                     progress: bool = False) -> SurfaceResult:
    """Pulls a smooth mesh's vertices onto the creases and boundaries of the
    points, then drops the facets that receive little mass (Algorithm 4).

    Args:
      points: ``(N, 3)`` the points the mesh was reconstructed from.
      mesh: the smooth mesh: anything with ``vertices (V, 3)`` and
        ``triangles (T, 3)`` attributes (:func:`otjax.io3d.read_mesh`, a
        :class:`SurfaceResult`, a dataset's ``mesh``) or a
        ``(vertices, triangles)`` pair.
      masses: ``(N,)`` point masses, default all 1.
      passes: relocation passes over the vertices (>= 0).
      order: ``"colouring"`` (classes of vertices with disjoint closed stars,
        one solver call each) or ``"sequential"`` (one vertex at a time, the paper).
      density_threshold: relative mass density below which a facet is dropped
        (``0`` keeps every facet that carries mass).
      solver: the local LP solver: ``"exact"`` (HiGHS), ``"batched"`` (JAX) or
        ``"auto"`` (JAX, HiGHS for the members it does not certify); ``None``:
        :func:`default_solver`.
      seed: seeds the bins, the relaxation and each pass's vertex order.
      progress: a progress bar (tqdm, on stderr) over the passes' vertices.

    Returns:
      A :class:`SurfaceResult`: every input vertex moved (``vertices (V, 3)``),
      the faces the density filter keeps, as given, with their masses, the
      transport cost, the options as ``params``, the points for its plots;
      its ``stats`` is the run's :class:`FeatureRecovery` (which faces are
      kept, densities, passes, the plan).

    Raises:
      ValueError: a ``mesh`` of neither form, malformed points, masses or
        mesh (shapes, non-finite values, no faces, indices out of range,
        degenerate or repeated faces), points at another scale than the
        mesh or far from it, or a bad option; all before any work.

    Example:
      >>> from otjax.datasets3d import rounded_box
      >>> box = rounded_box(300, noise=0.005, seed=1, resolution=3)
      >>> result = recover_features(box.points, box.mesh, passes=1, solver="exact")
      >>> result.vertices.shape, result.stats.cost_after <= result.stats.cost_before
      ((56, 3), True)
    """
    vertices, triangles = _mesh_arrays(mesh)
    if order not in ("colouring", "sequential"):
        raise ValueError(f"order must be 'colouring' or 'sequential', got {order!r}")
    if isinstance(passes, bool) or not isinstance(passes, (int, np.integer)) or passes < 0:
        raise ValueError(f"passes must be an integer >= 0, got {passes!r}")
    if solver not in (None, "exact", "batched", "auto"):
        raise ValueError(f"solver must be 'exact', 'batched', 'auto' or None, got {solver!r}")
    solver = default_solver() if solver is None else solver
    threshold = check_threshold(density_threshold)
    seed = check_number("seed", seed, integer=True)
    given = validate_input(points, vertices, triangles, masses)
    params = {"passes": int(passes), "order": order, "density_threshold": threshold, "solver": solver,
              "seed": seed}
    t0 = time.perf_counter()
    run = _recover(given, passes, order, threshold, solver, seed, progress)
    # the validated input (duplicates merged), back from the canonical frame
    return run.to_result(params, time.perf_counter() - t0, run.frame.points_out(run.plan.points),
                         run.frame.masses_out(run.plan.masses))


def _mesh_arrays(mesh) -> tuple:
    """``(vertices, triangles)`` of a mesh object or pair (unchecked)."""
    if hasattr(mesh, "vertices") and hasattr(mesh, "triangles"):
        return mesh.vertices, mesh.triangles
    if isinstance(mesh, (tuple, list)) and len(mesh) == 2:
        return tuple(mesh)
    raise ValueError("mesh must have vertices and triangles attributes (e.g. otjax.io3d.read_mesh) "
                     f"or be a (vertices, triangles) pair, got {type(mesh).__name__}")


def _recover(given: CheckedInput, passes: int, order: str, threshold: float, solver: str, seed: int,
             progress: bool) -> FeatureRecovery:
    """Algorithm 4 on checked input: the plan, the passes, the filter (the run's arrays)."""
    frame, q, m = to_canonical(given.points, given.masses)
    with jax.enable_x64(True):
        plan, relaxation = initial_plan(frame.points_in(given.vertices), given.triangles, q, m, solver, seed,
                                        order)
        n_moving = len(np.unique(plan.bins.keys))
        stats = []
        with tqdm(total=passes * n_moving, desc="feature recovery", unit="vertex", disable=not progress,
                  file=sys.stderr, leave=False) as bar:
            for k in range(passes):
                bar.set_postfix_str(f"pass {k + 1}/{passes}")
                s = relocation_pass(plan, solver, order, np.random.default_rng([seed, k]), bar=bar)
                s = s._replace(cost_before=_cost_out(frame, s.cost_before),
                               cost_after=_cost_out(frame, s.cost_after))
                stats.append(s)
                bar.set_postfix_str(f"pass {k + 1}/{passes}, cost {s.cost_after:.4g}")
    moved = frame.points_out(plan.positions)
    mass = frame.masses_out(facet_masses(plan, given.triangles))
    density = facet_density(moved, given.triangles, mass)
    keep = keep_facets(density.relative, threshold)
    cost = _cost_out(frame, plan.total_cost())
    first = stats[0].cost_before if stats else cost
    return FeatureRecovery(moved, given.triangles[keep], keep, mass, density.relative, density.sorted, first,
                           cost, tuple(stats), relaxation, surface_plan(plan), frame)


def _cost_out(frame: Frame, cost: float) -> float:
    value, exponent = frame.cost_out(cost)
    with np.errstate(over="ignore", under="ignore"):
        return float(np.ldexp(value, exponent))
