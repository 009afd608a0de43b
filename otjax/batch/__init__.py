"""Kernel batches, shared by every dimension; knows no geometry.

- :mod:`otjax.batch.fields` -- a kernel's input layout written once (a
  :class:`~otjax.batch.fields.FieldSpec`), packed into two reusable buffers.
- :mod:`otjax.batch.packing` -- grouping variable-size jobs into batches of
  a few capacity classes.
- :mod:`otjax.batch.pipeline` -- dispatching packed batches to a jitted
  kernel without waiting, with a buffer pool and a record of the compiled
  shapes.
- :mod:`otjax.batch.exported` -- each kernel shape kept on disk as an
  exported module, so that a new process does not trace it again.
"""

from otjax.batch.fields import Dims, Field, FieldSpec, Gather, PackedBuffers, Prefix
from otjax.batch.packing import choose_packing, pack_first_fit, pack_next_fit
from otjax.batch.pipeline import Handle, KernelPipeline, ShapePolicy, require_x64

__all__ = [
    "Dims",
    "Field",
    "FieldSpec",
    "Gather",
    "Handle",
    "KernelPipeline",
    "PackedBuffers",
    "Prefix",
    "ShapePolicy",
    "choose_packing",
    "pack_first_fit",
    "pack_next_fit",
    "require_x64",
]
