"""``sigma="auto"``: the 2D noise level from mutual-nearest epipolar distances, with a
fallback when the data hold too little evidence (ALGORITHM.md §0.1).

Samples are the epipolar distances of *mutual* nearest pairs: node ``u`` of view ``m``,
its nearest point ``v`` in view ``n``, and ``u`` is also ``v``'s nearest in view ``m``
(this drops most distances to unrelated points). A true match's distance is half-normal
with scale ``c = √2 σ`` (both points' noise); what is left (clutter, unrelated points,
far-off detections) is modelled by an exponential (the nearest unrelated point) and a wide
uniform (anything). A fixed number of EM iterations fits the three-component mixture from
several low-quantile starts and keeps the most likely fit.

The estimate is not trusted (``fallback``) when the half-normal holds fewer than
:data:`MIN_MATCHES` pairs or when ``σ̂`` exceeds :data:`MAX_SIGMA_PER_FOCAL` of the focal
length; then ``σ = FALLBACK_SIGMA_PX``.
"""

import jax
import jax.numpy as jnp

from .._types import Array, Bool, Float

EM_ITERS = 40
MUTUAL = True
START_QUANTILES = (0.1, 0.25, 0.5)  # the half-normal scale starts from these sample quantiles
MIN_MATCHES = 3.0  # pairs more likely true matches than not, needed for σ̂ to be used
MAX_SIGMA_PER_FOCAL = 0.01  # a plausible σ is at most 1 % of the focal length
UNIFORM_PER_FOCAL = 0.1  # the uniform spans at least 10 % of the focal length
FALLBACK_SIGMA_PX = 1.0
MIN_SCALE_PX = 1e-3  # the half-normal scale's floor (noise-free data: every distance ≈ 0)
EXP_MEAN_PER_SCALE = 5.0  # the exponential's mean stays ≥ this many half-normal scales


def mutual_nearest_samples(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"]
) -> tuple[Float[Array, "M P M"], Float[Array, "M P M"]]:
    """The nearest distance ``x[m, i, n] = min_j d[m, i, n, j]`` (pixels, 0 where unused) and
    its weight: ½ where the nearest is mutual and finite, else 0 (each unordered pair then
    counts once in total)."""
    nearest = jnp.argmin(d, axis=-1)  # (M, P, M): j* of node (m, i) in view n; ties: smallest j
    x = jnp.min(d, axis=-1)
    toward = jnp.transpose(nearest, (2, 0, 1))  # toward[m, n, j] = nearest[n, j, m]
    back = jnp.take_along_axis(toward, jnp.swapaxes(nearest, 1, 2), axis=2)  # (M, M, P)
    P = mask.shape[1]
    mutual = jnp.swapaxes(back, 1, 2) == jnp.arange(P, dtype=back.dtype)[None, :, None]
    ok = (mutual | ~MUTUAL) & jnp.isfinite(x) & mask[:, :, None]
    return jnp.where(ok, x, 0.0), jnp.where(ok, 0.5, 0.0).astype(d.dtype)


