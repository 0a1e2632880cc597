"""The memory estimate: known from the shapes, checked before compiling, close to XLA's."""

import platform
import time

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import FAST_COMPILE_FLAGS, ring_rig, run_with_xla_defaults

import cdog_jax
from cdog_jax import Config, associate, associate_batch
from cdog_jax._associate import _associate_jit, _prepare
from cdog_jax._runtime.memory import (
    ENV_BUDGET,
    check_memory,
    estimate_peak_bytes,
    limit_heap_arenas,
    map_large_blocks,
    memory_budget_bytes,
    release_freed_memory,
)
from cdog_jax._runtime.stored_programs import loaded_programs


def test_ten_thousand_detections_per_view_are_refused_before_compiling(monkeypatch):
    monkeypatch.delenv(ENV_BUDGET, raising=False)
    rig = ring_rig(10)
    xy = np.random.default_rng(0).uniform(0, 640, (10, 10_000, 2)).astype(np.float32)
    mask = np.ones((10, 10_000), bool)
    before = _associate_jit._cache_size() + loaded_programs()
    t0 = time.perf_counter()
    with pytest.raises(
        MemoryError, match=r"10 views × 10000 slots need about 18[0-9]\.[0-9] GB"
    ) as info:
        associate(rig, xy, mask, method=Config.paper(), memory_budget_gb=20.0)
    assert time.perf_counter() - t0 < 1.0
    assert (
        _associate_jit._cache_size() + loaded_programs() == before
    )  # nothing was traced or compiled
    message = str(info.value)
    assert (
        "memory budget of 20.0 GB" in message
        and "smaller capacity P (at most" in message
        and ENV_BUDGET in message
    )
    # The default budget comes from this machine's memory; the estimate exceeds any of today's.
    with pytest.raises(MemoryError, match="of physical memory|memory\\)"):
        associate(rig, xy, mask, method=Config.paper())


def test_budget_from_the_environment_and_per_chunk_in_a_batch(monkeypatch):
    rig = ring_rig(4)
    xy, mask = np.zeros((8, 4, 300, 2), np.float32), np.ones((8, 4, 300), bool)
    one = estimate_peak_bytes(4, 300, Config.paper(), batch_size=4)
    monkeypatch.setenv(ENV_BUDGET, str(one / 1e9 * 0.99))
    with pytest.raises(MemoryError, match=f"4 scenes at a time.*{ENV_BUDGET}=.*smaller batch_size"):
        associate_batch(rig, xy, mask, method=Config.paper(), batch_size=4)
    monkeypatch.setenv(ENV_BUDGET, "lots")
    with pytest.raises(ValueError, match=ENV_BUDGET):
        memory_budget_bytes()
    monkeypatch.setenv(ENV_BUDGET, str(one / 1e9 * 1.01))
    assert check_memory("x", 4, 300, Config.paper(), np.float32, 4) == one  # passes: no error
    with pytest.raises(MemoryError):
        check_memory("x", 4, 300, Config.paper(), np.float32, 8)


def test_estimate_is_monotone():
    for config in (
        Config.paper(),
        Config.reference(),
        Config.extended(support_filter=True, refine=True),
    ):
        by_p = [estimate_peak_bytes(5, p, config) for p in (1, 10, 100, 1000)]
        by_m = [estimate_peak_bytes(m, 50, config) for m in (2, 5, 10, 20)]
        by_b = [estimate_peak_bytes(5, 50, config, batch_size=b) for b in (1, 2, 8, 32)]
        for seq in (by_p, by_m, by_b):
            assert all(a < b for a, b in zip(seq, seq[1:]))
        assert estimate_peak_bytes(5, 50, config, dtype=jnp.float64) > estimate_peak_bytes(
            5, 50, config, dtype=jnp.float32
        )


