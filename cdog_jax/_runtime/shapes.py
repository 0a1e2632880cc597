"""Few shapes, few compiled programs, little padding: :func:`cdog_jax.associate_batch` pads
the slot capacity ``P`` to a rung of a fine ladder (powers of two and one and a half times
them: 4, 6, 8, 12, 16, 24, 32, 48, 64; above 64 four rungs per doubling: 80, 96, 112, 128;
above 128 sixteen: 136, 144, …, 256, 272, …; :func:`cdog_jax.associate`, one scene at a
time, pads to 32, 64 or 128 up to 128 slots: :func:`scene_capacity`) and also pads the
number of scenes ``B`` (a rung of the ladder of two rungs per doubling from 1 up to
``batch_size``, then whole chunks of ``batch_size``), so that a process compiles two
programs per doubling of its frames' counts (four above 64 slots, sixteen above 128) while
a padded program does at most 1.5× the slots (2.25× the pairwise work; 1.25× and 1.56×
above 64 slots, 1.07× and 1.13× above 128) and 1.5× the scenes of the unpadded
one. Padding is neutral: padded slots hold no detection,
padded scenes none at all, and the result is trimmed back to the caller's shapes (bitwise
what the unpadded program returns; ALGORITHM.md §16). For the same reason trailing slots
that no view fills are not sent to the program at all: the ladder's rung is chosen from the
slots in use (:func:`occupied_slots`), and the result is filled back out to the caller's
``P`` with what an empty slot and an empty group row hold.

Padding and trimming happen in NumPy on the host, so that they compile nothing.
"""

from __future__ import annotations

import dataclasses

import jax
import numpy as np

from .._result import Association

MIN_CAPACITY = 4  # slots per view of the smallest program


def ladder_rung(count: int, smallest: int = 1) -> int:
    """The smallest rung ``>= max(count, smallest)`` of the ladder 1, 2, 3, 4, 6, 8, 12, 16,
    24, 32, 48, … (``2^k`` and ``3 · 2^(k-1)``): two rungs per doubling, so a count is padded
    by less than half of itself."""
    n = max(int(count), int(smallest), 1)
    power = 1 << (n - 1).bit_length()  # the smallest power of two >= n
    three_quarters = 3 * power // 4  # the 1.5× rung below it (an integer from 4 up)
    return three_quarters if power >= 4 and n <= three_quarters else power


FINE_FROM = 64
"""Above this many slots per view the slot ladder has four rungs per doubling (80, 96, 112,
128): the pairwise work of a scene grows with the square of its slots."""

FINER_FROM = 128
"""Above this many slots per view the rungs are the multiples of a thirty-second of the next
power of two (every 8 slots up to 256, every 16 up to 512, …; sixteen rungs per doubling): a
rung pads by less than a sixteenth of its slots (1.13× the pairwise work, which is most of
such a scene's time). 10 views × 130 points run at 136 slots in 36 ms, where a rung of 160
took 52 ms (2-core CPU, experiments/RESULTS.md); each rung is one more program to compile
(seconds) for a loop whose scenes' sizes vary this much."""


