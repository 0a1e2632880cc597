"""Lengths of short vectors written out coordinate by coordinate: the NumPy lengths, with
broadcasting, within float32 round-off."""

import jax.numpy as jnp
import numpy as np

from cdog_jax.geometry._vectors import distance, squared_length


def test_squared_length_and_distance_match_numpy():
    rng = np.random.default_rng(3)
    for d in (2, 3):
        v = rng.normal(size=(7, 5, d)).astype(np.float32) * 100.0
        np.testing.assert_allclose(
            np.asarray(squared_length(jnp.asarray(v))), np.sum(v * v, axis=-1), rtol=1e-6
        )
        a, b = v[:, None, 0], v[None, :, 1]  # (7, 1, d) against (1, 7, d)
        want = np.linalg.norm(a - b, axis=-1)
        got = np.asarray(distance(jnp.asarray(a), jnp.asarray(b)))
        assert got.shape == (7, 7)
        np.testing.assert_allclose(got, want, rtol=1e-6)
    # A point against itself is at distance 0 exactly.
    assert float(distance(jnp.ones(3), jnp.ones(3))) == 0.0
