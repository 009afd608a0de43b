"""otjax: shape reconstruction and simplification by optimal transport, in JAX.

Public API (2D curves):

- :func:`reconstruct_curve` -- points (+ masses) to a simplicial curve.
- :class:`CurveResult` -- its result: arrays, ``.plot()``, ``.save()``.
- :func:`read_points`, :func:`image_to_points` -- input files and images.
- :mod:`otjax.datasets` -- synthetic shapes with known ground truth.
- :mod:`otjax.metrics` -- distances to that ground truth.
- :mod:`otjax.curves` -- the building blocks of the 2D pipeline (triangulation,
  transport plan, stencil batches, JAX cost kernels, decimation, relocation),
  for research code; see ``notebooks/``.
- :mod:`otjax.decimation` -- the greedy loop shared by every dimension
  (queues, relocation rounds) over an engine such as
  :class:`otjax.curves.CurveEngine`.
- :mod:`otjax.batch` -- kernel batches shared by every dimension: field
  specs, packing, the dispatch pipeline.
- :mod:`otjax.stencil` -- padded stencil batches of the public batched kernel.

Surfaces (3D, Digne et al. 2014):

- :mod:`otjax.surfaces` -- the simplicial complex, facet bins, the sparse
  transport plan, local relaxation, the initial complex, vertex relocation,
  facet filtering, :class:`~otjax.surfaces.SurfaceResult`, a 3D view, and
  :func:`~otjax.surfaces.recover_features` (sharp features of a smooth mesh).
- :func:`recover_features` -- ``recover_features(points, mesh, masses=None,
  ...)``: a smooth mesh pulled onto the creases and boundaries of its points,
  filled holes reopened, as a :class:`~otjax.surfaces.SurfaceResult`.
- :mod:`otjax.lp` -- padded batches of local transport LPs, the batched JAX
  solver and the exact HiGHS one, per-member status.
- :mod:`otjax.datasets3d`, :mod:`otjax.metrics3d` -- surfaces with known
  ground truth (creases, boundaries) and distances to it.
- :mod:`otjax.io3d` -- 3D point files and triangle meshes (``.ply``,
  ``.obj``, ``.off``).
- :func:`enable_compilation_cache` -- keep compiled kernels on disk for
  later processes (the command line does by default).
"""

import importlib

from otjax import batch, curves, datasets, decimation, metrics, stencil
from otjax.background import Background, estimate_background
from otjax.compile_cache import enable_compilation_cache
from otjax.curves.reconstruct import reconstruct_curve
from otjax.curves.result import CurveResult
from otjax.io import image_to_points, read_points

# The 3D half is imported on first use (PEP 562): a curve command or script
# does not pay for loading it.
_LAZY = {"datasets3d": ("otjax.datasets3d", None), "io3d": ("otjax.io3d", None), "lp": ("otjax.lp", None),
         "metrics3d": ("otjax.metrics3d", None), "surfaces": ("otjax.surfaces", None),
         "recover_features": ("otjax.surfaces.features", "recover_features")}

__all__ = [
    "Background",
    "CurveResult",
    "batch",
    "curves",
    "datasets",
    "datasets3d",
    "decimation",
    "enable_compilation_cache",
    "estimate_background",
    "image_to_points",
    "io3d",
    "lp",
    "metrics",
    "metrics3d",
    "read_points",
    "reconstruct_curve",
    "recover_features",
    "stencil",
    "surfaces",
]
__version__ = "0.1.0"


def __getattr__(name: str):
    if name not in _LAZY:
        raise AttributeError(f"module 'otjax' has no attribute {name!r}")
    module, attribute = _LAZY[name]
    value = importlib.import_module(module)
    value = value if attribute is None else getattr(value, attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
