"""The named methods that comparisons share: every registered method
(:func:`cdog_jax.method_names`) and the benchmark's ablation ``no_iqr``, the methods of
``cdog-jax benchmark --methods``; and the cumulative stages of the per-stage ablation."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Mapping

from .._method import Method, method_from, method_names
from ..cdog._pipeline import Config

ABLATIONS: dict[str, Callable[[], Method]] = {"no_iqr": lambda: Config.paper(iqr=False)}
"""Benchmark-only variants (not registered for :func:`cdog_jax.associate`)."""


class _NamedMethods(Mapping):
    """Name → a function that makes the method: the registry as it is now (a method
    registered later appears too), then :data:`ABLATIONS`."""

    def __getitem__(self, name: str) -> Callable[[], Method]:
        if name in ABLATIONS:
            return ABLATIONS[name]
        if name in method_names():
            return lambda: method_from(name, "benchmark")
        raise KeyError(name)

    def __iter__(self) -> Iterator[str]:
        yield from method_names()
        yield from (name for name in ABLATIONS if name not in method_names())

    def __len__(self) -> int:
        return sum(1 for _ in self)


METHODS: Mapping[str, Callable[[], Method]] = _NamedMethods()
DEFAULT_METHODS = ("best", "extended", "paper", "reference")


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
