"""experiments/compare_methods.py: a C-DOG config's cache key covers the files of its stages."""

import importlib.util
import pathlib
import sys

from cdog_jax import Config
from cdog_jax.baselines import SoftBA
from cdog_jax.benchmark import Grid

SCRIPT = pathlib.Path(__file__).resolve().parents[1] / "experiments" / "compare_methods.py"


def _load():
    spec = importlib.util.spec_from_file_location("compare_methods_script", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # its dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def test_cache_key_hashes_the_stage_files(monkeypatch, tmp_path):
    script = _load()
    names = {m.__name__ for m in script._rule_modules(Config.best())}
    # the stages' own files and what they use (seeding's hypotheses), not only cdog/_pipeline.py
    assert {
        "cdog_jax.refine._seed",
        "cdog_jax.refine._hypotheses",
        "cdog_jax.refine._ambiguity",
        "cdog_jax.refine._reassign",
        "cdog_jax.graph._graph_stage",
    } <= names
    assert "cdog_jax.refine._seed" not in {m.__name__ for m in script._rule_modules(Config.paper())}
    assert script._rule_modules(SoftBA()) == []
    base = Grid.quick()
    before = script.cache_folder(str(tmp_path), "best", Config.best(), base)
    assert script.cache_folder(str(tmp_path), "best", Config.best(), base) == before
    # A changed stage file (here: its hash) changes the folder.
    real = script._source_hash
    monkeypatch.setattr(
        script,
        "_source_hash",
        lambda *objs: (
            real(*objs)
            + (
                "x"
                if any(getattr(o, "__name__", "") == "cdog_jax.refine._seed" for o in objs)
                else ""
            )
        ),
    )
    assert script.cache_folder(str(tmp_path), "best", Config.best(), base) != before
