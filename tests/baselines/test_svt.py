from matrix_baseline_checks import (
    check_hand_scene,
    check_jit_vmap_padding_permutation,
    check_noise_free,
)

from cdog_jax.baselines._svt import MatchSVTOptions, match_svt_groups

OPTIONS = MatchSVTOptions()


def test_hand_made_scene():
    check_hand_scene(match_svt_groups, OPTIONS)


def test_noise_free_scenes_exact_without_false_edges():
    check_noise_free(match_svt_groups, OPTIONS)


def test_jit_vmap_padding_and_slot_permutation():
    check_jit_vmap_padding_permutation(match_svt_groups, OPTIONS)


def test_options_reject_bad_static_values():
    import pytest

    with pytest.raises(ValueError, match="iterations"):
        MatchSVTOptions(iterations=-1)
