"""The command line's switch to XLA's own CPU kernels for small sums and products
(cdog_jax/_runtime/xla_kernels.py): set before JAX starts its backend, on a jaxlib it was
measured with, never over a choice already in ``XLA_FLAGS``, never once JAX runs."""

import os
import subprocess
import sys

import jax.numpy as jnp

from cdog_jax._runtime import xla_kernels


def test_not_set_once_jax_runs(monkeypatch):
    jnp.zeros(1).block_until_ready()  # the backend runs: its flags are read
    monkeypatch.setenv("XLA_FLAGS", "--xla_cpu_max_isa=SSE4_2")
    assert not xla_kernels.use_xla_kernels()
    assert os.environ["XLA_FLAGS"] == "--xla_cpu_max_isa=SSE4_2"


def test_set_before_jax_starts_and_known_to_its_xla():
    code = (
        "import os, jaxlib\n"
        "from cdog_jax._runtime import xla_kernels as k\n"
        "k.MEASURED_JAXLIB = ('no such release',)\n"
        "first = k.use_xla_kernels()\n"
        "k.MEASURED_JAXLIB = (jaxlib.__version__,)\n"
        "second, third = k.use_xla_kernels(), k.use_xla_kernels()\n"
        "import jax.numpy as jnp\n"
        "total = float(jnp.arange(4.0).sum())  # XLA starts with the flag (or stops the process)\n"
        "print(first, second, third, total, os.environ['XLA_FLAGS'])\n"
    )
    env = dict(os.environ, XLA_FLAGS="--xla_cpu_max_isa=SSE4_2")
    done = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    )
    assert done.stdout.split() == [
        "False",
        "True",
        "False",  # XLA_FLAGS chooses already
        "6.0",
        "--xla_cpu_max_isa=SSE4_2",
        xla_kernels.FLAG,
    ], done.stdout + done.stderr
