"""Thresholds in focal-length units (``threshold_unit="focal"``) and the fitted gate
(``tau_mode="fitted"``, with ``sigma_mode="robust"``), docs/ALGORITHM.md §0."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig
from oracle import (
    epipolar_distance_table,
    estimate_sigma_robust as oracle_robust,
    focal_scale as oracle_focal,
)

from cdog_jax import Config, associate, associate_classes
from cdog_jax.cdog._config import tau_px, thresholds_in_pixels
from cdog_jax.geometry import Rig

RIG = ring_rig(4)
P = 8  # padded to 32 by associate, as elsewhere in the tests


def _scaled(rig, xy, s):
    """The same scene seen by cameras with ``s`` times the resolution (K's first two rows
    and every pixel scaled by ``s``)."""
    K = np.asarray(rig.K, np.float64).copy()
    K[:, :2] *= s
    return Rig(jnp.asarray(K, rig.K.dtype), rig.R, rig.t), xy * s


def _run(rig, xy, mask, config, sigma):
    res = associate(
        rig, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), method=config, sigma=sigma
    )
    return np.asarray(res.labels), float(res.tau_px), float(res.sigma_px)


def test_focal_units_scale_every_length_threshold():
    # Given σ = 0.5 means 0.5 px of a 1000 px camera: 0.5 · f / 1000 px here; px² squared.
    thresholds = Config.paper(delta=0.6).thresholds(0.5)
    f = 830.0
    scaled = thresholds_in_pixels(thresholds, jnp.float32(f), Config.units)
    for name in thresholds._fields:
        power = {"px": 1, "px2": 2}.get(Config.units[name], 0)
        assert float(getattr(scaled, name)) == pytest.approx(
            float(getattr(thresholds, name)) * (f / 1000.0) ** power, rel=1e-6
        ), name
    assert float(scaled.delta) == pytest.approx(0.6) and float(scaled.sigma_px) == pytest.approx(
        0.415
    )


def test_focal_units_give_the_same_groups_at_any_resolution():
    # σ̂, τ and every length threshold follow the resolution, so the groups do not change.
    # (A given σ in focal units: test_focal_units_with_classes_and_pooled_sigma.)
    xy, mask, _, _ = random_scene(RIG, 6, P, sigma=0.4, seed=3, clutter=1)
    config = Config.paper(threshold_unit="focal")
    labels, tau, sig = _run(RIG, xy, mask, config, "auto")
    assert (labels >= 0).any()
    for s in (0.5, 4.0):
        rig_s, xy_s = _scaled(RIG, xy, s)
        labels_s, tau_s, sig_s = _run(rig_s, xy_s, mask, config, "auto")
        np.testing.assert_array_equal(labels_s, labels)
        assert tau_s == pytest.approx(s * tau, rel=1e-4)
        assert sig_s == pytest.approx(s * sig, rel=1e-3)


def test_focal_units_with_classes_and_pooled_sigma():
    # σ̂ pooled over the classes of a frame (here by the robust estimator) is passed to the
    # pipeline as a given σ, in focal units.
    xy, mask, inst, _ = random_scene(RIG, 4, 4, sigma=0.5, seed=4)
    classes = np.where(inst >= 0, inst % 2, 0)
    config = Config.paper(threshold_unit="focal", sigma_mode="robust")
    runs = []
    for s in (1.0, 3.0):
        rig_s, xy_s = _scaled(RIG, xy, s)
        out = associate_classes(
            rig_s, xy_s[None], mask[None], classes[None], method=config, sigma="auto", batch_size=4
        )
        runs.append((np.asarray(out.association.labels), np.asarray(out.association.tau_px)))
    assert (runs[0][0] >= 0).any()
    np.testing.assert_array_equal(runs[1][0], runs[0][0])
    np.testing.assert_allclose(
        runs[1][1], 3.0 * runs[0][1], rtol=1e-3
    )  # float32 EM: not to the last bit


def test_fitted_gate_needs_the_robust_fit_and_per_scene_sigma_with_classes():
    xy, mask, _, _ = random_scene(RIG, 4, 6, seed=5)
    config = Config.paper(sigma_mode="robust", tau_mode="fitted")
    with pytest.raises(ValueError, match="tau_mode='fitted'.*sigma_pool='scene'"):
        associate_classes(
            RIG, xy[None], mask[None], np.zeros((1,) + mask.shape, int), method=config
        )
    with pytest.raises(ValueError, match="tau_mode='fitted'.*sigma_mode='robust'"):
        Config.paper(sigma_mode="auto", tau_mode="fitted")
    with pytest.raises(ValueError, match="tau_mode='fitted'.*sigma_mode='robust'"):
        associate(
            RIG, xy, mask, method=Config.paper(tau_mode="fitted"), sigma="auto"
        )  # given -> auto


def test_fitted_gate_is_a_high_quantile_of_the_true_pairs():
    # Gaussian noise: the pipeline's σ and τ are the oracle's robust σ̂ and fitted gate (the
    # 95.4 % quantile of the true-pair distance for alpha_tau = 2), close to, but not, the
    # formula's α √2 σ̂ (both cover ≈ 95 %).
    xy, mask, _, _ = random_scene(RIG, 7, P, sigma=1.0, seed=6)
    config = Config.paper(sigma_mode="robust", tau_mode="fitted")
    res = associate(
        RIG, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), method=config, sigma="auto"
    )
    sigma, tau = float(res.sigma_px), float(res.tau_px)
    K, R, t = (np.asarray(a, np.float64) for a in (RIG.K, RIG.R, RIG.t))
    xy32 = np.asarray(xy, np.float32).astype(np.float64)
    want_sigma, want_gate, fallback = oracle_robust(
        epipolar_distance_table(K, R, t, xy32, mask), mask, oracle_focal(K), with_gate=True
    )
    assert not int(res.status) and not fallback and 0.7 < sigma < 1.4
    assert sigma == pytest.approx(want_sigma, rel=1e-3) and tau == pytest.approx(
        want_gate, rel=1e-3
    )
    formula = 2.0 * np.sqrt(2.0) * sigma
    assert 0.7 < tau / formula < 1.4 and abs(tau - formula) > 1e-3 * formula


def test_gate_formula_without_a_fit():
    thresholds = Config.paper().thresholds(1.0)
    assert float(tau_px(thresholds, jnp.float32(1.0))) == pytest.approx(2.0 * np.sqrt(2.0))
    assert float(tau_px(thresholds, jnp.float32(1.0), jnp.float32(np.nan))) == pytest.approx(
        2.0 * np.sqrt(2.0)
    )
    assert float(tau_px(thresholds, jnp.float32(1.0), jnp.float32(5.0))) == pytest.approx(5.0)
    assert float(tau_px(thresholds, jnp.float32(1.0), jnp.float32(0.5))) == pytest.approx(
        1.0
    )  # the floor tau_min_px


def test_focal_units_scale_the_lengths_declared_in_pixels():
    # Exactly the numbers whose stage declares them in px (px² for jump_floor_px2).
    assert {n for n, u in Config.units.items() if u} == {
        "sigma_px",
        "tau_min_px",
        "iqr_floor_px",
        "iqr_min_px",
        "iqr_force_px",
        "jump_floor_px2",
    }
    assert Config.units["jump_floor_px2"] == "px2"


def test_config_rejects_unknown_units_and_modes():
    with pytest.raises(ValueError, match="threshold_unit"):
        Config(threshold_unit="mm")
    with pytest.raises(ValueError, match="tau_mode"):
        Config(tau_mode="quantile")
    with pytest.raises(ValueError, match="sigma_mode"):
        Config(sigma_mode="median")
