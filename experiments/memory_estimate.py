"""The memory estimate against XLA's own figure, preset by preset and shape by shape.

``cdog_jax.estimate_peak_bytes`` decides before compiling whether a scene fits the memory
budget (docs/ALGORITHM.md §14). Here each preset's single-scene program is compiled as a
library call compiles it (its own compile options; run without ``XLA_FLAGS`` for XLA's
defaults) and XLA's ``memory_analysis()`` (temporaries + arguments + outputs) is set beside
the estimate. The estimate should be an upper bound, at most 1.5 times XLA's figure.

    python experiments/memory_estimate.py
    python experiments/memory_estimate.py --presets best --shapes 10x1000 --dtype float64
"""

from __future__ import annotations

import argparse

import jax
import jax.numpy as jnp
import numpy as np

import cdog_jax
from cdog_jax import Config
from cdog_jax._associate import _associate_jit, _prepare  # the program a call compiles
from cdog_jax.synthetic import default_rig

PRESETS = ("paper", "reference", "extended", "best")
SHAPES = ((3, 16), (4, 64), (8, 32), (10, 32), (10, 1000), (4, 3000))


def xla_bytes(name: str, M: int, P: int, dtype) -> int:
    """XLA's figure for ``associate``'s program of preset ``name`` on M views × P slots."""
    config = getattr(Config, name)()
    static, thresholds = _prepare(config, 1.0, None, dtype)
    rig = default_rig(num_views=M)
    rig = jax.tree.map(
        lambda a: a.astype(dtype) if jnp.issubdtype(a.dtype, jnp.floating) else a, rig
    )
    compiled = _associate_jit.lower(
        rig, jnp.zeros((M, P, 2), dtype), jnp.ones((M, P), bool), thresholds, method=static
    ).compile()
    a = compiled.memory_analysis()
    return a.temp_size_in_bytes + a.argument_size_in_bytes + a.output_size_in_bytes


def main(argv=None) -> None:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--presets", default=",".join(PRESETS))
    p.add_argument("--shapes", default=",".join(f"{m}x{q}" for m, q in SHAPES))
    p.add_argument("--dtype", default="float32", choices=("float32", "float64"))
    args = p.parse_args(argv)
    if args.dtype == "float64":
        jax.config.update("jax_enable_x64", True)
    dtype = np.dtype(args.dtype)
    print("| preset | views × slots | XLA (bytes per pair) | estimate (bytes per pair) | ratio |")
    print("|---|---|---|---|---|")
    for name in args.presets.split(","):
        for shape in args.shapes.split(","):
            M, P = (int(v) for v in shape.split("x"))
            xla = xla_bytes(name, M, P, dtype)
            estimate = cdog_jax.estimate_peak_bytes(M, P, getattr(Config, name)(), dtype=dtype)
            N2 = float(M * P) ** 2
            print(
                f"| `{name}()` | {M} × {P} | {xla / N2:.2f} | {estimate / N2:.2f} | "
                f"{estimate / xla:.2f} |",
                flush=True,
            )


if __name__ == "__main__":
    main()
