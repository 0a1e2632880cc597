"""``sigma_mode="robust"``: the 2D noise level from the nearest epipolar distances, robust to
heavy-tailed detection noise (ALGORITHM.md §0.1).

The censored mixture of ``sigma_mode="auto"`` (``graph/_sigma.py``: a sample is a ``match``,
a true match ``hidden`` behind a nearer unrelated point, ``none`` or uniform), with three
changes: the true-pair distance ``T`` is half-normal or a half Student-t of ``ν`` degrees of
freedom (a Gaussian whose variance varies from detection to detection: latent precision
``u ~ Gamma(ν/2, ν/2)``), fitted for every ``ν`` of :data:`NU_GRID` from the same starts (the
most likely fit wins); a hidden true match lies at or beyond the second-nearest point (not
only beyond the nearest); the unrelated points' spread starts from the second-nearest
distances. ``σ`` is the scale of the Gaussian with the same median as the distances the
winning fit calls true pairs (median absolute deviation): the noise of the bulk, not
inflated by the tail. The fit also gives any quantile of the true-pair distance (the
``tau_mode="fitted"`` gate).

Fallback as for ``"auto"`` (``trusted_sigma``): fewer than :data:`MIN_MATCHES` expected true
pairs give ``σ = FALLBACK_SIGMA_PX``, a ``σ̂`` above :data:`MAX_SIGMA_PER_FOCAL` of the focal
length gives that bound; either way the fitted gate is not used.
"""

import math

import jax
import jax.numpy as jnp
from jax.scipy.special import log_ndtr

from .._types import Array, Bool, Float
from ._sigma import (
    MIN_SCALE_PX,
    START_QUANTILES,
    em_start,
    half_normal_beyond_moment,
    mixture_log_parts,
    most_likely,
    nearest_samples,
    run_em,
    table_sum,
    trusted_sigma,
)

# Degrees of freedom of the match distance's fits (inf: half-normal); the most likely wins.
NU_GRID = (float("inf"), 8.0, 4.0, 2.0)
MEDIAN_Z = 0.6744897501960817  # Φ⁻¹(3/4): the median of |N(0, 1)|
QUANTILE_ITERS = 64  # bisection steps of the true-pair distance's quantiles (to 2⁻⁶⁴ of the range)
# Terms of the tail series of the half-t's survival (ALGORITHM.md §0.1): y ≤ ½, so the
# truncation error is below 2⁻⁴⁰ relative.
TAIL_TERMS = 40
GAUSS_COVERAGE = 0.9544997361036416  # P(|Z| < 2): what α_τ = 2 covers of Gaussian true pairs


def nearest_two_samples(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"]
) -> tuple[
    Float[Array, "M P M"], Float[Array, "M P M"], Float[Array, "M P M"], Float[Array, "M P M"]
]:
    """:func:`~cdog_jax.graph._sigma.nearest_samples` ``(x, w, count)`` (pixels, weights,
    counts) and the second-nearest distance ``x2 >= x`` (pixels; ``x`` where view ``n`` has
    one point or the second is not finite)."""
    x, w, count = nearest_samples(d, mask)
    # The second smallest: the smallest once one copy of the minimum is removed.
    first = jnp.argmin(d, axis=-1)
    rest = jnp.where(jnp.arange(d.shape[-1])[None, None, None, :] == first[..., None], jnp.inf, d)
    x2 = jnp.min(rest, axis=-1)
    return x, w, count, jnp.where((w > 0) & jnp.isfinite(x2), x2, x)


def _poly(coef, y):
    """``Σ_j coef[j] y^j`` (Horner)."""
    out = jnp.zeros_like(y) + coef[-1]
    for value in coef[-2::-1]:
        out = out * y + value
    return out


