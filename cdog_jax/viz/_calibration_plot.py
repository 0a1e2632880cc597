"""The convergence figure of ``cdog-jax calibrate``: camera errors per refinement round."""

from __future__ import annotations

import numpy as np

from ..io._atomic import atomic_savefig


def convergence_figure(rows: list[dict], path: str) -> str:
    """Mean rotation error (degrees) and focal error (%) against the truth, at the start and
    after each round, one line per level; the boundary between the coarse rounds (wand
    frames, shrinking gate) and the fine rounds (dense scenes) is marked."""
    # matplotlib loads with the first figure: importing the package stays quick
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # after the backend is chosen

    fig, axes = plt.subplots(1, 2, figsize=(10.0, 4.0), constrained_layout=True)
    panels = (
        ("rotation_deg", "rotation_rounds", "mean rotation error (°, log)"),
        ("focal_pct", "focal_rounds", "mean |focal error| (%, log)"),
    )
    for ax, (start_key, key, label) in zip(axes, panels):
        for r in rows:
            values = np.concatenate([[r[start_key][0]], r[key]])
            lv = r["level"]
            ax.plot(
                np.arange(values.size),
                np.maximum(values, 1e-3),
                marker="o",
                label=f"{lv.name}: {lv.rotation_deg:g}°, {100 * lv.focal_frac:g} %",
            )
        if rows:
            split = rows[0]["coarse_rounds"] + 0.5
            ax.axvline(split, color="0.5", linestyle="--", linewidth=1)
            ax.text(
                split - 0.1,
                0.02,
                "coarse: wand frames ",
                transform=ax.get_xaxis_transform(),
                ha="right",
                va="bottom",
                fontsize=8,
            )
            ax.text(
                split + 0.1,
                0.02,
                " fine: dense scenes",
                transform=ax.get_xaxis_transform(),
                ha="left",
                va="bottom",
                fontsize=8,
            )
        ax.set_yscale("log")
        ax.set_xlabel("round (association + joint refinement)")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
    axes[0].legend(title="perturbation", fontsize=8, loc="center right")
    axes[1].set_title("focal lengths are freed in the last round only", fontsize=9)
    fig.suptitle(
        "Camera refinement from a drifted built-in rig (errors after a similarity alignment to the truth)"
    )
    atomic_savefig(fig, path, dpi=120)
    plt.close(fig)
    return path