def estimate_is_within_a_factor_of_xla():
    """The estimate against XLA's own figure for the program (temporaries, arguments,
    outputs): an upper bound, at most 1.5 times it."""
    for name, M, P in (("paper", 4, 64), ("reference", 8, 32), ("best", 8, 32), ("best", 3, 16)):
        config = getattr(Config, name)()
        static, thresholds = _prepare(config, 1.0, None, jnp.float32)
        compiled = _associate_jit.lower(
            ring_rig(M), jnp.zeros((M, P, 2)), jnp.ones((M, P), bool), thresholds, method=static
        ).compile()
        analysis = compiled.memory_analysis()
        xla = (
            analysis.temp_size_in_bytes
            + analysis.argument_size_in_bytes
            + analysis.output_size_in_bytes
        )
        ratio = estimate_peak_bytes(M, P, config) / xla
        assert 1.0 <= ratio <= 1.5, (name, M, P, ratio)


# The suite's switches that change what XLA fuses; the other three (LLVM's optimisation
# level, the instruction set, machine code in one piece) change only the machine code.
_FUSION_SWITCHES = " ".join(
    flag
    for flag in FAST_COMPILE_FLAGS.split()
    if not flag.startswith(
        (
            "--xla_backend_optimization_level",
            "--xla_cpu_max_isa",
            "--xla_cpu_parallel_codegen_split_count",
        )
    )
)


def test_estimate_is_within_a_factor_of_xla():
    """As a library call compiles the program (XLA's fusion and the program's own compile
    options), in a child process: the suite's fusion switch (tests/conftest.py) fuses less
    and needs more temporary memory. Its code-generation switches stay on: they change no
    buffer (the same sizes as XLA's defaults for these four programs) and compile about a
    third faster."""
    run_with_xla_defaults(__file__, "estimate_is_within_a_factor_of_xla", switches=_FUSION_SWITCHES)


def test_the_public_namespace_names_the_estimate():
    assert cdog_jax.estimate_peak_bytes is estimate_peak_bytes


def test_the_c_heap_is_capped_and_trimmed_under_glibc_and_left_alone_elsewhere(monkeypatch):
    """A command's process caps glibc's arenas and hands free pages back between parts; in
    another C library (no ``malloc_trim``) both do nothing and say so."""
    import ctypes
    import platform
    import subprocess
    import sys

    code = (
        "from cdog_jax._runtime.memory import limit_heap_arenas, release_freed_memory;"
        "import numpy as np; a = [np.ones(1 << 16) for _ in range(200)]; del a;"
        "print(limit_heap_arenas(), release_freed_memory())"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    capped, trimmed = done.stdout.split()
    assert capped == str(platform.libc_ver()[0] == "glibc") and trimmed in ("True", "False")

    def no_libc(*args, **kwargs):
        raise OSError("libc.so.6: cannot open shared object file")

    monkeypatch.setattr(ctypes, "CDLL", no_libc)
    assert limit_heap_arenas() is False and release_freed_memory() is False
    assert map_large_blocks() is False


_FRAGMENTS = """
import sys
import numpy as np
from cdog_jax._runtime.memory import map_large_blocks
if sys.argv[1] == "mapped":
    assert map_large_blocks()
def resident():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * 4096
big = np.ones(16 << 17); del big  # a 16 MiB block freed: glibc raises its threshold to it
before = resident()
blocks = [np.ones(1 << 18) for _ in range(50)]  # 50 tables of 2 MiB
last = blocks[-1]; del blocks  # all freed but the last
print((resident() - before) / 2**20)
"""


@pytest.mark.skipif(platform.libc_ver()[0] != "glibc", reason="glibc's heap only")
def test_large_tables_go_back_to_the_system_when_freed():
    """With glibc's own threshold, 2 MiB tables freed below one still alive stay resident
    (the heap cannot shrink under it): a long recording's peak grew part by part. With the
    command's fixed threshold each is unmapped when freed."""
    import subprocess
    import sys

    def grown(mode):
        done = subprocess.run(
            [sys.executable, "-c", _FRAGMENTS, mode], capture_output=True, text=True
        )
        assert done.returncode == 0, done.stderr
        return float(done.stdout)

    assert grown("default") > 50.0
    assert grown("mapped") < 10.0