def _log_t_tail(a, nu):
    """``(log P(T > x), E[u T² | T > x] / c²)`` for ``T = |t_ν|`` of scale ``c``, ``a = x / c``,
    ``ν`` an even integer.

    With ``y = ν / (ν + a²)`` and ``k = ν / 2``: ``P(T > x) = I_y(k, ½)`` (regularised
    incomplete beta), and ``E[u T² | T > x] / c² = (ν + 1) − ν I_y(k + 1, ½) / I_y(k, ½)``
    (the latent precision's weight ``(ν + 1) / (ν + a²)`` turns ``t_ν`` into ``t_{ν+2}`` of the
    same ``y``): from 1 (``a = 0``) to ``ν + 1`` (``a → ∞``). For integer ``k``,
    ``I_y(k, ½) = 1 − √(1−y) Σ_{j<k} b_j y^j = √(1−y) Σ_{j≥k} b_j y^j``, ``b_j = C(2j, j) / 4^j``
    (the binomial series of ``(1−y)^{-½}``): the finite sum where ``y > ½``, the series (in
    logs: no underflow far in the tail) where ``y ≤ ½``.
    """
    k = int(nu) // 2
    coef = [math.comb(2 * j, j) / 4.0**j for j in range(k + 1 + TAIL_TERMS)]
    y = nu / (nu + a * a)
    root = a / jnp.sqrt(nu + a * a)  # √(1 − y), without cancellation
    # y > ½: the finite sums.
    head = _poly(coef[:k], y)
    body = 1.0 - root * head
    body_up = body - root * coef[k] * y**k
    log_body = jnp.log(jnp.maximum(body, jnp.finfo(a.dtype).tiny))
    ratio_body = body_up / jnp.where(body > 0, body, 1.0)
    # y ≤ ½: the series from j = k, scaled by y^k.
    ys = jnp.minimum(y, 0.5)
    tail = _poly(coef[k:], ys)
    tail_up = _poly(coef[k + 1 :], ys)
    log_tail = jnp.log(jnp.maximum(root, jnp.finfo(a.dtype).tiny)) + k * jnp.log(ys) + jnp.log(tail)
    ratio_tail = ys * tail_up / tail
    near = y > 0.5
    moment = (nu + 1.0) - nu * jnp.where(near, ratio_body, ratio_tail)
    return jnp.where(near, log_body, log_tail), jnp.clip(moment, 1.0, nu + 1.0)


def _log_match(a, c, nu):
    """``(log density of T at x, log P(T > x))`` for the half-normal (``ν = inf``) or half-t."""
    if math.isinf(nu):
        return 0.5 * jnp.log(2.0 / jnp.pi) - jnp.log(c) - 0.5 * a * a, jnp.log(2.0) + log_ndtr(-a)
    log_norm = (
        math.log(2.0)
        + math.lgamma(0.5 * (nu + 1.0))
        - math.lgamma(0.5 * nu)
        - 0.5 * math.log(nu * math.pi)
    )
    return log_norm - jnp.log(c) - 0.5 * (nu + 1.0) * jnp.log1p(a * a / nu), _log_t_tail(a, nu)[0]


def _log_parts(x, x2, count, c, inv_kappa, pi, width, nu):
    """Log joint density ``(4, S)`` of every sample under match / hidden / none / uniform.
    A hidden true match is another detection of the view: at or beyond ``x2``."""
    log_t = _log_match(x / c, c, nu)[0]  # density of T at x
    log_t_beyond = _log_match(x2 / c, c, nu)[1]  # log P(T > x2)
    return mixture_log_parts(x, count, log_t, log_t_beyond, inv_kappa, pi, width)


def _second_moments(x, c, nu):
    """Per sample, the M-step's ``(E[u T²] of a match at x, E[u T² | T > x])`` (``u = 1`` for
    the half-normal): the scale update is ``c² = Σ`` of these, weighted, over the true pairs."""
    if math.isinf(nu):
        return x * x, half_normal_beyond_moment(x, c)
    a = x / c
    weight = (nu + 1.0) / (nu + a * a)  # E[u | x], the latent precision
    return weight * x * x, c * c * _log_t_tail(a, nu)[1]


