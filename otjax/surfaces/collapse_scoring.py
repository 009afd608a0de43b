"""Half-edge collapses of a surface complex scored by transport (§4.2, Algorithm 3).

For a candidate ``(source, target)`` the region is the paper's ``Omega_e``:
the closure of the stars of both ends (:meth:`SimplicialComplex.edge_closure`).
The points transported (wholly or partly) onto it are cut out of the plan
with their partial masses there (:meth:`SurfacePlan.stencil`, which also
reads what they cost now), and one local LP sends them onto the simplices
the region becomes, the closed star of ``target`` after the collapse
(:meth:`SimplicialComplex.simulate_collapse`). The two sets of simplices
differ by exactly what the collapse changes: ``source`` and its facets
leave, the images of its facets arrive, every other simplex of the after
star was in the region already, so writing the solved local plan back over
the after star (:meth:`SurfacePlan.assign`) and dropping the source's
simplices leaves every other entry of the plan as it was. Hence::

    delta = cost of the local optimum after - cost of those partial masses now

is the change of the global cost when the solved plan is applied.

Every candidate's LP is solved together
(:func:`otjax.lp.solve.solve_members`): batches of a fixed size and a few
padded shapes for the JAX solver, HiGHS for small groups and for the members
it does not certify (or for all, ``method="exact"``).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from otjax.lp.batched import NewtonOptions
from otjax.lp.problem import CONVERGED, ITERATION_LIMIT, LocalLP
from otjax.lp.solve import MembersResult, solve_members
from otjax.surfaces.complex import SimplicialComplex, Triangle, replace_vertex
from otjax.surfaces.plan import Stencil, SurfacePlan

#: A new facet whose ``2 area / longest edge^2`` (about the sine of its
#: smallest angle) is below this is degenerate: its bins' barycentric
#: coordinates would be ill-conditioned, and a flat facet has none.
DEGENERATE = 1e-8


class CollapseCandidate(NamedTuple):
    """A simulated collapse, ready to be solved and applied.

    Attributes:
      source, target: the half-edge (``source`` is removed).
      stencil: the local problem after the collapse: ``lp`` sends the
        region's points ``(P,)`` with their partial masses onto the bins
        ``(K,)`` of ``vertices``/``facets`` (the closed star of ``target``
        after the collapse); ``cost`` is what those partial masses cost now.
      removed: the facets of ``source`` (they vanish with it).
      new_bins: bins of the after facets the plan has none for yet.
    """

    source: int
    target: int
    stencil: Stencil
    removed: tuple[Triangle, ...]
    new_bins: dict


class ScoredCollapse(NamedTuple):
    """A candidate with its solved local plan.

    Attributes:
      candidate: the :class:`CollapseCandidate`.
      delta: ``cost - candidate.stencil.cost``: the change of the global cost.
      cost: the local plan's cost after the collapse.
      plan: ``(P, K)`` the local plan (feasible).
      status: the solver's status code (:mod:`otjax.lp.problem`).
    """

    candidate: CollapseCandidate
    delta: float
    cost: float
    plan: np.ndarray
    status: int


def inadmissible(complex_: SimplicialComplex, source: int, target: int, degenerate: float = DEGENERATE) -> str | None:
    """Why the collapse of ``(source, target)`` is refused, or ``None``.

    The link condition is not required: the paper's complex may be
    non-manifold and change topology, the transport cost judges that. What
    is refused is geometry a facet cannot stand for: a new facet (the image
    of a source facet that did not exist) that is degenerate (its bins need
    an area and a well-conditioned barycentric frame), or that turns over
    (its normal against the source facet's is at more than 90 degrees: a
    fold, which a facet carrying no mass would hide at no cost). Images
    that already exist merge with them (no duplicate facet is made).

    Example:
      >>> c = SimplicialComplex(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [2, 2, 0]]),
      ...                       np.array([[0, 1, 2], [1, 2, 3]]))
      >>> inadmissible(c, 0, 3)
      'there is no edge between 0 and 3'
    """
    if not complex_.has_edge(source, target) or source == target:
        return f"there is no edge between {source} and {target}"
    # Every new image at once: this runs for every candidate drawn, and
    # per-facet np.cross calls were most of the candidates' building time.
    facets, images = [], []
    for t in complex_.vertex_triangles[source]:
        img = replace_vertex(t, source, target)
        if img is not None and img not in complex_.triangles:
            facets.append(t)
            images.append(img)
    if not facets:
        return None
    pos = complex_.positions
    ab = pos[np.array([[v for v in t if v != source] for t in facets])]  # (F, 2, 3)
    a, b = ab[:, 0], ab[:, 1]
    before = _cross(a - pos[source], b - pos[source])
    after = _cross(a - pos[target], b - pos[target])
    longest = np.max(np.stack([np.sum((a - b) ** 2, 1), np.sum((a - pos[target]) ** 2, 1),
                               np.sum((b - pos[target]) ** 2, 1)]), axis=0)
    degenerated = ~(np.sqrt(np.sum(after * after, 1)) > degenerate * longest)
    turned = ~(np.sum(before * after, 1) > 0)
    bad = np.flatnonzero(degenerated | turned)
    if not len(bad):
        return None
    k = int(bad[0])
    if degenerated[k]:
        return f"the new facet {images[k]} is degenerate"
    return f"the facet {facets[k]} turns over into {images[k]}"


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``(F, 3)`` row-wise cross products (``np.cross`` costs more than
    the arithmetic on a few rows)."""
    return np.stack([u[:, 1] * v[:, 2] - u[:, 2] * v[:, 1], u[:, 2] * v[:, 0] - u[:, 0] * v[:, 2],
                     u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]], axis=1)


