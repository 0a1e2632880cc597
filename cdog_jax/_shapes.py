"""Few shapes, few compiled programs: :func:`cdog_jax.associate` pads the slot capacity ``P``
to a short ladder (powers of two from 32) and :func:`cdog_jax.associate_batch` also pads
the number of scenes ``B`` (powers of two up to ``batch_size``, then whole chunks of
``batch_size``), so that a process compiles a handful of programs whatever its frames'
counts. Padding is neutral: padded slots hold no detection, padded scenes none at all, and
the result is trimmed back to the caller's shapes (bitwise what the unpadded program
returns; ALGORITHM.md §16).

Padding and trimming happen in NumPy on the host, so that they compile nothing.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from ._result import Association

MIN_CAPACITY = 32  # slots per view of the smallest program


def slot_capacity(num_slots: int) -> int:
    """The padded capacity for ``num_slots`` slots per view: the smallest power of two
    ``>= max(num_slots, 32)``."""
    return max(MIN_CAPACITY, 1 << max(int(num_slots) - 1, 0).bit_length())


def chunk_size(num_scenes: int, batch_size: int) -> int:
    """Scenes per compiled call: ``batch_size``, or for fewer scenes the smallest power of
    two ``>= num_scenes`` (at most ``batch_size``)."""
    return min(batch_size, 1 << max(int(num_scenes) - 1, 0).bit_length())


def pad_slots(array: np.ndarray, capacity: int, axis: int, fill=0) -> np.ndarray:
    """``array`` padded along ``axis`` with ``fill`` to length ``capacity``."""
    extra = capacity - array.shape[axis]
    if extra == 0:
        return array
    widths = [(0, 0)] * array.ndim
    widths[axis] = (0, extra)
    return np.pad(array, widths, constant_values=fill)


def pad_scenes(array: np.ndarray, num_scenes: int) -> np.ndarray:
    """``array (B, ...)`` padded to ``num_scenes`` leading entries by repeating its last one
    (valid values: a padded scene's mask is all False, so they are never used)."""
    extra = num_scenes - array.shape[0]
    if extra == 0:
        return array
    return np.concatenate([array, np.repeat(array[-1:], extra, axis=0)])


def trim(result: Association, num_slots: int, num_scenes: int | None = None) -> Association:
    """``result`` of a padded call cut back to ``num_slots`` slots per view, hence
    ``G = M · num_slots // 2`` group rows (valid groups come first), and, for a batch, to
    ``num_scenes`` scenes. Fields become device arrays again."""
    host = jax.tree.map(np.asarray, jax.device_get(result))
    lead = () if num_scenes is None else (slice(0, num_scenes),)
    num_groups_max = host.labels.shape[-2] * num_slots // 2

    def cut(name, value):
        if name == "labels":
            return value[(*lead, Ellipsis, slice(0, num_slots))]
        if name in ("groups", "valid", "points3d", "bpe", "err_px", "n_views"):
            return value[(*lead, slice(0, num_groups_max))]
        return value[lead]

    names = [field.name for field in dataclasses.fields(Association)]  # the pytree's leaf order
    leaves = [jax.device_put(np.asarray(cut(name, getattr(host, name)))) for name in names]
    return jax.tree.unflatten(jax.tree.structure(result), leaves)  # batched too (no __init__ check)