def _em(x, x2, w, count, c0, inv_kappa0, width, spread_min, nu, sum_width):
    """EM from half-normal scale ``c0`` with the match distance's ``nu``; returns the scale,
    the unrelated points' spread ``1/κ``, the shares ``π`` and the log-likelihood."""

    def log_parts(c, inv_kappa, pi):
        return _log_parts(x, x2, count, c, inv_kappa, pi, width, nu)

    def true_moments(c, match, hidden):
        return match * _second_moments(x, c, nu)[0] + hidden * _second_moments(x2, c, nu)[1]

    c, inv_kappa, pi = run_em(
        log_parts, true_moments, x, w, count, c0, inv_kappa0, width, spread_min, sum_width=sum_width
    )
    log_lik = table_sum(w * jax.nn.logsumexp(log_parts(c, inv_kappa, pi), axis=0), sum_width)
    return c, inv_kappa, pi, log_lik


def _true_quantiles(q, x, x2, w, count, c, inv_kappa, pi, width, nu, sum_width):
    """The ``q``-quantiles (pixels, any shape) of the true-pair distance ``T``, estimated from
    the samples under one fit, and the expected number of true pairs.

    ``F(t) = Σ w (r_match 1{x ≤ t} + r_hidden P(T ≤ t | T > x2)) / Σ w (r_match + r_hidden)``
    (a hidden sample's ``T`` is only known to exceed ``x2``; its law beyond is the fit's): the distribution of the samples the fit calls true, not the fitted shape, so a
    tail the fit's shape misses moves the quantiles little. Solved by bisection on
    ``[0, width]``.
    """
    resp = jax.nn.softmax(_log_parts(x, x2, count, c, inv_kappa, pi, width, nu), axis=0) * w[None]
    match, hidden = resp[0], resp[1]
    n_true = table_sum(match + hidden, sum_width)
    log_beyond_x = _log_match(x2 / c, c, nu)[1]

    def cdf(t):
        log_beyond_t = _log_match(t / c, c, nu)[1]
        passed = -jnp.expm1(jnp.minimum(log_beyond_t - log_beyond_x, 0.0))  # P(T ≤ t | T > x2)
        return table_sum(jnp.where(x <= t, match, 0.0) + hidden * passed, sum_width) / jnp.maximum(
            n_true, MIN_SCALE_PX
        )

    def step(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = jax.vmap(cdf)(mid.reshape(-1)).reshape(mid.shape) < q
        return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

    lo, hi = jax.lax.fori_loop(
        0, QUANTILE_ITERS, step, (jnp.zeros_like(q), jnp.full_like(q, width))
    )
    return 0.5 * (lo + hi), n_true


def estimate_sigma_robust(
    d: Float[Array, "M P M P"], mask: Bool[Array, "M P"], focal_px: Float[Array, ""]
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """Noise estimate ``σ`` (pixels) from the epipolar distance table ``d (M, P, M, P)``,
    ``mask (M, P)`` and the rig's focal length ``focal_px`` (sets the plausible range), robust
    to heavy tails. Returns ``(sigma, fallback)`` as
    :func:`cdog_jax.graph.estimate_sigma` does. Always finite."""
    sigma, _, fallback = fit_noise(*nearest_two_samples(d, mask), focal_px, GAUSS_COVERAGE)
    return sigma, fallback


def estimate_noise(
    d: Float[Array, "M P M P"],
    mask: Bool[Array, "M P"],
    focal_px: Float[Array, ""],
    coverage: float | Float[Array, ""],
) -> tuple[Float[Array, ""], Float[Array, ""], Bool[Array, ""]]:
    """:func:`estimate_sigma_robust` and the ``coverage``-quantile of the true-pair distance:
    ``(sigma, gate_px, fallback)`` (:func:`fit_noise`)."""
    return fit_noise(*nearest_two_samples(d, mask), focal_px, coverage)


def robust_sigma_from_samples(
    x: Float[Array, "*S"],
    w: Float[Array, "*S"],
    count: Float[Array, "*S"],
    x2: Float[Array, "*S"],
    focal_px: Float[Array, ""],
    *,
    sum_width: int | None = None,
) -> tuple[Float[Array, ""], Bool[Array, ""]]:
    """:func:`estimate_sigma_robust` from the samples of :func:`nearest_two_samples` (any
    shape, e.g. those of several scenes pooled; weight 0 marks an unused entry);
    ``sum_width`` as :func:`~cdog_jax.graph._sigma.sigma_from_samples`'."""
    sigma, _, fallback = fit_noise(x, w, count, x2, focal_px, GAUSS_COVERAGE, sum_width=sum_width)
    return sigma, fallback


def fit_noise(
    x: Float[Array, "*S"],
    w: Float[Array, "*S"],
    count: Float[Array, "*S"],
    x2: Float[Array, "*S"],
    focal_px: Float[Array, ""],
    coverage: float | Float[Array, ""],
    *,
    sum_width: int | None = None,
) -> tuple[Float[Array, ""], Float[Array, ""], Bool[Array, ""]]:
    """``(sigma, gate_px, fallback)`` from the samples of :func:`nearest_two_samples`:
    :func:`estimate_sigma_robust`'s σ and fallback, and ``gate_px``, the ``coverage``-quantile
    (in ``(0, 1)``) of the true-pair distance (pixels; NaN on a fallback). ``sum_width``: the
    width the samples' sums are padded to (:func:`~cdog_jax.graph._sigma.table_sum`)."""
    x, w, count, x2 = (a.reshape(-1) for a in (x, w, count, x2))
    dtype = x.dtype
    focal_px, width, c0, scaled_mean, spread_min = em_start(x, w, count, focal_px, sum_width)
    # The spread starts from the second-nearest distances (mostly unrelated points: the
    # nearest of count − 1 of them has mean 1/κ / (count − 1)); without any, the nearest.
    w_other = jnp.where(count > 1.0, w, 0.0)
    second_mean = table_sum(w_other * (count - 1.0) * x2, sum_width) / jnp.maximum(
        table_sum(w_other, sum_width), MIN_SCALE_PX
    )
    spread0 = jnp.where(table_sum(w_other, sum_width) > 0, second_mean, scaled_mean)
    inv_kappa0 = jnp.clip(spread0, spread_min, width * jnp.maximum(jnp.max(count), 1.0))

    # Every ν from every start; the most likely fit wins. (ν, start) pairs in NU_GRID order.
    fits = [
        jax.vmap(_em, in_axes=(None, None, None, None, 0, None, None, None, None, None))(
            x, x2, w, count, c0, inv_kappa0, width, spread_min, nu, sum_width
        )
        for nu in NU_GRID
    ]
    c, inv_kappa, pi, log_lik = (jnp.concatenate(parts) for parts in zip(*fits))
    best = most_likely(log_lik)  # near-ties: the first (the half-normal before heavier tails)
    levels = jnp.stack([jnp.asarray(0.5, dtype), jnp.asarray(coverage, dtype)])
    branches = [
        lambda c, k, p, nu=nu: _true_quantiles(
            levels, x, x2, w, count, c, k, p, width, nu, sum_width
        )
        for nu in NU_GRID
    ]
    (median, gate), n_match = jax.lax.switch(
        best // len(START_QUANTILES), branches, c[best], inv_kappa[best], pi[best]
    )
    # The Gaussian σ of the same median: a true pair's distance is |N(0, 2σ²)|.
    sigma, fallback = trusted_sigma(median / (jnp.sqrt(2.0) * MEDIAN_Z), n_match, focal_px)
    gate = jnp.where(fallback, jnp.nan, gate)
    return sigma.astype(dtype), gate.astype(dtype), fallback
