"""The benchmark sweep for host methods (``Method.jittable`` False, e.g. ``"exact"``): the
scenes of :func:`cdog_jax.benchmark.sweep`, one at a time in Python.

:func:`sweep_host` draws every scene of a :class:`Grid` from the same key, at the same
draw capacity and compacted to the same bucket capacity as :func:`sweep` does, runs each
method on it (a host method eagerly, a jittable one compiled per bucket) and scores it with
:func:`cdog_jax.metrics.scene_metrics`, so that its :class:`SweepResult` sits beside the
compiled sweep's in tables and figures. Meant for sub-grids a host method can finish.
"""

from __future__ import annotations

import functools
import time
from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .._expect import expect_args
from .._method import Method, Observations, method_from
from .._runtime.xla_kernels import jit
from ..geometry._camera import Rig
from ..metrics._scores import scene_metrics
from ..synthetic._rig import DEFAULT_BOX, IMAGE_SIZE
from ..synthetic._scene import generate_scene
from ._grid import Grid, bucket_of, compact_scene
from ._sweep import (
    EXTRA_FIELDS,
    SweepResult,
    _host_thresholds,
    default_mesh,
    describe_devices,
    metric_fields,
    versions,
)


@functools.partial(jit, static_argnames=("capacity", "draw_capacity", "image_size"))
def _scene(rig, box, key, count, sigma, *, capacity, draw_capacity, image_size):
    scene = generate_scene(
        key, rig, count, sigma, capacity=draw_capacity, box=box, image_size=image_size
    )
    return compact_scene(scene, capacity=capacity)


@functools.partial(jit, static_argnames=("method",))
def _associate_jit(rig, xy, mask, thresholds, *, method):
    return method.associate_scene(rig, Observations(xy, mask), thresholds)


@jit
def _score(rig, result, scene):
    return scene_metrics(rig, result, scene), (result.sigma_px, result.tau_px, result.num_groups)


def _associate(rig, scene, thresholds, method: Method):
    if method.jittable:
        return _associate_jit(rig, scene.xy, scene.mask, thresholds, method=method)
    return method.associate_scene(
        rig, Observations(np.asarray(scene.xy), np.asarray(scene.mask)), thresholds
    )


def sweep_host(
    rig: Rig,
    grid: Grid,
    methods: Mapping[str, Method | str] | Sequence[str],
    *,
    buckets: tuple[int, ...] = (20, 50, 90, 130),
    box=DEFAULT_BOX,
    image_size: tuple[int, int] = IMAGE_SIZE,
) -> SweepResult:
    """Every scene of ``grid``, each method run on it scene by scene, scored as :func:`sweep`
    scores it.

    Args:
        rig: the cameras, ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``; ``grid.views`` selects a subset, as in :func:`sweep`.
        grid: the scenes (a sub-grid a host method can finish).
        methods: ``{name: method}`` (a :class:`~cdog_jax.Method` or a registered name) or a
            list of registered names; host methods and jittable ones alike.
        buckets, box, image_size: as in :func:`sweep` (the same values give the same scenes).

    Returns:
        A :class:`SweepResult` with ``(S,)`` arrays, the fields of :func:`sweep`'s. ``time_s`` is each
        scene's own association time (warm: every bucket's first scene is run once before
        the timed runs), ``wall_s`` the whole run, ``compile_s`` 0, ``batch_size`` 1.
    """
    expect_args("sweep_host", rig=(rig, Rig), grid=(grid, Grid))
    if isinstance(methods, str):
        raise TypeError(
            f"sweep_host: methods must be a mapping {{name: method}} or a list of registered names; got the string {methods!r}"
        )
    if not isinstance(methods, Mapping):
        methods = {name: name for name in methods}
    if not methods:
        raise ValueError("sweep_host: methods must name at least one method")
    methods = {name: method_from(m, f"sweep_host (method {name!r})") for name, m in methods.items()}
    buckets = tuple(int(b) for b in buckets)
    if grid.views is not None:
        if max(grid.views) >= rig.num_views:
            raise ValueError(
                f"grid.views {grid.views} out of range for a rig of {rig.num_views} views"
            )
        rig = rig.select(grid.views)
    dtype = rig.K.dtype
    box = np.asarray(jnp.asarray(box, dtype))
    if box.shape != (2, 3):
        raise ValueError(f"box must be two (3,) corners; got shape {box.shape}")
    idx, keys = grid.flat(), np.asarray(grid.keys())
    which = bucket_of(idx.count, buckets)
    capacity = np.asarray(buckets, np.int32)[which]
    size = (int(image_size[0]), int(image_size[1]))

    t_start = time.perf_counter()
    scenes = []
    for s in range(grid.num_scenes):
        scenes.append(
            _scene(
                rig,
                jnp.asarray(box),
                jnp.asarray(keys[s]),
                jnp.asarray(idx.count[s], jnp.int32),
                jnp.asarray(idx.sigma[s], dtype),
                capacity=int(capacity[s]),
                draw_capacity=grid.capacity,
                image_size=size,
            )
        )
    per_method, time_s = {}, {}
    for name, method in methods.items():
        structure, base = method.structure(), _host_thresholds(method, dtype)
        for s in range(grid.num_scenes):
            method.check_scene(
                np.asarray(scenes[s].mask), f"sweep_host (method {name!r}, scene {s})"
            )
        rows, times, warm = [], np.zeros(grid.num_scenes), set()
        for s, scene in enumerate(scenes):
            thresholds = base._replace(sigma_px=np.asarray(idx.sigma[s], dtype))
            if int(capacity[s]) not in warm:  # compile apart
                jax.block_until_ready(_associate(rig, scene, thresholds, structure))
                warm.add(int(capacity[s]))
            t0 = time.perf_counter()
            result = jax.block_until_ready(_associate(rig, scene, thresholds, structure))
            times[s] = time.perf_counter() - t0
            rows.append(jax.device_get(_score(rig, result, scene)))
        fields = {
            f: np.stack([np.asarray(getattr(r[0], f)) for r in rows]) for f in metric_fields()
        }
        fields.update(
            {f: np.stack([np.asarray(r[1][k]) for r in rows]) for k, f in enumerate(EXTRA_FIELDS)}
        )
        per_method[name], time_s[name] = fields, times
    wall_s = time.perf_counter() - t_start

    mesh = default_mesh()
    return SweepResult(
        grid=grid,
        configs=tuple(methods),
        sigma=idx.sigma,
        count=idx.count,
        scene=idx.scene,
        num_points=np.asarray([int(sc.num_points) for sc in scenes], np.int32),
        capacity=capacity,
        metrics=per_method,
        time_s=time_s,
        wall_s=float(wall_s),
        compile_s=0.0,
        timing_s=0.0,
        config_repr={name: repr(m) for name, m in methods.items()},
        versions=versions(),
        device=describe_devices(mesh),
        num_devices=1,
        buckets=buckets,
        batch_size=(1,) * len(buckets),
        box=tuple(tuple(float(v) for v in corner) for corner in box),
        rig={"K": np.asarray(rig.K), "R": np.asarray(rig.R), "t": np.asarray(rig.t)},
    )
