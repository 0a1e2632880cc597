"""The benchmark grid (docs/BENCHMARK.md §1): noise levels × point counts × scenes, with per-scene keys.

Every scene of a grid is named by ``(σ, count, scene index)`` and its PRNG key is derived
from those values alone (never from its position in the grid), so a sub-grid, a
re-ordered grid or a different capacity bucketing produces the very same scenes.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import ARRAY, INT, expect_args
from .._runtime.xla_kernels import jit
from ..synthetic._scene import Scene

DRAW_CAPACITY = 130
"""Default slot capacity at which grid scenes are drawn (the paper's largest count)."""


class GridIndex(NamedTuple):
    """Flat per-scene description of a grid, ``S`` scenes in σ-major, count, scene order.

    Attributes:
        sigma: ``(S,)`` float64 pixel noise std σ of each scene.
        count: ``(S,)`` int32 requested point count.
        scene: ``(S,)`` int32 scene index within its (σ, count) cell.
        cell: ``(S,)`` int32 cell index ``sigma_index * len(counts) + count_index``.
        sigma_index: ``(S,)`` int32 position of σ in ``Grid.sigmas``.
        count_index: ``(S,)`` int32 position of the count in ``Grid.counts``.
    """

    sigma: np.ndarray
    count: np.ndarray
    scene: np.ndarray
    cell: np.ndarray
    sigma_index: np.ndarray
    count_index: np.ndarray


@dataclasses.dataclass(frozen=True)
class Grid:
    """A benchmark grid: every (σ, count) cell holds ``scenes`` independent scenes.

    Attributes:
        sigmas: pixel noise levels σ (≥ 0; distinct at 0.001 px, which names the scene).
        counts: requested 3D point counts per scene (``1 … capacity``).
        scenes: scenes per cell.
        seed: base seed of every scene key (see :meth:`keys`).
        views: indices of the rig's views to use (an ablation), or None for all views.
        capacity: slot capacity at which scenes are drawn before they are compacted into
            their bucket; part of a scene's identity (``generate_scene`` draws
            ``capacity * 4`` candidates), so keep it fixed when comparing grids.
    """

    sigmas: tuple[float, ...]
    counts: tuple[int, ...]
    scenes: int = 5
    seed: int = 0
    views: tuple[int, ...] | None = None
    capacity: int = DRAW_CAPACITY

    def __post_init__(self):
        # Normalise lists (e.g. from JSON) to tuples of plain Python numbers: hashable.
        object.__setattr__(self, "sigmas", tuple(float(s) for s in self.sigmas))
        object.__setattr__(self, "counts", tuple(int(c) for c in self.counts))
        if self.views is not None:
            object.__setattr__(self, "views", tuple(int(v) for v in self.views))
        if not self.sigmas or not self.counts:
            raise ValueError(
                f"Grid needs at least one sigma and one count; got {self.sigmas} and {self.counts}"
            )
        if min(self.sigmas) < 0 or not np.all(np.isfinite(self.sigmas)):
            raise ValueError(f"Grid.sigmas must be finite and >= 0; got {self.sigmas}")
        milli = [_milli_px(s) for s in self.sigmas]
        if len(set(milli)) != len(milli):
            raise ValueError(f"Grid.sigmas must be distinct at 0.001 px; got {self.sigmas}")
        if len(set(self.counts)) != len(self.counts):
            raise ValueError(f"Grid.counts must be distinct; got {self.counts}")
        if not isinstance(self.capacity, int) or self.capacity < 1:
            raise ValueError(f"Grid.capacity must be a positive int; got {self.capacity!r}")
        if min(self.counts) < 1 or max(self.counts) > self.capacity:
            raise ValueError(
                f"Grid.counts must lie in [1, capacity={self.capacity}]; got {self.counts}"
            )
        if not isinstance(self.scenes, int) or self.scenes < 1:
            raise ValueError(f"Grid.scenes must be a positive int; got {self.scenes!r}")
        views = self.views
        if views is not None and (
            len(views) < 2 or len(set(views)) != len(views) or min(views) < 0
        ):
            raise ValueError(
                f"Grid.views must be None or >= 2 distinct view indices; got {self.views}"
            )

    @classmethod
    def paper(cls, **overrides) -> Grid:
        """docs/BENCHMARK.md §1: σ = 0, 0.25, …, 5 (21) × counts 1…20, 25…130 step 5 (42) × 5 scenes."""
        base = dict(
            sigmas=tuple(0.25 * i for i in range(21)),
            counts=tuple(range(1, 21)) + tuple(range(25, 131, 5)),
            scenes=5,
        )
        base.update(overrides)
        return cls(**base)

    @classmethod
    def quick(cls, **overrides) -> Grid:
        """A tiny grid for smoke runs: σ ∈ {0, 1, 3, 5} × counts {5, 20, 60} × 2 scenes."""
        base = dict(sigmas=(0.0, 1.0, 3.0, 5.0), counts=(5, 20, 60), scenes=2)
        base.update(overrides)
        return cls(**base)

    def replace(self, **changes) -> Grid:
        """A copy with some fields changed."""
        return dataclasses.replace(self, **changes)

    @property
    def num_scenes(self) -> int:
        """``S = len(sigmas) * len(counts) * scenes``."""
        return len(self.sigmas) * len(self.counts) * self.scenes

    def flat(self) -> GridIndex:
        """Per-scene arrays ``(S,)`` in σ-major, then count, then scene order."""
        ns, nc, nk = len(self.sigmas), len(self.counts), self.scenes
        si, ci, k = np.meshgrid(np.arange(ns), np.arange(nc), np.arange(nk), indexing="ij")
        si, ci, k = (a.reshape(-1).astype(np.int32) for a in (si, ci, k))
        return GridIndex(
            sigma=np.asarray(self.sigmas, np.float64)[si],
            count=np.asarray(self.counts, np.int32)[ci],
            scene=k,
            cell=(si * nc + ci).astype(np.int32),
            sigma_index=si,
            count_index=ci,
        )

    def keys(self) -> jax.Array:
        """``(S, 2)`` uint32 PRNG keys, one per scene of :meth:`flat`.

        ``key = fold_in(fold_in(fold_in(PRNGKey(seed), round(1000 σ)), count), scene)``:
        it depends on the scene's own σ (in milli-pixels), count and index only, not on
        the other cells of the grid.
        """
        idx = self.flat()
        milli = np.asarray([_milli_px(s) for s in idx.sigma], np.int32)
        return scene_keys(self.seed, milli, idx.count, idx.scene)


def _milli_px(sigma: float) -> int:
    return int(round(1000.0 * float(sigma)))


@jit
def _fold_keys(base, milli, count, scene):
    one = lambda s, c, k: jax.random.fold_in(jax.random.fold_in(jax.random.fold_in(base, s), c), k)  # noqa: E731
    return jax.vmap(one)(milli, count, scene)


def scene_keys(seed: int, sigma_milli_px, count, scene) -> jax.Array:
    """PRNG keys ``(S, 2)`` uint32 of grid scenes named by σ (integer milli-pixels,
    ``(S,)``), point count ``(S,)`` and scene index ``(S,)`` (see :meth:`Grid.keys`)."""
    expect_args(
        "scene_keys",
        seed=(seed, INT),
        sigma_milli_px=(sigma_milli_px, ARRAY),
        count=(count, ARRAY),
        scene=(scene, ARRAY),
    )
    base = jax.random.PRNGKey(seed)
    arrays = (jnp.asarray(np.asarray(a, np.int32)) for a in (sigma_milli_px, count, scene))
    return _fold_keys(base, *arrays)


def compact_scene(scene: Scene, *, capacity: int) -> Scene:
    """The same scene with its detections moved to the first slots of each view and the
    slot axis cut (or zero-padded) to ``capacity``.

    Valid slots keep their relative (shuffled) order, so the result is again a uniformly
    shuffled scene; nothing is dropped as long as ``capacity >= scene.num_points``.
    Works under ``jit`` and ``vmap``.

    Args:
        scene: a :class:`~cdog_jax.synthetic.Scene` with ``xy (M, P, 2)``, ``mask (M, P)``,
            ``instance (M, P)``, ``points3d (P, 3)``.
        capacity: the new static slot count ``P'``.

    Returns:
        A ``Scene`` with ``xy (M, P', 2)``, ``mask (M, P')``, ``instance (M, P')`` (-1 in
        padding) and ``points3d (P', 3)``.
    """
    expect_args("compact_scene", scene=(scene, Scene), capacity=(capacity, INT))
    if not isinstance(capacity, int) or capacity < 1:
        raise ValueError(f"capacity must be a Python int >= 1; got {capacity!r}")
    M, P = scene.mask.shape
    mask = scene.mask
    # Destination slot of each valid detection; invalid ones go out of range (dropped).
    dest = jnp.where(mask, jnp.cumsum(mask, axis=1, dtype=jnp.int32) - 1, capacity)  # (M, P)
    view = jnp.broadcast_to(jnp.arange(M, dtype=jnp.int32)[:, None], (M, P))
    xy = jnp.zeros((M, capacity, 2), scene.xy.dtype).at[view, dest].set(scene.xy, mode="drop")
    new_mask = jnp.zeros((M, capacity), bool).at[view, dest].set(mask, mode="drop")
    instance = (
        jnp.full((M, capacity), -1, scene.instance.dtype)
        .at[view, dest]
        .set(scene.instance, mode="drop")
    )
    points3d = scene.points3d[:capacity]
    if capacity > P:
        points3d = jnp.concatenate([points3d, jnp.zeros((capacity - P, 3), points3d.dtype)])
    return Scene(
        xy=xy, mask=new_mask, instance=instance, points3d=points3d, num_points=scene.num_points
    )


def bucket_of(count, buckets: tuple[int, ...]) -> np.ndarray:
    """Index ``(S,)`` of the smallest bucket capacity ``>= count`` for every count ``(S,)``.

    Raises ``ValueError`` if a count exceeds the largest bucket or buckets are not
    strictly increasing positive ints.
    """
    expect_args("bucket_of", count=(count, ARRAY), buckets=(buckets, (tuple, list)))
    buckets = tuple(buckets)
    if (
        not buckets
        or any(not isinstance(b, int) or b < 1 for b in buckets)
        or list(buckets) != sorted(set(buckets))
    ):
        raise ValueError(f"buckets must be strictly increasing positive ints; got {buckets}")
    count = np.asarray(count)
    if count.size and count.max() > buckets[-1]:
        raise ValueError(
            f"the largest bucket ({buckets[-1]}) is below the largest point count ({count.max()})"
        )
    return np.searchsorted(np.asarray(buckets), count, side="left").astype(np.int32)
