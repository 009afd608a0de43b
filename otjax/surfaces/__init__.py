"""Surface reconstruction (Digne et al. 2014): the simplicial complex, its
half-edge collapse, and the facet bins of the discretised transport.

Topology and bins are NumPy only; cost kernels live in their own modules.
"""

from otjax.surfaces.bins import FacetBins, bin_positions, facet_bins
from otjax.surfaces.complex import CollapseChange, ComplexArrays, LocalComplex, SimplicialComplex

__all__ = [
    "CollapseChange", "ComplexArrays", "FacetBins", "LocalComplex", "SimplicialComplex", "bin_positions",
    "facet_bins",
]
