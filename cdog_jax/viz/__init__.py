"""Every figure: an association over the views, the rig in 3D, epipolar lines, the BPE
histogram, the benchmark's figures (docs/BENCHMARK.md) and the calibration convergence.
matplotlib is imported when a figure is drawn, not with this package."""

from ._benchmark_curves import (
    metrics_vs_sigma as metrics_vs_sigma,
    time_vs_count as time_vs_count,
    views_ablation as views_ablation,
)
from ._bpe_plot import plot_bpe_histogram as plot_bpe_histogram
from ._calibration_plot import convergence_figure as convergence_figure
from ._epipolar_plot import plot_epipolar as plot_epipolar
from ._grid_maps import heatmaps as heatmaps, surfaces as surfaces
from ._plot import plot_association as plot_association
from ._rig_plot import plot_rays as plot_rays, plot_rig as plot_rig