def slot_capacity(num_slots: int) -> int:
    """The padded capacity for ``num_slots`` slots per view: the smallest ladder rung
    (:func:`ladder_rung`) ``>= max(num_slots, MIN_CAPACITY)`` up to :data:`FINE_FROM`; above
    it the smallest multiple of an eighth of the next power of two (less than a quarter of
    padding), and above :data:`FINER_FROM` of a thirty-second (less than a sixteenth)."""
    n = max(int(num_slots), MIN_CAPACITY)
    if n <= FINE_FROM:
        return ladder_rung(n, MIN_CAPACITY)
    power = 1 << (n - 1).bit_length()  # the octave (power / 2, power]
    step = power // (32 if n > FINER_FROM else 8)
    return -(-n // step) * step


COARSE_UP_TO = 128
"""Up to this many slots per view :func:`scene_capacity` pads to 32, 64 or 128."""


def scene_capacity(num_slots: int) -> int:
    """The padded capacity of one scene given alone (:func:`cdog_jax.associate`): 32, 64 or
    128 up to :data:`COARSE_UP_TO` slots per view, :func:`slot_capacity` above. A first call
    at a new capacity compiles for seconds, while up to 128 slots a scene runs in
    milliseconds at any rung: a loop over frames of 5–130 points (a notebook's) compiles
    three programs rather than the fine ladder's ten. Above 128 slots the pairwise work
    (the square of the slots) dominates, and the fine rungs keep it within 1.13× of the
    unpadded scene's. Batches, the classes' scenes and live frames keep the fine ladder."""
    n = max(int(num_slots), 1)
    if n > COARSE_UP_TO:
        return slot_capacity(n)
    return max(32, 1 << (n - 1).bit_length())


def chunk_size(num_scenes: int, batch_size: int) -> int:
    """Scenes per compiled call: ``batch_size``, or for fewer scenes the smallest ladder rung
    ``>= num_scenes`` (at most ``batch_size``)."""
    return min(int(batch_size), ladder_rung(num_scenes))


def occupied_slots(mask: np.ndarray | jax.Array) -> int:
    """Slots per view up to the last detection of any view (and scene) of ``mask (..., P)``:
    ``P`` less the trailing slots that hold no detection anywhere; 0 without detections."""
    mask = np.asarray(mask)  # on the host: a JAX array's reshape would compile a program
    used = np.flatnonzero(np.any(mask.reshape(-1, mask.shape[-1]), axis=0))
    return int(used[-1]) + 1 if used.size else 0


def pad_slots(array: np.ndarray, capacity: int, axis: int, fill=0) -> np.ndarray:
    """``array`` padded along ``axis`` with ``fill`` to length ``capacity``, or cut to it
    (callers cut only slots that hold no detection: see :func:`occupied_slots`)."""
    extra = capacity - array.shape[axis]
    if extra == 0:
        return array
    if extra < 0:
        return np.take(array, np.arange(capacity), axis=axis)
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


_EMPTY_ROW = {"groups": -1, "valid": False, "points3d": 0, "bpe": 0, "err_px": 0, "n_views": 0}
"""What every field of an :class:`Association` holds in a group row past the last group."""


def trim(
    result: Association, num_slots: int, num_scenes: int | None = None, on_host: bool = False
) -> Association:
    """``result`` of a padded call brought back to ``num_slots`` slots per view, hence
    ``G = M · num_slots // 2`` group rows (valid groups come first), and, for a batch, to
    ``num_scenes`` scenes. A call at fewer slots (trailing empty slots left out) is filled
    out: labels with -1, group rows with :data:`_EMPTY_ROW`, as the program at
    ``num_slots`` returns them (a group needs two detections, so the program at fewer
    slots already holds every row a group can use). Fields become device arrays again (in
    one transfer), or stay NumPy arrays with ``on_host`` (a caller that reads them there)."""
    host = jax.tree.map(np.asarray, jax.device_get(result))
    lead = () if num_scenes is None else (slice(0, num_scenes),)
    num_groups_max = host.labels.shape[-2] * num_slots // 2
    group_axis = 0 if num_scenes is None else 1

    def cut(name, value):
        if name == "labels":
            return pad_slots(value[lead], num_slots, axis=value.ndim - 1, fill=-1)
        if name in _EMPTY_ROW:
            return pad_slots(value[lead], num_groups_max, axis=group_axis, fill=_EMPTY_ROW[name])
        return value[lead]

    names = [field.name for field in dataclasses.fields(Association)]  # the pytree's leaf order
    leaves = [np.asarray(cut(name, getattr(host, name))) for name in names]
    if not on_host:
        leaves = jax.device_put(leaves)
    return jax.tree.unflatten(jax.tree.structure(result), leaves)  # batched too (no __init__ check)
