"""A kernel's input layout, written once, and the reusable buffers it packs into.

A jitted kernel that takes seventeen arrays pays a transfer and its
bookkeeping for each (about 20 us on CPU, a third of a small call), so a
batch travels as one float64 and one int32 buffer (booleans as 0/1). The
:class:`FieldSpec` next to each kernel names its fields -- dtype kind, shape
as a function of the row capacity ``r``, pad value, the axis a batch fills --
and everything else (offsets, views, padding, unpacking inside the kernel)
follows from it.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import numpy as np

KINDS = ("float", "int", "bool")


class Dims(NamedTuple):
    """A field's shape at row capacity ``r``: ``(*head, r // per + plus, *tail)``.

    The middle axis is the one a batch fills from its start. A plain value
    rather than a closure, so that specs (and buffers) pickle.
    """

    per: int = 1
    plus: int = 0
    head: tuple[int, ...] = ()
    tail: tuple[int, ...] = ()

    def __call__(self, r: int) -> tuple[int, ...]:
        return (*self.head, r // self.per + self.plus, *self.tail)


class Field(NamedTuple):
    """One input array of a kernel.

    Attributes:
      name: the field's name (the kernel's container attribute).
      kind: ``"float"`` (float64 buffer), ``"int"`` or ``"bool"`` (int32 buffer).
      dims: its :class:`Dims`.
      pad: value of the entries no batch wrote; a number or ``r -> number``
        (a module-level function, so that specs pickle).
    """

    name: str
    kind: str
    dims: Dims
    pad: float | Callable[[int], float] = 0

    @property
    def axis(self) -> int:
        """The axis a batch fills from its start."""
        return len(self.dims.head)

    def pad_at(self, r: int):
        return self.pad(r) if callable(self.pad) else self.pad


class Gather(NamedTuple):
    """A field value read from ``source`` at ``index`` (along axis 0) straight
    into the buffer, without a temporary."""

    source: np.ndarray
    index: np.ndarray


class Prefix(NamedTuple):
    """A field value: ``value`` in the first ``n`` entries."""

    n: int
    value: float


class Place(NamedTuple):
    """Where a field lives: its buffer (``True``: the float one), offset and shape."""

    is_float: bool
    offset: int
    shape: tuple[int, ...]


class FieldSpec:
    """The ordered fields of a kernel's input.

    Args:
      fields: the :class:`Field` list; names must be distinct.
    """

    def __init__(self, fields):
        self.fields = tuple(fields)
        names = [f.name for f in self.fields]
        if len(set(names)) != len(names):
            raise ValueError(f"field names must be distinct: {names}")
        for f in self.fields:
            if f.kind not in KINDS:
                raise ValueError(f"field {f.name}: kind must be one of {KINDS}, got {f.kind!r}")
        self._layouts: dict[int, tuple[dict[str, Place], tuple[int, int]]] = {}

    def layout(self, r: int) -> tuple[dict[str, Place], tuple[int, int]]:
        """``({name: Place}, (float size, int size))`` at row capacity ``r``."""
        hit = self._layouts.get(r)
        if hit is None:
            places, offsets = {}, {True: 0, False: 0}
            for f in self.fields:
                shape = tuple(int(s) for s in f.dims(r))
                is_float = f.kind == "float"
                places[f.name] = Place(is_float, offsets[is_float], shape)
                offsets[is_float] += int(np.prod(shape))
            hit = self._layouts[r] = (places, (offsets[True], offsets[False]))
        return hit

    def unpack(self, floats, ints, r: int) -> dict:
        """``{name: array}`` views of packed buffers (NumPy or JAX arrays);
        boolean fields compared with 0."""
        places, _ = self.layout(r)
        out = {}
        for f in self.fields:
            p = places[f.name]
            buf = floats if p.is_float else ints
            x = buf[p.offset: p.offset + int(np.prod(p.shape))].reshape(p.shape)
            out[f.name] = x != 0 if f.kind == "bool" else x
        return out


def aligned_zeros(n: int, dtype) -> np.ndarray:
    """``np.zeros(n, dtype)`` whose data starts on a 64-byte boundary.

    XLA:CPU takes such an argument of a jitted call without a copy; an
    unaligned one is copied on every call (see ``docs/decisions.md#aligned-buffers``).
    """
    dtype = np.dtype(dtype)
    raw = np.zeros(n * dtype.itemsize + 64, np.uint8)
    start = (-raw.ctypes.data) % 64
    return raw[start: start + n * dtype.itemsize].view(dtype)


class PackedBuffers:
    """The two input buffers of one kernel call at row capacity ``r``, for reuse.

    :meth:`fill` writes a batch and resets only what the previous batch wrote
    beyond it, so the buffers always hold exactly what fresh, padded buffers
    filled with the batch would: no zeroing of megabytes per call and no page
    faults on new memory. The kernel reads them in place, so they must not be
    filled again before the call that used them has returned (the
    :class:`~otjax.batch.pipeline.KernelPipeline` pools them).

    Args:
      spec: the kernel's :class:`FieldSpec`.
      r: row capacity.
    """

    def __init__(self, spec: FieldSpec, r: int):
        self.spec = spec
        self.r = r
        places, (n_float, n_int) = spec.layout(r)
        self.floats = aligned_zeros(n_float, np.float64)
        self.ints = aligned_zeros(n_int, np.int32)
        self.views: dict[str, np.ndarray] = {}
        self._pads = {}
        for f in spec.fields:
            p = places[f.name]
            buf = self.floats if p.is_float else self.ints
            view = buf[p.offset: p.offset + int(np.prod(p.shape))].reshape(p.shape)
            pad = f.pad_at(r)
            if pad != 0:
                view[...] = pad
            self.views[f.name] = view if f.axis == 0 else np.moveaxis(view, f.axis, 0)
            self._pads[f.name] = pad
        self._used = dict.fromkeys(self.views, 0)

    def __reduce__(self):
        # A copy (deepcopy, pickling) is a fresh set: copied views would no
        # longer view the copied buffers, nor be aligned.
        return PackedBuffers, (self.spec, self.r)

    def fill(self, values: dict) -> None:
        """Writes a batch: ``{name: array | Gather | Prefix}``, each filling
        its field from the start along the field's axis; unnamed fields and
        entries past a value are padding.

        Raises:
          ValueError: a value longer than its field.
        """
        for name, view in self.views.items():
            value = values.get(name)
            if value is None:
                n = 0
            elif isinstance(value, Gather):
                n = len(value.index)
            elif isinstance(value, Prefix):
                n = value.n
            else:
                n = len(value)
            if n > len(view):
                raise ValueError(f"field {name}: {n} entries, capacity {len(view)}")
            used = self._used[name]
            if used > n:
                view[n:used] = self._pads[name]
            self._used[name] = n
            if isinstance(value, Gather):
                if value.source.dtype == view.dtype:
                    # mode="clip" lets take write straight into the view (ids are valid).
                    np.take(value.source, value.index, axis=0, out=view[:n], mode="clip")
                else:
                    view[:n] = value.source[value.index]
            elif isinstance(value, Prefix):
                view[:n] = value.value
            elif n:
                view[:n] = value
