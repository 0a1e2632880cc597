"""One JAX device per CPU core, so that a sweep on a CPU uses every core.

XLA runs a compiled program of small operations on one core of a CPU: the sweep's scenes
run one after another. JAX can present the CPU as several devices instead; :func:`sweep`
shards its scenes over every device of its mesh, so with one device per core the scenes
run on all cores at once (2 cores: the full grid warm in about half the time, the same
numbers). The device count must be chosen before JAX runs its first operation.
"""

from __future__ import annotations

import os
import re

import jax
from jax._src import xla_bridge


def usable_cores() -> int:
    """Cores this process may run on (its CPU affinity where the platform has one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # macOS, Windows
        return max(1, os.cpu_count() or 1)


def use_cpu_cores(*, count: int | None = None) -> int:
    """Give JAX ``count`` CPU devices (default: one per usable core) for :func:`sweep`.

    Call it right after ``import jax`` and before any JAX operation: JAX fixes its devices
    when it first runs something. A count the user already chose (``jax_num_cpu_devices``,
    ``XLA_FLAGS``) is kept. Other work is unaffected: arrays and single-scene calls still
    live on the first device.

    Returns:
        The number of CPU devices JAX will have.

    Raises:
        RuntimeError: JAX has already run an operation (its devices are fixed), and the
            count asked for is not the one it has.
        ValueError: ``count`` is below 1.
    """
    if count is not None and int(count) < 1:
        raise ValueError(f"use_cpu_cores: count must be at least 1; got {count}")
    wanted = usable_cores() if count is None else int(count)
    if xla_bridge.backends_are_initialized():
        have = len(jax.devices("cpu"))
        if count is not None and have != wanted:
            raise RuntimeError(
                f"use_cpu_cores: JAX already runs with {have} CPU device(s); call use_cpu_cores(count={wanted}) "
                "right after `import jax`, before any JAX operation"
            )
        return have
    chosen = _chosen_count()
    if count is None and chosen is not None:
        return chosen
    jax.config.update("jax_num_cpu_devices", wanted)
    return wanted


def _chosen_count() -> int | None:
    """The CPU device count the user already chose (``jax_num_cpu_devices`` first, then
    ``XLA_FLAGS=--xla_force_host_platform_device_count=N``), or None."""
    if int(jax.config.jax_num_cpu_devices) > 0:
        return int(jax.config.jax_num_cpu_devices)
    match = re.search(
        r"xla_force_host_platform_device_count=(\d+)", os.environ.get("XLA_FLAGS", "")
    )
    return int(match.group(1)) if match else None
