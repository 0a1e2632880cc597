"""Where the chunks of a batch run: one device after another, so that a machine with several
devices (GPUs, or CPU cores exposed as devices) runs several chunks at once.

XLA runs a program of small operations on one CPU core: a batch of scenes in chunks would
use one core of many. JAX can expose the host's cores as separate CPU devices
(``jax_num_cpu_devices``, set before its first computation); the chunks of a batch then go
round-robin over the devices and run side by side. Each chunk runs the same program as on
one device, so results are bitwise the same whatever the device count.

The library changes no JAX setting on import: :func:`use_cpu_cores` is called by the
command line (its own process) and may be called by a user at the start of a script.
"""

from __future__ import annotations

import os

import jax

MAX_CPU_DEVICES = 8
"""Cores the command line exposes as CPU devices at most (more chunks in flight than this
only add memory)."""


def usable_cores() -> int:
    """CPU cores this process may run on (its affinity where the platform tells it)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def use_cpu_cores(*, count: int | None = None) -> bool:
    """Expose ``count`` CPU cores (default: the usable ones, at most
    :data:`MAX_CPU_DEVICES`) as JAX CPU devices, so that batches run on all of them.

    Only possible before JAX's first computation in the process, and only where the user
    has not chosen a device count (``jax_num_cpu_devices`` or ``XLA_FLAGS``'s
    ``--xla_force_host_platform_device_count``). Returns whether the setting was made;
    never raises (too late, or a JAX without the option: nothing changes)."""
    count = min(usable_cores(), MAX_CPU_DEVICES) if count is None else int(count)
    if count < 2 or "xla_force_host_platform_device_count" in os.environ.get("XLA_FLAGS", ""):
        return False
    try:
        if getattr(jax.config, "jax_num_cpu_devices", -1) not in (-1, None):
            return False  # chosen already
        jax.config.update("jax_num_cpu_devices", count)
    except (AttributeError, RuntimeError, ValueError):  # too late in this process, or no such option
        return False
    return True


def chunk_devices(num_chunks: int) -> list:
    """The device of each of ``num_chunks`` chunks of a batch: the default backend's local
    devices in turn (all the same device where there is one, or one chunk)."""
    devices = jax.local_devices()
    if num_chunks < 2 or len(devices) < 2:
        return [None] * num_chunks
    return [devices[k % len(devices)] for k in range(num_chunks)]
