"""The benchmark sweep (docs/BENCHMARK.md §1–2): generate, associate and score a whole grid
in one compiled program per capacity bucket.

:func:`sweep` builds every scene of a :class:`Grid` from its own key, runs every config on
it and scores it with :func:`cdog_jax.metrics.scene_metrics`, all inside compiled code:

- Capacity buckets: a scene of ``n`` points is padded to the smallest bucket capacity
  ``>= n`` (scenes are drawn at ``Grid.capacity`` and compacted, so a scene is the same
  whatever the bucketing). Each bucket is one ``jax.jit`` program, a ``lax.map``
  (``batch_size`` scenes vmapped per step, which bounds memory); all are compiled first,
  then dispatched one after another, and the results gathered back to grid order. Progress
  is reported from the host as each bucket's results arrive, so the programs hold no
  callback and persist in the compilation cache with or without progress.
- Devices: the scene axis of every bucket is split over a one-axis mesh named
  ``"scenes"`` with ``jax.shard_map`` (default: all devices of ``jax.devices()``), each
  bucket padded with empty scenes (dropped afterwards) to ``devices × steps × batch``,
  the batch trimmed so that ``lax.map`` has no remainder step. One device is the same
  program with a mesh of one.
- Multi-host: call ``jax.distributed.initialize()`` in every process, then call
  :func:`sweep` with the same arguments in every process. ``jax.devices()`` then lists the
  devices of all hosts, the inputs are placed with ``jax.device_put`` on the global mesh
  (every process computes the same grid arrays), each host runs its shards, and the
  output is replicated so every process gets the full :class:`SweepResult`; save it from
  process 0 only (``jax.process_index() == 0``). Two CPU processes on localhost give
  exactly the one-process result (tests/benchmark/test_distributed.py).

Time per scene is an *estimate*: after the sweep, one chunk of each bucket (``TIMING_SCENES``
scenes spread over the bucket, rounded up to a multiple of its batch size) is associated
per config by a jitted ``lax.map`` of each method's per-scene function with the sweep's
batch size (what :func:`cdog_jax.associate_batch` does), warm, median of ``timing_runs``
runs; every scene of the bucket gets ``chunk time / chunk size``. It excludes scene
generation and scoring, and on several devices it is the time of one device.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from collections.abc import Callable, Mapping, Sequence
from typing import NamedTuple

import jax
import jax.numpy as jnp
import jaxlib
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from .._expect import expect_args
from .._method import Method, Observations, method_from
from .._runtime.memory import check_memory
from .._runtime.progress import compiling, interactive, sweep_bar
from .._runtime.xla_kernels import jit
from .._version import __version__
from ..cdog._pipeline import Config
from ..geometry._camera import Rig
from ..metrics._scores import Metrics, scene_metrics
from ..synthetic._rig import DEFAULT_BOX, IMAGE_SIZE
from ..synthetic._scene import generate_scene
from ._grid import Grid, bucket_of, compact_scene

AXIS = "scenes"
"""Name of the mesh axis that scenes are sharded over."""

EXTRA_FIELDS = ("sigma_px_used", "tau_px_used", "num_groups")
"""Per-scene outputs of the association kept beside the :class:`Metrics` fields."""


def metric_fields() -> tuple[str, ...]:
    """Names of the :class:`~cdog_jax.metrics.Metrics` fields, in declaration order."""
    return tuple(f.name for f in dataclasses.fields(Metrics))


@dataclasses.dataclass(frozen=True, eq=False)
class SweepResult:
    """Per-scene results of :func:`sweep` (``S`` scenes in :meth:`Grid.flat` order).

    Attributes:
        grid: the grid that was swept.
        configs: config names, in the order given.
        sigma: ``(S,)`` float64 σ of each scene (pixels).
        count: ``(S,)`` int32 requested point count.
        scene: ``(S,)`` int32 scene index within its cell.
        num_points: ``(S,)`` int32 instances actually generated (``<= count``).
        capacity: ``(S,)`` int32 slot capacity (bucket) the scene ran at.
        metrics: ``{config: {field: (S,) array}}``, every :class:`Metrics` field plus
            ``sigma_px_used`` (σ given or estimated), ``tau_px_used`` and ``num_groups``.
        time_s: ``{config: (S,) float64}`` estimated association time per scene (module
            docstring; NaN when timing was off).
        wall_s: run time of the compiled bucket programs (generate + associate + score,
            all configs and scenes; includes copying the results to the host).
        compile_s: trace + compile time of those programs (0 for a program this process
            compiled before; a few seconds when read from the persistent cache).
        timing_s: time spent on the per-bucket timing afterwards (compiles included).
        config_repr: ``{config: repr(Config)}``.
        versions: ``{"jax": …, "jaxlib": …, "cdog_jax": …, "numpy": …}``.
        device: description of the devices the sweep ran on.
        num_devices: size of the scene mesh.
        buckets: bucket capacities.
        batch_size: scenes per ``lax.map`` step, per bucket.
        box: sampling box ``((x0, y0, z0), (x1, y1, z1))`` (scene units).
        rig: ``{"K": (M, 3, 3), "R": (M, 3, 3), "t": (M, 3)}`` numpy arrays of the views used.
    """

    grid: Grid
    configs: tuple[str, ...]
    sigma: np.ndarray
    count: np.ndarray
    scene: np.ndarray
    num_points: np.ndarray
    capacity: np.ndarray
    metrics: dict[str, dict[str, np.ndarray]]
    time_s: dict[str, np.ndarray]
    wall_s: float
    compile_s: float
    timing_s: float
    config_repr: dict[str, str]
    versions: dict[str, str]
    device: str
    num_devices: int
    buckets: tuple[int, ...]
    batch_size: tuple[int, ...]
    box: tuple[tuple[float, ...], tuple[float, ...]]
    rig: dict[str, np.ndarray]

    @property
    def num_scenes(self) -> int:
        """``S``."""
        return int(self.sigma.shape[0])

    def metrics_of(self, name: str, *, where: np.ndarray | None = None) -> Metrics:
        """The :class:`Metrics` (fields ``(S,)`` numpy, or ``(S',)`` under the boolean
        mask ``where (S,)``) of config ``name``, e.g. for :func:`cdog_jax.metrics.mean_metrics`."""
        fields = metric_fields()
        arrays = [self.metrics[name][f] for f in fields]
        if where is not None:
            arrays = [a[where] for a in arrays]
        # Built by unflattening (no __init__): the fields carry a batch axis.
        template = Metrics(**{f: jnp.zeros((), a.dtype) for f, a in zip(fields, arrays)})
        return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(template), arrays)

    def __eq__(self, other) -> bool:
        if not isinstance(other, SweepResult):
            return NotImplemented
        for f in dataclasses.fields(self):
            if not _equal(getattr(self, f.name), getattr(other, f.name)):
                return False
        return True

    __hash__ = None  # type: ignore[assignment]  # holds arrays


def _equal(a, b) -> bool:
    """Exact equality of nested dicts / tuples / arrays (same dtype, shape and values;
    NaN equals NaN)."""
    if isinstance(a, dict) or isinstance(b, dict):
        if not (isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys()):
            return False
        return all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        nan = np.issubdtype(a.dtype, np.floating)
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=nan)
    if isinstance(a, float) and isinstance(b, float) and np.isnan(a) and np.isnan(b):
        return True
    return type(a) is type(b) and a == b


# --------------------------------------------------------------------------- the compiled call


@dataclasses.dataclass(frozen=True)
class _Plan:
    """Everything static about one sweep program (hashable: the compile cache key)."""

    groups: tuple[tuple[Method, tuple[int, ...]], ...]  # (structure, config positions)
    capacities: tuple[int, ...]  # bucket capacities that hold scenes
    batch_sizes: tuple[int, ...]  # per-device lax.map batch size per bucket
    draw_capacity: int
    image_size: tuple[int, int]
    mesh: Mesh


def _scene_outputs(rig, box, thresholds, plan, capacity, batch, args):
    """Generate one scene, run every config on it and score it. Configs that differ only
    in numbers share one traced pipeline, mapped over their thresholds like scenes are
    (``batch = 1``: a scan, ~9× faster on CPU than vmapped while loops; else vmapped)."""
    key, count, sigma = args
    scene = generate_scene(
        key, rig, count, sigma, capacity=plan.draw_capacity, box=box, image_size=plan.image_size
    )
    scene = compact_scene(scene, capacity=capacity)
    per_group = []
    for stacked, (structure, members) in zip(thresholds, plan.groups):

        def run(one, structure=structure):
            res = structure.associate_scene(
                rig, Observations(scene.xy, scene.mask), one._replace(sigma_px=sigma)
            )
            return scene_metrics(rig, res, scene), (res.sigma_px, res.tau_px, res.num_groups)

        if len(members) == 1:
            out = jax.tree.map(lambda a: a[None], run(jax.tree.map(lambda a: a[0], stacked)))
        elif batch == 1:
            out = jax.lax.map(run, stacked)
        else:
            out = jax.vmap(run)(stacked)
        per_group.append(out)
    return scene.num_points, tuple(per_group)


def _map(fn, xs, batch: int):
    """``lax.map`` in steps of ``batch`` vmapped scenes; ``batch = 1`` is a plain scan of the
    unbatched function (no vmapped while loops: the fastest on CPU)."""
    return jax.lax.map(fn, xs, batch_size=batch if batch > 1 else None)


def _bucket_body(rig, box, thresholds, inputs, *, plan, bucket: int):
    """One bucket's scenes on all devices: ``(num_points, per-group outputs)``, each with
    the bucket's (padded) scene axis first."""
    capacity, batch = plan.capacities[bucket], plan.batch_sizes[bucket]

    def per_device(rig, box, thresholds, inputs):
        one = functools.partial(_scene_outputs, rig, box, thresholds, plan, capacity, batch)
        return _map(one, inputs, batch)

    if plan.mesh.devices.size == 1:
        # One device: nothing to split. Without shard_map's manual axes, refinement's
        # linear solves (lineax) trace too: under shard_map they fail ("pytree does not
        # match out_structure"), which _sweep refuses up front for a mesh of several devices.
        return per_device(rig, box, thresholds, inputs)
    rep, shard = PartitionSpec(), PartitionSpec(AXIS)
    return jax.shard_map(
        per_device,
        mesh=plan.mesh,
        in_specs=(rep, rep, rep, shard),
        out_specs=shard,
        # The pipeline's loops start from constant carries (replicated) that become
        # per-scene (varying) values; there are no collectives, so skip the VMA check.
        check_vma=False,
    )(rig, box, thresholds, inputs)


_COMPILED: dict = {}  # (plan, bucket, argument structure and shapes) -> compiled bucket
_COMPILED_MAX = 16  # executables kept (oldest dropped first)


def _compiled(plan: _Plan, bucket: int, args):
    """The compiled program of one bucket for ``plan`` and the argument shapes (cached in
    this process, and in the persistent compilation cache); and its compile time."""
    avals = jax.tree.map(lambda a: (a.shape, a.dtype), args)
    cache_key = (plan, bucket, jax.tree.structure(args), tuple(jax.tree.leaves(avals)))
    if cache_key in _COMPILED:
        return _COMPILED[cache_key], 0.0
    t0 = time.perf_counter()
    replicated = NamedSharding(plan.mesh, PartitionSpec())
    fn = jit(functools.partial(_bucket_body, plan=plan, bucket=bucket), out_shardings=replicated)
    compiled = fn.lower(*args).compile()
    elapsed = time.perf_counter() - t0
    _COMPILED[cache_key] = compiled
    while len(_COMPILED) > _COMPILED_MAX:
        del _COMPILED[next(iter(_COMPILED))]
    return compiled, elapsed


# --------------------------------------------------------------------------- progress


class SweepProgress(NamedTuple):
    """What a ``progress`` callback of :func:`sweep` receives after each bucket.

    Attributes:
        bucket: index of the finished bucket (among the non-empty ones).
        num_buckets: non-empty buckets in the sweep.
        capacity: slot capacity of the finished bucket.
        scenes_done: grid scenes in all finished buckets.
        num_scenes: grid scenes in the sweep.
        elapsed_s: seconds since the first bucket program started.
    """

    bucket: int
    num_buckets: int
    capacity: int
    scenes_done: int
    num_scenes: int
    elapsed_s: float


def print_progress(p: SweepProgress) -> None:
    """A ``progress`` callback for :func:`sweep` that prints one line per finished bucket."""
    expect_args("print_progress", p=(p, SweepProgress))
    print(
        f"  bucket {p.bucket + 1}/{p.num_buckets} (capacity {p.capacity}) done: "
        f"{p.scenes_done}/{p.num_scenes} scenes, {p.elapsed_s:.1f} s",
        flush=True,
    )


# --------------------------------------------------------------------------- the public sweep


def default_mesh() -> Mesh:
    """A one-axis mesh ``("scenes",)`` over every device of ``jax.devices()``."""
    return Mesh(np.asarray(jax.devices()), (AXIS,))


class _Layout(NamedTuple):
    """Scenes per non-empty bucket (host arrays), padded for the devices and batch size."""

    inputs: tuple  # per bucket (keys (n, 2), count (n,), sigma (n,)), n = D * steps * batch
    members: tuple  # per bucket: grid positions of its scenes (unpadded)
    capacities: tuple[int, ...]
    batch_sizes: tuple[int, ...]  # per-device lax.map batch size (<= the one asked for)
    gather: np.ndarray  # (S,) position of each grid scene in the concatenated buckets


def _layout(grid: Grid, buckets, batch_size, num_devices: int, dtype) -> _Layout:
    idx, keys = grid.flat(), np.asarray(grid.keys())
    which = bucket_of(idx.count, buckets)
    inputs, members, capacities, batches = [], [], [], []
    gather = np.zeros(grid.num_scenes, np.int32)
    offset = 0
    for b, capacity in enumerate(buckets):
        sel = np.flatnonzero(which == b)
        if sel.size == 0:
            continue
        # Per device: `steps` lax.map steps of `batch` scenes, with `batch` chosen so that
        # the padding is small and lax.map has no remainder (which would trace the whole
        # pipeline a second time, at another batch shape, doubling compile time).
        local = -(-sel.size // num_devices)
        steps = -(-local // batch_size[b])
        batch = -(-local // steps)
        n = steps * batch * num_devices
        pad = n - sel.size  # padding: empty scenes (count 0), dropped by `gather`
        inputs.append(
            (
                np.concatenate([keys[sel], np.zeros((pad, 2), keys.dtype)]),
                np.concatenate([idx.count[sel], np.zeros(pad, np.int32)]),
                np.concatenate([idx.sigma[sel], np.zeros(pad)]).astype(dtype),
            )
        )
        gather[sel] = offset + np.arange(sel.size, dtype=np.int32)
        offset += n
        members.append(sel)
        capacities.append(capacity)
        batches.append(batch)
    return _Layout(tuple(inputs), tuple(members), tuple(capacities), tuple(batches), gather)


def _check_memory(num_views: int, layout: _Layout, groups: dict, dtype) -> None:
    """Refuse before compiling when a bucket's step (``batch`` scenes, each with the configs
    of one structure vmapped when ``batch > 1``) would exceed the memory budget
    (:func:`cdog_jax._runtime.memory.check_memory`; buckets and structures run one after another)."""
    for capacity, batch in zip(layout.capacities, layout.batch_sizes):
        for structure, members in groups.items():
            at_once = batch * (len(members) if batch > 1 else 1)
            check_memory(
                f"sweep (bucket {capacity})",
                num_views,
                capacity,
                structure,
                dtype,
                at_once,
                vmapped=batch > 1,
            )


def _check_methods(methods) -> dict[str, Method]:
    """``{name: Method}`` from ``methods`` (a mapping of names to methods or registered
    names, or a sequence of registered names)."""
    if methods is None:
        methods = {"paper": Config.paper()}
    elif isinstance(methods, str):
        raise TypeError(
            f"sweep: methods must be a mapping {{name: method}} or a list of registered names; got the string {methods!r}"
        )
    elif not isinstance(methods, Mapping):
        methods = {name: name for name in methods}
    methods = dict(methods)
    if not methods:
        raise ValueError("sweep: methods must name at least one method")
    checked = {}
    for name, method in methods.items():
        if not isinstance(name, str) or not name or "/" in name or "," in name:
            raise ValueError(
                f"sweep: method names must be non-empty strings without '/' or ','; got {name!r}"
            )
        checked[name] = method_from(method, f"sweep (method {name!r})")
        if not checked[name].jittable:
            raise ValueError(
                f"sweep: method {name!r} runs on the host (NumPy) and cannot join the compiled sweep; "
                "run it on a sub-grid with cdog_jax.benchmark.sweep_host"
            )
    return checked


def _check_batch_size(batch_size, buckets, mesh: Mesh) -> tuple[int, ...]:
    if batch_size is None:
        # CPU: unbatched scans are fastest (measured: 2.5 s vs 4.4 s for a σ slice of the
        # paper grid at batch 16); accelerators want wide vmapped steps.
        batch_size = 1 if mesh.devices.flat[0].platform == "cpu" else 32
    if isinstance(batch_size, int):
        batch_size = (batch_size,) * len(buckets)
    batch_size = tuple(int(b) for b in batch_size)
    if len(batch_size) != len(buckets) or min(batch_size) < 1:
        raise ValueError(
            f"batch_size must be a positive int or one per bucket {buckets}; got {batch_size}"
        )
    return batch_size


def sweep(
    rig: Rig,
    grid: Grid,
    *,
    methods: Mapping[str, Method | str] | Sequence[str] | None = None,
    buckets: tuple[int, ...] = (20, 50, 90, 130),
    batch_size: int | tuple[int, ...] | None = None,
    box=DEFAULT_BOX,
    image_size: tuple[int, int] = IMAGE_SIZE,
    mesh: Mesh | None = None,
    timing: bool = True,
    timing_runs: int = 3,
    progress: Callable[[SweepProgress], None] | str | bool | None = "auto",
) -> SweepResult:
    """Generate, associate and score every scene of ``grid``: one compiled program per bucket.

    Args:
        rig: the cameras, ``K (M, 3, 3)``, ``R (M, 3, 3)``, ``t (M, 3)``; ``grid.views``
            selects a subset.
        grid: the scenes (σ × count × scenes per cell, seed).
        methods: ``{name: method}`` to run on every scene (a :class:`~cdog_jax.Method` or a
            registered name), or a list of registered names (default
            ``{"paper": Config.paper()}``). Each scene gets ``method.thresholds(σ)`` with
            its true σ (methods with ``sigma_mode="auto"`` estimate it themselves). Numbers
            are traced: changing only them reuses the compiled program, and methods that differ only
            in numbers (a tuning grid) share one pipeline, mapped over their thresholds.
        buckets: increasing slot capacities; a scene runs at the smallest one ``>=`` its
            count. The largest must hold the largest count.
        batch_size: scenes per ``lax.map`` step on each device (vmapped); one int or one
            per bucket. Bounds memory. Default: 1 on CPU (a plain scan), 32 otherwise.
        box: sampling box corners (scene units), as for ``generate_scene``.
        image_size: ``(width, height)`` for visibility (pixels).
        mesh: a one-axis ``Mesh`` named ``"scenes"``; default all devices.
        timing: estimate per-scene association time afterwards (module docstring).
        timing_runs: timed runs per chunk (the median is kept).
        progress: called on the host with a :class:`SweepProgress` each time a bucket
            finishes (e.g. :func:`print_progress`). Reported from the host between the
            bucket programs, so progress does not change what is compiled. ``"auto"``
            (default, or ``True``): a progress bar on stderr when it is a terminal, else none;
            ``False``: none. In a terminal a line also says while the sweep
            compiles.

    Returns:
        A :class:`SweepResult` with ``(S,)`` arrays in :meth:`Grid.flat` order.
    """
    expect_args("sweep", rig=(rig, Rig), grid=(grid, Grid))
    if isinstance(progress, bool):
        progress = "auto" if progress else None
    if isinstance(progress, str) and progress != "auto":
        raise ValueError(
            f"sweep: progress must be a callable, None, a bool or 'auto'; got {progress!r}"
        )
    if progress is not None and not isinstance(progress, str) and not callable(progress):
        raise TypeError(
            f"sweep: progress must be a callable, None, a bool or 'auto'; got {type(progress).__name__}"
        )
    methods = _check_methods(methods)
    close_bar = None
    if progress == "auto":
        progress, close_bar = sweep_bar(grid.num_scenes) if interactive() else (None, None)
    try:
        return _sweep(
            rig,
            grid,
            methods,
            buckets,
            batch_size,
            box,
            image_size,
            mesh,
            timing,
            timing_runs,
            progress,
        )
    finally:
        if close_bar is not None:
            close_bar()


def _sweep(
    rig, grid, configs, buckets, batch_size, box, image_size, mesh, timing, timing_runs, progress
) -> SweepResult:
    """:func:`sweep` after its ``progress`` is resolved to a callable or ``None`` and its
    methods to ``{name: Method}`` (``configs``)."""
    mesh = default_mesh() if mesh is None else mesh
    if tuple(mesh.axis_names) != (AXIS,):
        raise ValueError(
            f"mesh must have exactly one axis named {AXIS!r}; got {tuple(mesh.axis_names)}"
        )
    buckets = tuple(int(b) for b in buckets)
    batch_size = _check_batch_size(batch_size, buckets, mesh)
    if grid.views is not None:
        if max(grid.views) >= rig.num_views:
            raise ValueError(
                f"grid.views {grid.views} out of range for a rig of {rig.num_views} views"
            )
        rig = rig.select(grid.views)
    if timing_runs < 1:
        raise ValueError(f"timing_runs must be >= 1; got {timing_runs}")
    dtype = rig.K.dtype
    box = np.asarray(jnp.asarray(box, dtype))
    if box.shape != (2, 3):
        raise ValueError(f"box must be two (3,) corners; got shape {box.shape}")

    refining = [name for name, method in configs.items() if getattr(method, "refine", False)]
    if refining and mesh.devices.size > 1:
        raise ValueError(
            f"{refining[0]!r} refines points (refine=True), whose least-squares solver cannot run split over "
            f"{mesh.devices.size} devices; sweep it on one device (mesh=Mesh(jax.devices()[:1], ('scenes',))) or without refine"
        )
    layout = _layout(grid, buckets, batch_size, mesh.devices.size, dtype)
    # Configs that share a structure share one traced pipeline (mapped over their thresholds).
    groups: dict[Method, list[int]] = {}
    for i, config in enumerate(configs.values()):
        groups.setdefault(config.structure(), []).append(i)
    _check_memory(rig.num_views, layout, groups, dtype)
    plan = _Plan(
        groups=tuple((structure, tuple(members)) for structure, members in groups.items()),
        capacities=layout.capacities,
        batch_sizes=layout.batch_sizes,
        draw_capacity=grid.capacity,
        image_size=tuple(int(v) for v in image_size),
        mesh=mesh,
    )
    values = list(configs.values())
    thresholds = tuple(
        jax.tree.map(lambda *a: np.stack(a), *(_host_thresholds(values[i], dtype) for i in members))
        for _, members in plan.groups
    )
    replicated = NamedSharding(mesh, PartitionSpec())
    shared = jax.device_put((rig, box, thresholds), replicated)
    bucket_args = [
        (*shared, jax.device_put(inputs, NamedSharding(mesh, PartitionSpec(AXIS))))
        for inputs in layout.inputs
    ]
    with compiling(f"the sweep ({len(configs)} method(s), {len(layout.capacities)} bucket(s))"):
        programs = [_compiled(plan, b, args) for b, args in enumerate(bucket_args)]
    compile_s = sum(elapsed for _, elapsed in programs)
    t0 = time.perf_counter()
    outputs = [
        program(*args) for (program, _), args in zip(programs, bucket_args)
    ]  # all dispatched
    if progress is not None:
        done, total = 0, int(sum(m.size for m in layout.members))
        for b, out in enumerate(outputs):
            jax.block_until_ready(out)
            done += layout.members[b].size
            progress(
                SweepProgress(
                    b, len(outputs), layout.capacities[b], done, total, time.perf_counter() - t0
                )
            )
    # Buckets side by side (padding included), then back to grid order.
    stacked = jax.tree.map(lambda *a: np.concatenate(a, axis=0), *jax.device_get(outputs))
    num_points, per_group = jax.tree.map(lambda a: a[layout.gather], stacked)
    wall_s = time.perf_counter() - t0

    t0 = time.perf_counter()
    if timing:
        time_s = _time_buckets(rig, box, configs, grid, layout, plan.image_size, timing_runs)
    else:
        time_s = {name: np.full(grid.num_scenes, np.nan) for name in configs}
    timing_s = time.perf_counter() - t0 if timing else 0.0

    idx = grid.flat()
    capacity = np.zeros(grid.num_scenes, np.int32)
    for sel, cap in zip(layout.members, layout.capacities):
        capacity[sel] = cap
    return SweepResult(
        grid=grid,
        configs=tuple(configs),
        sigma=idx.sigma,
        count=idx.count,
        scene=idx.scene,
        num_points=np.asarray(num_points, np.int32),
        capacity=capacity,
        metrics=_per_config(per_group, plan, list(configs)),
        time_s=time_s,
        wall_s=float(wall_s),
        compile_s=float(compile_s),
        timing_s=float(timing_s),
        config_repr={name: repr(c) for name, c in configs.items()},
        versions=versions(),
        device=describe_devices(mesh),
        num_devices=int(mesh.devices.size),
        buckets=buckets,
        batch_size=batch_size,
        box=tuple(tuple(float(v) for v in corner) for corner in box),
        rig={"K": np.asarray(rig.K), "R": np.asarray(rig.R), "t": np.asarray(rig.t)},
    )


def _per_config(per_group, plan: _Plan, names: list[str]) -> dict[str, dict[str, np.ndarray]]:
    """Split the per-structure outputs (leaves ``(S, configs in the group)``) by config."""
    metrics, fields = {}, metric_fields()
    for (m, extra), (_, members) in zip(per_group, plan.groups):
        for j, i in enumerate(members):
            metrics[names[i]] = {f: np.asarray(getattr(m, f))[:, j] for f in fields}
            metrics[names[i]].update({f: np.asarray(v)[:, j] for f, v in zip(EXTRA_FIELDS, extra)})
    return {name: metrics[name] for name in names}


def _host_thresholds(config: Method, dtype):
    """``config.thresholds(0)`` as numpy scalars of ``dtype`` (σ is set per scene)."""
    return jax.tree.map(lambda a: np.asarray(a, dtype), config.thresholds(0.0, dtype=dtype))


@functools.partial(jit, static_argnames=("capacity", "draw_capacity", "image_size"))
def _chunk_scenes(rig, box, keys, count, sigma, *, capacity, draw_capacity, image_size):
    one = lambda k, c, s: compact_scene(  # noqa: E731
        generate_scene(k, rig, c, s, capacity=draw_capacity, box=box, image_size=image_size),
        capacity=capacity,
    )
    return jax.vmap(one)(keys, count, sigma)


TIMING_SCENES = 8
"""Scenes per timing chunk (rounded up to a multiple of the bucket's batch size)."""


@functools.partial(jit, static_argnames=("config", "batch"))
def _associate_chunk(rig, xy, mask, thresholds, *, config, batch):
    """The sweep's association step alone on a chunk of scenes (``lax.map`` as in the sweep)."""
    one = lambda a: config.associate_scene(rig, Observations(a[0], a[1]), a[2])  # noqa: E731
    return _map(one, (xy, mask, thresholds), batch)


def _time_buckets(rig, box, configs, grid, layout, image_size, runs):
    """Per-scene time estimates: median warm time of one chunk per bucket and config, run
    with the sweep's batch size, divided by the chunk size."""
    idx, keys = grid.flat(), np.asarray(grid.keys())
    dtype = rig.K.dtype
    time_s = {name: np.full(grid.num_scenes, np.nan) for name in configs}
    for sel, capacity, batch in zip(layout.members, layout.capacities, layout.batch_sizes):
        chunk = min(sel.size, batch * -(-TIMING_SCENES // batch))
        pick = sel[np.unique(np.linspace(0, sel.size - 1, chunk).round().astype(np.int64))]
        sigma = np.asarray(idx.sigma[pick], dtype)
        args = (jnp.asarray(keys[pick]), jnp.asarray(idx.count[pick]), jnp.asarray(sigma))
        scenes = _chunk_scenes(
            rig,
            jnp.asarray(box),
            *args,
            capacity=capacity,
            draw_capacity=grid.capacity,
            image_size=image_size,
        )
        for name, config in configs.items():
            thresholds = jax.tree.map(
                lambda a: np.broadcast_to(a, pick.shape).copy(), _host_thresholds(config, dtype)
            )
            thresholds = thresholds._replace(sigma_px=sigma)
            static = dict(config=config.structure(), batch=min(batch, pick.size))
            run = functools.partial(
                _associate_chunk, rig, scenes.xy, scenes.mask, thresholds, **static
            )
            jax.block_until_ready(run())  # compile and warm up
            times = []
            for _ in range(runs):
                t0 = time.perf_counter()
                jax.block_until_ready(run())
                times.append(time.perf_counter() - t0)
            time_s[name][sel] = float(np.median(times)) / pick.size
    return time_s


def versions() -> dict[str, str]:
    """Versions of the libraries that produce a sweep: jax, jaxlib, cdog_jax, numpy."""
    return {
        "jax": jax.__version__,
        "jaxlib": jaxlib.__version__,
        "cdog_jax": __version__,
        "numpy": np.__version__,
    }


def describe_devices(mesh: Mesh) -> str:
    """A short description of the mesh's devices, e.g. ``"cpu: 4 × cpu (1 process)"``."""
    devices = list(mesh.devices.flat)
    kinds = sorted({d.device_kind for d in devices})
    processes = len({d.process_index for d in devices})
    plural = "es" if processes > 1 else ""
    return (
        f"{devices[0].platform}: {len(devices)} × {', '.join(kinds)} ({processes} process{plural})"
    )
