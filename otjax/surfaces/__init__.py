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
- :func:`reconstruct_surface` -- points to a decimated complex (§4):
  the initial complex, collapses scored in batches of local LPs by a
  :class:`SurfaceEngine` on the shared decimation loop.
- :func:`relocate`, :func:`relocation_targets`, :func:`refine` -- vertex
  relocation (§4.3): closed-form targets with the plan fixed, damped moves
  with local re-solves, gradient refinement.
- :func:`filter_facets`, :func:`facet_density` -- facet filtering by mass
  density (§4.4).
- :func:`find_transverse`, :func:`remove_transverse`,
  :func:`facet_alignment`, :func:`find_caps`, :func:`remove_caps`,
  :func:`fit_creases`, :func:`fit_border` -- facets standing across their
  points' surface and facets closing a concave corner of the open border
  found and removed, crease vertices moved onto the planes of the points
  around them, flat open-border vertices out to where the points end (not
  in the paper; the last step of :func:`reconstruct_surface`,
  ``fit_features=True``).
- :class:`SurfaceResult` -- a reconstructed surface: arrays, densities,
  ``.save()`` (``.ply``, ``.obj``, ``.off``, ``.json``), ``.plot()``.
- :func:`recover_features` -- pull a smooth mesh's vertices onto the creases
  and boundaries of its points and reopen filled holes (§5), as a
  :class:`SurfaceResult` whose ``stats`` is the run's :class:`FeatureRecovery`
  (also ``otjax.recover_features``).
- :func:`plot_complex` -- a matplotlib 3D view of points, the complex
  coloured by density and the transport plan.

The LP layer itself (padded batches, solvers, statuses) is :mod:`otjax.lp`.
"""

from otjax.surfaces.bins import FacetBins, bin_positions, facet_bins
from otjax.surfaces.border_fit import BorderFit, fit_border
from otjax.surfaces.caps import find_caps, remove_caps
from otjax.surfaces.complex import CollapseChange, ComplexArrays, LocalComplex, SimplicialComplex
from otjax.surfaces.crease_fit import CreaseFit, fit_creases
from otjax.surfaces.engine import SurfaceEngine
from otjax.surfaces.features import FeatureRecovery, PassStats, recover_features
from otjax.surfaces.filtering import FacetDensity, FilteredComplex, facet_density, filter_facets
from otjax.surfaces.initial_complex import InitialComplex, initial_complex, initial_settings
from otjax.surfaces.plan import BinSettings, Stencil, SurfacePlan
from otjax.surfaces.plot import plan_segments, plot_complex
from otjax.surfaces.reconstruct import SurfaceReconstruction, reconstruct_surface
from otjax.surfaces.refinement import RefineStats, refine
from otjax.surfaces.relaxation import LocalSolution, RelaxationStats, facet_ring, relax
from otjax.surfaces.relocation import RelocationStats, relocate, relocation_targets
from otjax.surfaces.result import SurfaceResult
from otjax.surfaces.solvers import LocalSolver, exact_solver
from otjax.surfaces.transverse import facet_alignment, find_transverse, remove_transverse

__all__ = [
    "BinSettings", "BorderFit", "CollapseChange", "ComplexArrays", "CreaseFit", "FacetBins", "FacetDensity",
    "FeatureRecovery", "FilteredComplex", "InitialComplex", "LocalComplex", "LocalSolution", "LocalSolver",
    "PassStats", "RefineStats", "RelaxationStats", "RelocationStats", "SimplicialComplex", "Stencil",
    "SurfaceEngine", "SurfacePlan", "SurfaceReconstruction", "SurfaceResult", "bin_positions",
    "exact_solver", "facet_alignment", "facet_bins", "facet_density", "facet_ring", "filter_facets",
    "find_caps", "find_transverse", "fit_border", "fit_creases", "initial_complex", "initial_settings",
    "plan_segments", "plot_complex", "reconstruct_surface", "recover_features", "refine", "relax",
    "relocate", "relocation_targets", "remove_caps", "remove_transverse"
]
