"""The visibility-support filter (Config.support_filter, off in every preset) against the
NumPy oracle (tests/oracle.py §8d), float64, on the oracle tests' 4-view variant scenes
(20 % missed detections, 0–2 clutter points per view)."""

import pytest
from test_pipeline_vs_oracle import VARIANT_SCENES, _check_float64

from cdog_jax import Config

SUPPORT = {
    # After the BPE filter only; and after recovery + regroup as well. Stricter than
    # the defaults (larger alpha), so that groups are dropped (in 10 and 4 of 12 scenes).
    "paper_support": Config.paper(support_filter=True, support_alpha=0.2),
    "extended_support_strict": Config.extended(
        support_filter=True,
        support_alpha=0.1,
        support_min_rate=0.05,
        support_ref_views=3.0,
        support_frac=2.0,
    ),
}


@pytest.mark.parametrize("variant", sorted(SUPPORT))
def test_float64_support_filter_matches_oracle(variant):
    _check_float64(VARIANT_SCENES, SUPPORT[variant])
