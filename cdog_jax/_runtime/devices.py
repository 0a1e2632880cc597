"""Where the chunks of a batch run: one device after another, so that a machine with several
devices (GPUs, or CPU cores exposed as devices) runs several chunks at once.

XLA runs a program of small operations on one CPU core: a batch of scenes in chunks would
use one core of many. JAX can expose the host's cores as separate CPU devices
(``jax_num_cpu_devices``, set before its first computation); the chunks of a batch then go
round-robin over the devices and run side by side. Each chunk runs the same program as on
one device, so results are bitwise the same whatever the device count.

The library changes no JAX setting on import: :func:`cdog_jax.benchmark.use_cpu_cores`
makes the setting; the command line calls it for its own process, a user at the start of a
script.
"""

from __future__ import annotations

import jax


def chunk_devices(num_chunks: int) -> list:
    """The device of each of ``num_chunks`` chunks of a batch: the default backend's local
    devices in turn (all the same device where there is one, or one chunk)."""
    devices = jax.local_devices()
    if num_chunks < 2 or len(devices) < 2:
        return [None] * num_chunks
    return [devices[k % len(devices)] for k in range(num_chunks)]
