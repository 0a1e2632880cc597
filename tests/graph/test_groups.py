"""Compacting a group table: valid rows first, each side in its order."""

import jax
import numpy as np
from hypothesis import given, settings, strategies as st

from cdog_jax.graph._groups import compact_groups

_compact = jax.jit(compact_groups)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.booleans(), min_size=1, max_size=12))
def test_compaction_is_the_stable_sort_of_the_rows_on_validity(flags):
    # The oracle: NumPy's stable argsort of "not valid" (valid rows first, ties in row order).
    valid = np.asarray(flags)
    G = len(valid)
    groups = np.arange(G * 3, dtype=np.int32).reshape(G, 3)  # every row tells where it came from
    # One program for every length drawn: the rows padded to 12 with invalid ones, which
    # sort last on both sides.
    pad = 12 - G
    valid_p = np.concatenate([valid, np.zeros(pad, bool)])
    groups_p = np.concatenate([groups, np.full((pad, 3), -1, np.int32)])
    got_groups, got_valid, got_order = (np.asarray(a) for a in _compact(groups_p, valid_p))
    order = np.argsort(~valid_p, kind="stable")
    np.testing.assert_array_equal(got_order, order)
    np.testing.assert_array_equal(got_groups, groups_p[order])
    np.testing.assert_array_equal(got_valid, valid_p[order])
