"""A new stage is one declaration and one entry in the stage list: its options become fields
of the config (defaults and checks), its numbers are traced and range-checked, and no other
file changes. The stage here is declared in this module only."""

from __future__ import annotations

import dataclasses
from typing import Literal, NamedTuple

import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import STAGES, Config, associate
from cdog_jax.cdog._config import Range, Switch, Threshold
from cdog_jax.cdog._pipeline import config_field_problems, make_config
from cdog_jax.cdog._stage import Stage

TRACES = []


class ErrorGateOptions(NamedTuple):
    """Which error a group is judged by."""

    error_kind: Literal["mean", "twice_mean"] = "mean"


def error_gate_stage(scene, state, options):
    """Drop the fitted groups whose mean reprojection error exceeds ``thresholds.error_gate_px``."""
    TRACES.append(options)  # once per trace: a number that changes must not add one
    error = state.fit.err_px * (2.0 if options.error_kind == "twice_mean" else 1.0)
    keep = state.table.valid & (error <= scene.thresholds.error_gate_px)
    return state._replace(
        table=state.table.keep(keep),
        fit=state.fit._replace(member=state.fit.member & keep[:, None]),
    )


ERROR_GATE = Stage(
    "error_gate",
    error_gate_stage,
    ErrorGateOptions,
    Switch("error_gate", False, "drop groups with a large error"),
    thresholds=(
        Threshold("error_gate_px", 5.0, Range(0.0, 100.0), "the largest mean error kept (pixels)"),
    ),
)
GATED_STAGES = (*STAGES[:-1], ERROR_GATE, STAGES[-1])  # after the fit, before the validity gate
Gated = make_config(GATED_STAGES, base=Config)


def test_the_new_options_are_config_fields_with_their_defaults():
    gated = Gated()
    assert (gated.error_gate, gated.error_kind, gated.error_gate_px) == (False, "mean", 5.0)
    assert isinstance(gated, Config) and gated.delta == Config().delta
    assert not hasattr(Config(), "error_gate_px")  # C-DOG itself is untouched
    assert Gated(error_gate_px=1.0).structure() == Gated()  # a number is not part of the jit key
    assert Gated(error_kind="twice_mean").structure() != Gated()
    thresholds = Gated(error_gate_px=7.0).thresholds(1.0)
    assert thresholds.error_gate_px == np.float32(7.0) and thresholds.delta == np.float32(0.5)
    assert "error_gate_px = 5.0 (traced)" in Gated.__doc__


def test_config_is_written_as_its_stages_declare():
    """Config's fields are written in its class body; a stage whose options have no field,
    a field no stage declares, or a field whose type or default is not the declared one is
    named (and stops the import for Config itself)."""
    assert config_field_problems(Config, STAGES) == []
    assert config_field_problems(Config, GATED_STAGES) == [
        "error_gate: declared by stage 'error_gate'; no field of Config",
        "error_kind: declared by stage 'error_gate'; no field of Config",
        "error_gate_px: declared by stage 'error_gate'; no field of Config",
    ]

    @dataclasses.dataclass(frozen=True)
    class Drifted(Config):
        delta: float = 0.4
        max_split_iters: float = 64.0
        extra: int = 0

    assert config_field_problems(Drifted, STAGES) == [
        "max_split_iters: type float; stage 'graph' declares <class 'int'>",
        "max_split_iters: default 64.0; stage 'graph' declares 64",
        "delta: default 0.4; stage 'graph' declares 0.5",
        "extra: a field no stage declares",
    ]
    assert config_field_problems(Gated, GATED_STAGES) == []


def test_the_new_options_are_checked():
    with pytest.raises(
        ValueError, match=r"Config.error_gate_px must be finite and in \[0, 100\]; got 200.0"
    ):
        Gated(error_gate_px=200.0)
    with pytest.raises(
        ValueError, match=r"Config.error_kind must be one of \('mean', 'twice_mean'\); got 'max'"
    ):
        Gated().replace(error_kind="max")
    with pytest.raises(TypeError, match="Config.error_gate must be True or False; got 1"):
        Gated(error_gate=1)
    twice = Stage(
        "twice",
        error_gate_stage,
        None,
        Switch("twice", False),
        thresholds=(Threshold("delta", 0.5),),
    )
    with pytest.raises(
        TypeError, match="option 'delta' is declared twice: by stage 'graph' and by stage 'twice'"
    ):
        make_config((*STAGES, twice))


def test_the_new_number_is_traced_and_its_thresholds_range_checked():
    rig = ring_rig(3)
    xy, mask, _, _ = random_scene(rig, 4, 6, sigma=0.5)
    method = Gated(error_gate=True)
    thresholds = method.thresholds(0.5)
    TRACES.clear()
    kept = associate(rig, xy.astype(np.float32), mask, method=method, thresholds=thresholds)
    dropped = associate(
        rig,
        xy.astype(np.float32),
        mask,
        method=method,
        thresholds=thresholds._replace(error_gate_px=np.float32(0.0)),
    )
    assert len(TRACES) == 1, "changing a number recompiled"
    assert int(np.sum(kept.valid)) > 0 and int(np.sum(dropped.valid)) == 0
    with pytest.raises(
        ValueError, match=r"thresholds.error_gate_px must be finite and in \[0, 100\]; got -1.0"
    ):
        associate(
            rig,
            xy,
            mask,
            method=method,
            thresholds=thresholds._replace(error_gate_px=np.float32(-1.0)),
        )
