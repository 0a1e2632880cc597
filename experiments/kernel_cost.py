"""What does XLA's CPU backend pay per kernel when it compiles a program?

Question: compile time of the pipeline is not proportional to its HLO instruction count
(``experiments/compile_profile.py``). What is it proportional to?

Method: synthetic programs of ``K`` independent blocks, each ``y = x · c + 1`` on a
``(160, 10)`` array (the size of a group table), optionally followed by transcendental
functions (``sin``, ``exp``, ``sqrt``), then summed; an ``optimization_barrier`` keeps
XLA from fusing the blocks together, so each block is its own kernels. Two variants:
every block with its own constant ``c = k + 1`` (``K`` distinct kernels) or the same
constant everywhere (``K`` copies of one kernel). Compile seconds (persistent cache off),
one fresh compile each. Run it under different ``XLA_FLAGS`` to compare XLA's switches.

Usage: ``python experiments/kernel_cost.py [--blocks 1,50,200,400]``.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("CDOG_JAX_CACHE", "0")

import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
from jax import lax  # noqa: E402


def program(num_blocks: int, heavy: bool, same: bool):
    def f(xs):
        outs = []
        for k in range(num_blocks):
            y = xs[k] * (2.0 if same else k + 1.0) + 1.0
            if heavy:
                y = jnp.sin(y) * jnp.exp(-y) + jnp.sqrt(jnp.abs(y))
            outs.append(lax.optimization_barrier(y).sum())
        return jnp.stack(outs)

    return f


def main(blocks=(1, 50, 200, 400)) -> None:
    print(f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}")
    print("blocks  heavy  copies | fusions  compile s  ms per fusion")
    for heavy in (False, True):
        for same in (False, True):
            for k in blocks:
                xs = [jnp.full((160, 10), float(i)) for i in range(k)]
                lowered = jax.jit(program(k, heavy, same)).lower(xs)
                t0 = time.perf_counter()
                compiled = lowered.compile()
                seconds = time.perf_counter() - t0
                fusions = compiled.as_text().count(" fusion(")
                print(
                    f"{k:6d} {str(heavy):>6} {str(same):>7} | {fusions:7d} {seconds:10.2f} {1e3 * seconds / max(fusions, 1):14.1f}"
                )


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--blocks", default="1,50,200,400")
    main(tuple(int(b) for b in parser.parse_args().blocks.split(",")))
