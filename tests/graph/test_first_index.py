"""``min_and_first_index`` (graph/_adjacency.py) is ``jnp.min`` and ``jnp.argmin`` at once,
ties and rows of +inf included, on any axis."""

import hypothesis.extra.numpy as hnp
import jax.numpy as jnp
import numpy as np
from hypothesis import given, settings, strategies as st

from cdog_jax.graph._adjacency import min_and_first_index

# Few distinct values, so that ties are common; +inf stands for a padded or gated entry.
VALUES = st.sampled_from([0.0, 1.5, 2.0, -3.0, np.inf])


@settings(max_examples=40, deadline=None)
@given(
    x=hnp.arrays(np.float32, hnp.array_shapes(min_dims=1, max_dims=3, max_side=5), elements=VALUES),
    data=st.data(),
)
def test_min_and_first_index_is_min_and_argmin(x, data):
    axis = data.draw(st.integers(-x.ndim, x.ndim - 1))
    low, index = min_and_first_index(jnp.asarray(x), axis=axis)
    np.testing.assert_array_equal(np.asarray(low), np.min(x, axis=axis))
    np.testing.assert_array_equal(np.asarray(index), np.argmin(x, axis=axis))
    assert index.dtype == jnp.int32
