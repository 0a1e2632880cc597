"""The command line's switch to XLA's own CPU kernels for small sums and products
(cdog_jax/_runtime/xla_kernels.py): set before JAX starts its backend, on a jaxlib it was
measured with, never over a choice already in ``XLA_FLAGS``, never once JAX runs."""

import os
import subprocess
import sys

import jax.numpy as jnp
import pytest
from helpers import ring_rig, run_with_xla_defaults

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


def programs_compile_with_xla_kernels():
    """Without any switch in ``XLA_FLAGS`` (XLA's defaults, as a library user runs): XLA hands
    small sums to its YNN library; the package's ``jit`` asks for its own kernels for that
    program alone, with the same results."""
    import jax
    import numpy as np

    from cdog_jax.people._persons import _retriangulate

    rig = ring_rig(4)
    rng = np.random.default_rng(0)
    xy = jnp.asarray(rng.uniform(100.0, 500.0, (16, 4, 2)), jnp.float32)
    member = jnp.asarray(rng.random((16, 4)) > 0.2)
    weights = jnp.ones((16, 4), jnp.float32)
    args = (rig, xy, member, weights)
    plain = jax.jit(_retriangulate.__wrapped__).lower(*args).compile()
    own = _retriangulate.lower(*args).compile()
    assert "__ynn_fusion" in plain.as_text()
    assert "__ynn_fusion" not in own.as_text()
    for a, b in zip(jax.tree.leaves(own(*args)), jax.tree.leaves(plain(*args))):
        assert np.allclose(a, b, rtol=1e-5, atol=1e-5, equal_nan=True)


def test_programs_compile_with_xla_kernels_without_a_process_setting():
    run_with_xla_defaults(__file__, "programs_compile_with_xla_kernels")


def test_a_jit_with_compile_options_is_refused_inside_another():
    """Why :func:`xla_kernels.jit` serves only programs called from the host: JAX refuses a
    nested ``jit`` with compile options (a user's ``jit`` around such a function fails)."""
    import jax

    inner = xla_kernels.jit(lambda x: x + 1.0)
    assert float(inner(jnp.float32(1.0))) == 2.0
    with pytest.raises(ValueError, match="compiler_options"):
        jax.jit(lambda x: inner(x) * 2.0)(jnp.float32(1.0))


def test_only_where_jax_runs_on_its_cpu(monkeypatch):
    """The compile option is a CPU switch: not asked for where an accelerator may be JAX's
    backend (chosen first, or a plugin for one installed)."""
    import importlib.metadata

    monkeypatch.setenv("JAX_PLATFORMS", "cuda,cpu")
    assert not xla_kernels._cpu_is_the_backend()
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    assert xla_kernels._cpu_is_the_backend()
    monkeypatch.setenv("JAX_PLATFORMS", "")
    monkeypatch.setattr(
        importlib.metadata, "entry_points", lambda group: ["jax_plugins.xla_cuda12"]
    )
    assert not xla_kernels._cpu_is_the_backend()
    code = "from cdog_jax._runtime import xla_kernels as k\nprint(k.COMPILER_OPTIONS)\n"
    # This machine runs JAX on its CPU (the parent's options): chosen so, the same options.
    for platforms, expected in (("cpu", repr(xla_kernels.COMPILER_OPTIONS)), ("tpu", "None")):
        env = dict(os.environ, JAX_PLATFORMS=platforms)
        done = subprocess.run(
            [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
        )
        assert done.stdout.strip() == expected, done.stdout + done.stderr
