"""``use_cpu_cores``: one JAX CPU device per core, chosen before JAX runs anything; a count
the user chose is kept; too late is an error that says what to do. Each case runs in a
fresh process (JAX fixes its devices once per process)."""

import os
import subprocess
import sys

import pytest

from cdog_jax.benchmark import use_cpu_cores
from cdog_jax.benchmark._cpu_cores import usable_cores


def _run(code: str, **env) -> str:
    environment = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    environment.update(env)
    done = subprocess.run(
        [sys.executable, "-c", code], env=environment, capture_output=True, text=True, check=True
    )
    return done.stdout.strip()


def test_a_fresh_process_gets_one_device_per_core_or_the_count_asked_for():
    code = (
        "import jax\nfrom cdog_jax.benchmark import use_cpu_cores\n"
        "n = use_cpu_cores({arg})\nprint(n, len(jax.devices('cpu')))"
    )
    assert _run(code.format(arg="")) == f"{usable_cores()} {usable_cores()}"
    assert _run(code.format(arg="count=3")) == "3 3"


def test_a_count_the_user_chose_is_kept():
    code = "import jax\nfrom cdog_jax.benchmark import use_cpu_cores\nn = use_cpu_cores()\nprint(n, len(jax.devices('cpu')))"
    assert _run(code, XLA_FLAGS="--xla_force_host_platform_device_count=3") == "3 3"


def test_too_late_is_an_error_that_says_what_to_do():
    code = (
        "import jax, jax.numpy as jnp\nfrom cdog_jax.benchmark import use_cpu_cores\n"
        "jnp.zeros(2).block_until_ready()\n"
        "have = len(jax.devices('cpu'))\nassert use_cpu_cores() == have\n"
        "try:\n    use_cpu_cores(count=have + 1)\nexcept RuntimeError as e:\n    print(e)\n"
    )
    message = _run(code)
    assert "already runs with 1 CPU device(s)" in message and "right after `import jax`" in message


def test_a_count_below_one_is_refused():
    with pytest.raises(ValueError, match="count must be at least 1"):
        use_cpu_cores(count=0)
