"""Histogram of the back-projection error of the groups of one or many associations.

Host-side (NumPy) and headless: a plain :class:`matplotlib.figure.Figure` on the Agg canvas.
"""

from __future__ import annotations

import os

import numpy as np

from .._result import Association
from ..io._atomic import atomic_savefig

_BAR_COLOR = "#3b6fb6"


def plot_bpe_histogram(
    result: Association, *, bins: int = 30, path: str | os.PathLike | None = None
):
    """Histogram of the BPE (px², ``result.bpe``) of every valid group.

    ``result`` may be one scene or a batch (any leading axes): all valid groups are pooled.
    The median is marked, and so is what detection noise alone gives,
    ``σ² (2 − 3 / n)`` px² for a group of ``n`` views (the least-squares residual of ``2n``
    coordinates after fitting 3; ``σ = result.sigma_px``, ``n`` the mean group size):
    groups far to its right are the ones the BPE filter looks at (docs/ALGORITHM.md §8).
    The axis is logarithmic when the values span more than two decades.

    Args:
        result: an :class:`Association`, unbatched or batched.
        bins: number of bins.
        path: if given, the figure is also saved there (format from the suffix).

    Returns:
        A :class:`matplotlib.figure.Figure` with one axes.
    """
    # matplotlib loads with the first figure: importing the package stays quick
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if not isinstance(result, Association):
        raise TypeError(
            f"plot_bpe_histogram: result must be an Association; got {type(result).__name__}"
        )
    if not (isinstance(bins, int) and bins >= 1):
        raise ValueError(f"plot_bpe_histogram: bins must be an integer >= 1; got {bins!r}")
    valid = np.asarray(result.valid, dtype=bool)
    bpe = np.asarray(result.bpe, dtype=np.float64)[valid]
    n_views = np.asarray(result.n_views, dtype=np.float64)[valid]
    sigma = np.asarray(result.sigma_px, dtype=np.float64)
    frames = int(np.prod(valid.shape[:-1]))

    fig = Figure(figsize=(8.0, 4.6), dpi=100, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    positive = bpe[bpe > 0]
    log = positive.size > 1 and positive.max() / positive.min() > 100.0
    if bpe.size:
        if log:
            edges = np.geomspace(positive.min(), positive.max(), bins + 1)
            ax.set_xscale("log")
            values = np.maximum(bpe, positive.min())
        else:
            edges, values = bins, bpe
        ax.hist(values, bins=edges, color=_BAR_COLOR, edgecolor="white", linewidth=0.6)
        median = float(np.median(bpe))
        ax.axvline(
            max(median, positive.min()) if log and positive.size else median,
            color="k",
            lw=1.4,
            label=f"median {median:.3g} px²",
        )
        noise = float(np.mean(sigma) ** 2 * (2.0 - 3.0 / max(float(n_views.mean()), 2.0)))
        if noise > 0:
            ax.axvline(
                noise,
                color="#d40000",
                lw=1.4,
                ls="--",
                label=f"noise alone: σ²(2 − 3/n) = {noise:.3g} px² (σ = {float(np.mean(sigma)):.2f} px, "
                f"n = {n_views.mean():.1f})",
            )
        ax.legend(fontsize=10, frameon=True, framealpha=0.92, edgecolor="0.8", loc="upper left")
    else:
        ax.text(
            0.5,
            0.5,
            "no valid group",
            transform=ax.transAxes,
            ha="center",
            va="center",
            fontsize=12,
        )
    ax.set_xlabel(
        "group back-projection error, BPE (px², mean squared reprojection error over its views)",
        fontsize=10,
    )
    ax.set_ylabel("groups", fontsize=10)
    ax.grid(True, axis="y", color="0.9")
    ax.set_axisbelow(True)
    where = f" over {frames} frames" if frames > 1 else ""
    ax.set_title(f"BPE of {bpe.size} groups{where}", fontsize=13, fontweight="bold", loc="left")
    if path is not None:
        atomic_savefig(fig, path)
    return fig
