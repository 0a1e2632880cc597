"""Thresholds in focal-length units (``Config.threshold_unit="focal"``) and the fitted gate
(``Config.tau_mode="fitted"``), docs/ALGORITHM.md §0."""

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import random_scene, ring_rig

from cdog_jax import Config, associate, associate_classes
from cdog_jax._config import tau_px
from cdog_jax.geometry import Rig

RIG = ring_rig(5)


def _scaled(rig, xy, s):
    """The same scene seen by cameras with ``s`` times the resolution (K's first two rows
    and every pixel scaled by ``s``)."""
    K = np.asarray(rig.K, np.float64).copy()
    K[:, :2] *= s
    return Rig(jnp.asarray(K, rig.K.dtype), rig.R, rig.t), xy * s


def _labels(rig, xy, mask, config, sigma):
    res = associate(rig, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), config=config, sigma=sigma)
    return np.asarray(res.labels), float(res.tau_px)


@pytest.mark.parametrize("sigma", [0.5, "auto"])
def test_focal_units_give_the_same_groups_at_any_resolution(sigma):
    # σ = 0.5 px (given as 0.5 px of a 1000 px camera: 0.4 px here, f ≈ 800) is below the
    # τ floor tau_min_px = 1, so the floor decides τ; in pixels it would stay 1 px at 4×
    # the resolution while the distances grow 4×.
    xy, mask, _, _ = random_scene(RIG, 12, 16, sigma=0.4, seed=3, clutter=2)
    config = Config.paper(threshold_unit="focal")
    labels, tau = _labels(RIG, xy, mask, config, sigma)
    for s in (0.5, 4.0):
        rig_s, xy_s = _scaled(RIG, xy, s)
        labels_s, tau_s = _labels(rig_s, xy_s, mask, config, sigma)
        np.testing.assert_array_equal(labels_s, labels)
        assert tau_s == pytest.approx(s * tau, rel=1e-4)


def test_focal_units_with_classes_and_pooled_sigma():
    xy, mask, inst, _ = random_scene(RIG, 4, 4, sigma=0.5, seed=4)
    classes = np.where(inst >= 0, inst % 2, 0)
    config = Config.paper(threshold_unit="focal")
    runs = []
    for s in (1.0, 3.0):
        rig_s, xy_s = _scaled(RIG, xy, s)
        out = associate_classes(rig_s, xy_s[None], mask[None], classes[None], config=config, sigma="auto")
        runs.append((np.asarray(out.association.labels), np.asarray(out.association.tau_px)))
    np.testing.assert_array_equal(runs[1][0], runs[0][0])
    np.testing.assert_allclose(runs[1][1], 3.0 * runs[0][1], rtol=1e-4)


def test_fitted_gate_needs_per_scene_sigma_with_classes():
    xy, mask, _, _ = random_scene(RIG, 4, 6, seed=5)
    with pytest.raises(ValueError, match="tau_mode='fitted'.*sigma_pool='scene'"):
        associate_classes(RIG, xy[None], mask[None], np.zeros((1,) + mask.shape, int), config=Config.paper(tau_mode="fitted"))


def test_fitted_gate_is_a_high_quantile_of_the_true_pairs():
    # Gaussian noise: the fitted gate is close to the formula's α √2 σ̂ (both cover ≈ 95 %);
    # with σ given there is nothing fitted and the formula holds (test_gate_formula_without_a_fit).
    # (The shapes and first config of the test above: one compiled program fewer.)
    xy, mask, _, _ = random_scene(RIG, 14, 16, sigma=1.0, seed=6)
    config = Config.paper(threshold_unit="focal")
    gauss = associate(RIG, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), config=config, sigma="auto")
    fitted = associate(RIG, jnp.asarray(xy, jnp.float32), jnp.asarray(mask), config=config.replace(tau_mode="fitted"), sigma="auto")
    assert float(fitted.sigma_px) == float(gauss.sigma_px)
    assert 0.7 < float(fitted.tau_px) / float(gauss.tau_px) < 1.4


def test_gate_formula_without_a_fit():
    th = Config.paper().thresholds(1.0)
    assert float(tau_px(th, jnp.float32(1.0), jnp.float32(np.nan))) == pytest.approx(2.0 * np.sqrt(2.0))
    assert float(tau_px(th, jnp.float32(1.0), jnp.float32(5.0))) == pytest.approx(5.0)
    assert float(tau_px(th, jnp.float32(1.0), jnp.float32(0.5))) == pytest.approx(1.0)  # the floor tau_min_px


def test_config_rejects_unknown_units_and_modes():
    with pytest.raises(Exception, match="threshold_unit"):  # beartype or the ValueError
        Config(threshold_unit="mm")
    with pytest.raises(Exception, match="tau_mode"):
        Config(tau_mode="quantile")
