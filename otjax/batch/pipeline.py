"""Dispatching packed batches to a jitted kernel: shapes, buffers, calls in flight.

A :class:`KernelPipeline` owns what a run of kernel calls shares: the
pool of :class:`~otjax.batch.fields.PackedBuffers` (a call's buffers go
back to the pool once its results are read), the policy that maps a
batch's need to a compiled shape, the kernel at each shape (read back from
an exported module while JAX's compilation cache is on, see
:mod:`otjax.batch.exported`) and the record of the shapes used and calls
made. :meth:`KernelPipeline.dispatch` does not wait: JAX runs the call
while the host exports the next batch.
"""

from __future__ import annotations

import functools
import importlib
from typing import Callable, NamedTuple

import jax
import numpy as np

from otjax.batch.exported import exported_kernel
from otjax.batch.fields import FieldSpec, PackedBuffers


def require_x64(what: str) -> None:
    """Raises a ``RuntimeError`` unless JAX's x64 mode is on.

    Kernels that locate points in exact float64 arithmetic cannot run in
    float32; JAX would silently narrow their inputs. The public entry
    points (``reconstruct_curve``, the command line) enable x64 for their
    duration; research code calling lower layers does it itself, with
    ``jax.enable_x64(True)`` around the calls or ``jax.config.update``.
    """
    if jax.dtypes.canonicalize_dtype(np.float64) != np.float64:
        raise RuntimeError(f"{what} needs JAX's float64 mode: run it inside `with jax.enable_x64(True):` "
                           "or set jax.config.update('jax_enable_x64', True)")


class ShapePolicy(NamedTuple):
    """Row capacities batches are compiled at.

    At or below ``budget`` two shapes, ``min_rows`` and ``budget``, and
    ``tiny_rows`` below them if given: each shape costs about a second of
    compilation, and a packing into ``min_rows`` batches is tried where it
    helps (:func:`~otjax.batch.packing.choose_packing`). Above ``budget`` a
    batch is scored at its own capacity class (see
    ``docs/decisions.md#row_budget`` and ``#tiny_rows``).
    """

    min_rows: int
    budget: int
    tiny_rows: int = 0

    def shape_for(self, need: int) -> int:
        """Row capacity a batch that needs ``need`` rows is scored at."""
        if self.tiny_rows and need <= self.tiny_rows:
            return self.tiny_rows
        if need <= self.min_rows:
            return self.min_rows
        return self.budget if need <= self.budget else need


class Handle(NamedTuple):
    """A dispatched call: its (unread) outputs and the buffers it reads."""

    outputs: tuple
    buffers: PackedBuffers


class KernelPipeline:
    """Calls of one jitted kernel on packed batches.

    Args:
      spec: the kernel's input :class:`~otjax.batch.fields.FieldSpec`.
      kernel: ``kernel(floats, ints, rows=r, dtype=dtype, **static) ->
        outputs``, jitted with those keywords static; its outputs serialisable by
        :mod:`jax.export` (arrays, tuples, registered NamedTuples).
      policy: the :class:`ShapePolicy`.
      dtype: float dtype of the kernel's cost arithmetic (an argument of every
        call, never a global switch).
      static: the kernel's other static keyword arguments, the same in
        every call.
    """

    def __init__(self, spec: FieldSpec, kernel: Callable, policy: ShapePolicy, dtype=np.float64,
                 static: dict | None = None):
        self.spec = spec
        self.kernel = kernel
        self.policy = policy
        self.dtype = dtype
        self.static = dict(static or {})
        self.calls = 0
        self.shapes_seen: set[int] = set()
        self._pool: dict[int, list[PackedBuffers]] = {}
        self._calls: dict[int, Callable] = {}  # row capacity -> the kernel at that shape

    def __getstate__(self) -> dict:
        # A jitted kernel pickles by the module and name it was defined with.
        state = dict(self.__dict__)
        state["kernel"] = (self.kernel.__module__, self.kernel.__qualname__)
        state["_pool"] = {}
        state["_calls"] = {}
        return state

    def __setstate__(self, state: dict) -> None:
        module, name = state["kernel"]
        state["kernel"] = functools.reduce(getattr, name.split("."), importlib.import_module(module))
        self.__dict__.update(state)

    def dispatch(self, values: dict, need: int) -> Handle:
        """Packs ``values`` (see :meth:`PackedBuffers.fill`) at the shape for
        ``need`` rows and starts the kernel; does not wait."""
        require_x64("otjax's scoring kernel")
        r = self.policy.shape_for(need)
        free = self._pool.get(r)
        buffers = free.pop() if free else PackedBuffers(self.spec, r)
        buffers.fill(values)
        self.shapes_seen.add(r)
        self.calls += 1
        call = self._calls.get(r)
        if call is None:
            static = {"rows": r, "dtype": self.dtype, **self.static}
            call = self._calls[r] = exported_kernel(self.kernel, static, (buffers.floats, buffers.ints))
        return Handle(call(buffers.floats, buffers.ints), buffers)

    def wait(self, handle: Handle) -> tuple:
        """The call's outputs as host arrays; its buffers go back to the pool."""
        # np.asarray per leaf, not jax.device_get: the same host arrays, and
        # ~50 us less a call (device_get starts a copy per leaf first).
        outputs = jax.tree_util.tree_map(np.asarray, handle.outputs)
        self._pool.setdefault(handle.buffers.r, []).append(handle.buffers)
        return outputs


# Kernel calls dispatched ahead of the one being collected
# (docs/decisions.md#in_flight).
IN_FLIGHT = 3


def pipelined(batches, dispatch: Callable, settle: Callable, in_flight: int = IN_FLIGHT,
              while_waiting: Callable | None = None) -> None:
    """Dispatches every batch, settling each once ``in_flight`` later ones run.

    ``dispatch(batch) -> handle`` starts a call, ``settle(batch, handle)``
    reads it. Batches are produced lazily, so the next one is built while
    earlier ones run (XLA:CPU runs two calls at once on two cores).
    ``while_waiting()`` runs once everything is dispatched, before the last
    calls are settled: host work that overlaps the kernels.
    """
    waiting = []
    for batch in batches:
        waiting.append((batch, dispatch(batch)))
        if len(waiting) > in_flight:
            settle(*waiting.pop(0))
    if while_waiting is not None:
        while_waiting()
    for batch, handle in waiting:
        settle(batch, handle)
