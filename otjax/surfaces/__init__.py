"""Surface reconstruction (Digne et al. 2014): the transport of points onto a
simplicial complex, for research code and notebooks.

- :class:`SimplicialComplex` -- vertices, edges, triangles, possibly
  non-manifold; stars, closures, links, half-edge collapse (NumPy).
- :func:`facet_bins`, :func:`bin_positions` -- the facet bins of the
  discretised transport (centroidal cells in barycentric coordinates).
- :class:`SurfacePlan` -- the sparse plan of points onto vertex and facet
  bins, per-simplex mass and cost, local stencils cut out as LPs.
- :func:`relax` -- local stencil relaxation of a plan (Algorithm 2), rounds
  of disjoint stencils batched into one solver call.
- :class:`LocalSolver` -- the local LP solvers (``"exact"`` HiGHS,
  ``"batched"`` JAX Newton, ``"auto"``) behind one call.
- :func:`initial_complex` -- 3D Delaunay of a random subset, relaxation,
  facets with mass (§4.1).

The LP layer itself (padded batches, solvers, statuses) is :mod:`otjax.lp`.
"""

from otjax.surfaces.bins import FacetBins, bin_positions, facet_bins
from otjax.surfaces.complex import CollapseChange, ComplexArrays, LocalComplex, SimplicialComplex
from otjax.surfaces.initial_complex import InitialComplex, initial_complex, initial_settings
from otjax.surfaces.plan import BinSettings, Stencil, SurfacePlan
from otjax.surfaces.relaxation import LocalSolution, RelaxationStats, facet_ring, relax
from otjax.surfaces.solvers import LocalSolver, exact_solver

__all__ = [
    "BinSettings", "CollapseChange", "ComplexArrays", "FacetBins", "InitialComplex", "LocalComplex",
    "LocalSolution", "LocalSolver", "RelaxationStats", "SimplicialComplex", "Stencil", "SurfacePlan",
    "bin_positions", "exact_solver", "facet_bins", "facet_ring", "initial_complex", "initial_settings", "relax",
]
