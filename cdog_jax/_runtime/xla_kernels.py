"""XLA's own CPU kernels for the small reductions and products of our programs.

XLA's CPU backend hands some fusions (sums over an axis, small dot products) to its YNN
library. For our programs' shapes (a sum over two or three coordinates, a 3 × 3 product,
thousands of small kernels a call) XLA's own kernels are faster: on a 2-core CPU a live
Shelf-like frame takes 1.3–2.2 ms less and the warm benchmark grid 15 % less, with the same
groups, labels and points (sums whose terms are added in another order may round the last
bit of a reprojection error or σ differently). XLA reads the switch once, when JAX starts
its backend, for the whole process: the command line sets it for its own process; a
library user sets ``XLA_FLAGS`` before starting Python (docs/LIVE.md).
"""

from __future__ import annotations

import os

from jax._src import xla_bridge

FLAG = "--xla_cpu_experimental_ynn_fusion_type="
"""The switch (an empty list of fusion kinds for the YNN library)."""

MEASURED_JAXLIB = ("0.10.",)
"""jaxlib releases the switch was measured with. An XLA that does not know a flag stops
the process when it starts, so the switch is set only on these."""


def use_xla_kernels() -> bool:
    """Set :data:`FLAG` in ``XLA_FLAGS`` for this process, before JAX starts its backend.

    Returns whether it did: not once JAX has run an operation (its flags are read), where
    ``XLA_FLAGS`` already chooses the YNN fusions, or on a jaxlib not in
    :data:`MEASURED_JAXLIB`.
    """
    flags = os.environ.get("XLA_FLAGS", "")
    if xla_bridge.backends_are_initialized() or "ynn_fusion_type" in flags:
        return False
    try:
        import jaxlib

        version = str(jaxlib.__version__)
    except (ImportError, AttributeError):
        return False
    if not version.startswith(MEASURED_JAXLIB):
        return False
    os.environ["XLA_FLAGS"] = f"{flags} {FLAG}".strip()
    return True
