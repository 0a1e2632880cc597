"""The named C-DOG configurations that comparisons share: the methods of
``cdog-jax benchmark --methods`` and the cumulative stages of the per-stage ablation."""

from __future__ import annotations

from collections.abc import Callable

from .._config import Config

# Name → a function that makes the configuration (made when used, not at import).
METHODS: dict[str, Callable[[], Config]] = {
    "paper": lambda: Config.paper(),
    "no_iqr": lambda: Config.paper(iqr=False),
    "reference": lambda: Config.reference(),
    "extended": lambda: Config.extended(),
}
DEFAULT_METHODS = ("paper", "no_iqr", "reference", "extended")


def ablation_stages() -> dict[str, Config]:
    """C-DOG built up one stage at a time, in order, each row adding one stage to the one
    before: the epipolar graph with view-uniqueness only, + δ-overlap pruning (Alg. 2),
    + IQR (Alg. 3), + the BPE jump filter (§IV-E) = ``paper()``, then union adjacency,
    + recovery by reprojection, + regrouping = ``extended()``."""
    return {
        "graph + split": Config.paper(prune_scope="none", iqr=False, bpe_filter=False),
        "+ δ-pruning": Config.paper(iqr=False, bpe_filter=False),
        "+ IQR": Config.paper(bpe_filter=False),
        "+ BPE filter = paper()": Config.paper(),
        "+ union adjacency": Config.paper(adjacency="union"),
        "+ recovery": Config.paper(adjacency="union", recover=True, recover_frac=2.0),
        "+ regroup = extended()": Config.extended(),
    }
