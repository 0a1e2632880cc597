"""C-DOG's stage list: the order each preset runs, and each stage's own options."""

from __future__ import annotations

import dataclasses

from cdog_jax import STAGES, Config
from cdog_jax.cdog._pipeline import SCENE, plan

SWITCHES = {
    "iqr",
    "second_association",
    "bpe_filter",
    "support_filter",
    "recover",
    "regroup",
    "refine",
    "seed",
    "reassign",
    "detach_ambiguous",
}
METHOD_LEVEL = {
    "sigma_mode",
    "tau_mode",
    "threshold_unit",
}  # read by associate_traced itself (σ, τ, units)


def _names(config):
    return [stage.name for stage, _ in plan(config)]


def test_each_preset_runs_its_stages_in_order():
    assert _names(Config.paper()) == ["graph", "iqr", "fit", "bpe_filter", "validity_gate"]
    assert _names(Config.reference()) == [
        "graph",
        "iqr",
        "second_association",
        "fit",
        "validity_gate",
    ]
    assert _names(Config.extended()) == [
        "graph",
        "iqr",
        "fit",
        "bpe_filter",
        "recover",
        "regroup",
        "refit",
        "validity_gate",
    ]
    assert _names(Config.best()) == [
        "graph",
        "fit",
        "support",
        "recover",
        "seed",
        "reassign",
        "seed_again",
        "refit",
        "support_again",
        "detach_ambiguous",
        "validity_gate",
    ]
    assert _names(Config.paper(reassign=True)) == [
        "graph",
        "iqr",
        "fit",
        "bpe_filter",
        "reassign",
        "refit",
        "validity_gate",
    ]
    everything = Config.extended(support_filter=True, refine=True, second_association=True)
    assert _names(everything) == [
        "graph",
        "iqr",
        "second_association",
        "fit",
        "bpe_filter",
        "support",
        "recover",
        "regroup",
        "refit",
        "support_again",
        "refine",
        "validity_gate",
    ]
    regroup = dict(plan(Config.extended()))[next(s for s in STAGES if s.name == "regroup")]
    assert [stage.name for stage, _ in regroup.plan] == [
        "graph",
        "iqr",
    ]  # the same stages, listed once


def test_every_structural_option_belongs_to_one_stage():
    owners: dict[str, list[str]] = {}
    for stage in STAGES:
        for name in getattr(stage.options, "_fields", ()):
            if name != "plan":
                owners.setdefault(name, []).append(stage.name)
    numbers = set(Config().thresholds()._fields)
    structural = {f.name for f in dataclasses.fields(Config)} - numbers
    assert set(owners) <= structural, set(owners) - structural
    assert set(SCENE.options._fields) == METHOD_LEVEL
    unowned = structural - set(owners) - SWITCHES - METHOD_LEVEL
    assert not unowned, f"Config fields no stage reads: {unowned}"
    # A stage listed again (refit, seed_again) is the same stage: count the rules, not the names.
    rules = {stage.name: stage.run for stage in STAGES}
    shared = {
        name: stages for name, stages in owners.items() if len({rules[s] for s in stages}) > 1
    }
    assert not shared, f"options read by more than one stage: {shared}"


def test_stage_options_are_read_from_the_config():
    options = {
        stage.name: opts for stage, opts in plan(Config.reference(max_iqr_iters=5, refine=True))
    }
    assert options["iqr"].max_iqr_iters == 5 and options["iqr"].iqr_guards is True
    assert options["graph"].prune_scope == "conflicts" and options["refine"].refine_max_steps == 20
