from matrix_baseline_checks import (
    check_hand_scene,
    check_jit_vmap_padding_permutation,
    check_noise_free,
)

from cdog_jax.baselines._spectral_sync import SpectralSyncOptions, spectral_sync_groups

OPTIONS = SpectralSyncOptions()


def test_hand_made_scene():
    check_hand_scene(spectral_sync_groups, OPTIONS)


def test_noise_free_scenes_exact_without_false_edges():
    check_noise_free(spectral_sync_groups, OPTIONS)


def test_jit_vmap_padding_and_slot_permutation():
    check_jit_vmap_padding_permutation(spectral_sync_groups, OPTIONS)


def test_options_reject_bad_static_values():
    import pytest

    with pytest.raises(ValueError, match="max_objects"):
        SpectralSyncOptions(max_objects=0)