def _em(x, w, c0, lam0, width):
    """EM on the half-normal + exponential + uniform mixture of ``x`` (weights ``w``) from
    half-normal scale ``c0``; returns the scale, the number of pairs more likely true
    matches than anything else, and the log-likelihood."""
    total = jnp.maximum(jnp.sum(w), MIN_SCALE_PX)
    log_uniform = -jnp.log(width)

    def log_parts(c, lam, pi):
        log_hn = 0.5 * jnp.log(2.0 / jnp.pi) - jnp.log(c) - 0.5 * (x / c) ** 2
        log_exp = jnp.log(lam) - lam * x
        return jnp.stack([log_hn, log_exp, jnp.broadcast_to(log_uniform, x.shape)]) + jnp.log(pi)[:, None]

    def step(_, state):
        c, lam, pi = state
        parts = log_parts(c, lam, pi)
        resp = jax.nn.softmax(parts, axis=0) * w[None]  # (3, S)
        n_k = jnp.sum(resp, axis=1)
        c = jnp.sqrt(jnp.sum(resp[0] * x * x) / jnp.maximum(n_k[0], MIN_SCALE_PX))
        c = jnp.clip(c, MIN_SCALE_PX, width)
        mean_exp = jnp.sum(resp[1] * x) / jnp.maximum(n_k[1], MIN_SCALE_PX)
        lam = 1.0 / jnp.clip(mean_exp, EXP_MEAN_PER_SCALE * c, width)
        pi = jnp.clip(n_k / total, 1e-4, 1.0)
        return c, lam, pi / jnp.sum(pi)

    pi0 = jnp.asarray([0.5, 0.3, 0.2], x.dtype)
    c, lam, pi = jax.lax.fori_loop(0, EM_ITERS, step, (c0, lam0, pi0))
    parts = log_parts(c, lam, pi)
    log_lik = jnp.sum(w * jax.nn.logsumexp(parts, axis=0))
    n_match = jnp.sum(jnp.where(jnp.argmax(parts, axis=0) == 0, w, 0.0))
    return c, n_match, log_lik


def estimate_sigma(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"], focal_px: Float[Array, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """Noise estimate ``σ`` (pixels) from the epipolar distance table ``d (M, P, M, P)``,
    ``mask (M, P)`` and the rig's focal length ``focal_px`` (sets the plausible range).

    Returns ``(sigma, fallback)``: ``fallback`` is True when the fit is not trusted
    (fewer than ``MIN_MATCHES`` pairs in the half-normal, or ``σ̂ > MAX_SIGMA_PER_FOCAL ·
    focal_px``), and then ``sigma = FALLBACK_SIGMA_PX``. Always finite.
    """
    x, w = mutual_nearest_samples(d, mask)
    x, w = x.reshape(-1), w.reshape(-1)
    n = jnp.sum(w > 0)
    focal_px = jnp.where(jnp.isfinite(focal_px) & (focal_px > 0), focal_px, 1.0)
    sigma_cap = MAX_SIGMA_PER_FOCAL * focal_px
    width = jnp.maximum(jnp.max(x), UNIFORM_PER_FOCAL * focal_px)

    ordered = jnp.sort(jnp.where(w > 0, x, jnp.inf))
    last = jnp.maximum(n - 1, 0)
    # A half-normal's q-quantile is c · Φ⁻¹((1 + q) / 2).
    q = jnp.asarray(START_QUANTILES, x.dtype)
    z = jnp.sqrt(2.0) * jax.scipy.special.erfinv(0.5 * (1.0 + q))
    at_q = ordered[jnp.floor(q * last).astype(jnp.int32)]
    c0 = jnp.clip(jnp.where(jnp.isfinite(at_q), at_q, 0.0) / z, MIN_SCALE_PX, width)
    mean = jnp.sum(w * x) / jnp.maximum(jnp.sum(w), MIN_SCALE_PX)
    lam0 = 1.0 / jnp.clip(mean, EXP_MEAN_PER_SCALE * c0, width)

    c, n_match, log_lik = jax.vmap(_em, in_axes=(None, None, 0, 0, None))(x, w, c0, lam0, width)
    best = jnp.argmax(jnp.where(jnp.isfinite(log_lik), log_lik, -jnp.inf))
    sigma = c[best] / jnp.sqrt(2.0)
    fallback = ~((n_match[best] >= MIN_MATCHES) & (sigma <= sigma_cap) & jnp.isfinite(sigma))
    return jnp.where(fallback, FALLBACK_SIGMA_PX, sigma).astype(d.dtype), fallback


def focal_scale(K: Float[Array, "M 3 3"]) -> Float[Array, ""]:
    """The rig's focal length (pixels): the median over views of ``(|f_x| + |f_y|) / 2``."""
    return jnp.median(0.5 * (jnp.abs(K[..., 0, 0]) + jnp.abs(K[..., 1, 1])))