def new_facet_bins(plan: SurfacePlan, facets, cache: dict | None = None) -> dict:
    """``{facet: Bins}`` of ``facets`` the plan has no bins for, made in one
    :func:`~otjax.surfaces.bins.facet_bins` call with the plan's settings
    (the same bins :meth:`SurfacePlan.ensure_bins` would make); ``cache``
    keeps them between calls (valid while the vertices do not move)."""
    cache = {} if cache is None else cache
    todo = sorted({f for f in facets if f not in plan.bins and f not in cache})
    cache.update(plan.make_bins(todo))
    return {f: cache[f] for f in facets if f not in plan.bins}


def after_stencil(plan: SurfacePlan, before: Stencil, vertices: Sequence[int], facets: Sequence[Triangle],
                  new_bins: dict) -> Stencil:
    """The points of ``before`` with their partial masses, as an LP onto the
    bins of ``vertices`` and ``facets`` (bins from the plan or ``new_bins``);
    its ``cost`` is ``before.cost``."""
    bins = [plan.bins[f] if f in plan.bins else new_bins[f] for f in facets]
    pos = plan.complex.positions
    counts = [1] * len(vertices) + [len(b.capacity) for b in bins]
    sites = np.concatenate([pos[list(vertices)]] + [b.barycentric @ pos[list(f)] for f, b in zip(facets, bins)])
    simplex = np.repeat(np.arange(len(counts)), counts)
    bin_of = np.arange(len(simplex), dtype=np.int64) - np.repeat(np.cumsum(counts) - counts, counts)
    capacity = np.concatenate([np.zeros(len(vertices))] + [b.capacity for b in bins])
    diff = plan.points[before.points][:, None, :] - sites[None, :, :]
    lp = LocalLP(np.einsum("pkd,pkd->pk", diff, diff), before.lp.mass, capacity, simplex, simplex < len(vertices))
    return Stencil(lp, before.points, tuple(vertices), tuple(facets), bin_of, before.cost)


def build_candidates(plan: SurfacePlan, half_edges, bin_cache: dict | None = None) -> list[CollapseCandidate | None]:
    """The simulated collapse of each half-edge, ``None`` where
    :func:`inadmissible`; new facets' bins are made in one call for all."""
    c = plan.complex
    regions = []
    for s, t in half_edges:
        if inadmissible(c, s, t) is not None:
            regions.append(None)
            continue
        after = c.simulate_collapse(s, t)
        regions.append((s, t, after))
    made = new_facet_bins(plan, [f for r in regions if r is not None for f in r[2].triangles], bin_cache)
    out: list[CollapseCandidate | None] = []
    for r in regions:
        if r is None:
            out.append(None)
            continue
        s, t, after = r
        region = c.edge_closure(s, t)
        before = plan.stencil(region.vertices, region.triangles)
        new = {f: made[f] for f in after.triangles if f in made}
        stencil = after_stencil(plan, before, after.vertices, after.triangles, new)
        out.append(CollapseCandidate(s, t, stencil, tuple(sorted(c.vertex_triangles[s])), new))
    return out


def score_candidates(candidates: Sequence[CollapseCandidate], method: str = "auto",
                     options: NewtonOptions = NewtonOptions()) -> tuple[list[ScoredCollapse | None], MembersResult]:
    """Solves every candidate's LP in one :func:`~otjax.lp.solve.solve_members`
    (``method``: ``"auto"`` or ``"exact"``); a candidate whose solution is not
    usable (infeasible, failed) scores ``None``."""
    solved = solve_members([c.stencil.lp for c in candidates], method, options)
    out: list[ScoredCollapse | None] = []
    for cand, sol in zip(candidates, solved.solutions):
        if sol.status not in (CONVERGED, ITERATION_LIMIT):
            out.append(None)
            continue
        out.append(ScoredCollapse(cand, sol.cost - cand.stencil.cost, sol.cost, sol.plan, sol.status))
    return out, solved


def score_collapses(plan: SurfacePlan, half_edges, method: str = "auto", bin_cache: dict | None = None,
                    options: NewtonOptions = NewtonOptions()) -> list[ScoredCollapse | None]:
    """:func:`build_candidates` then :func:`score_candidates`: one entry per
    half-edge, ``None`` where the collapse is refused.

    Example:
      >>> c = SimplicialComplex(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
      >>> from otjax.surfaces.plan import BinSettings
      >>> plan = SurfacePlan(c, np.array([[0.1, 0.1, 0.0], [0.9, 0.0, 0.0]]), np.ones(2), BinSettings(1.5))
      >>> [round(s.delta, 6) for s in score_collapses(plan, [(1, 0)], method="exact")]
      [0.8]
    """
    cands = build_candidates(plan, half_edges, bin_cache)
    live = [c for c in cands if c is not None]
    scored = iter(score_candidates(live, method, options)[0])
    return [None if c is None else next(scored) for c in cands]
