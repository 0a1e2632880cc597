"""Group-level stages: IQR outliers (Alg. 3), BPE jump filter (§IV-E), second association
(reference), the validity gate every valid group passes, least-squares refinement
(optimistix), and the BPE as a differentiable loss."""

from ._bpe_filter import bpe_jump_keep as bpe_jump_keep
from ._least_squares import refine_points as refine_points
from ._outliers import iqr_outliers as iqr_outliers, node_scores as node_scores, percentile_linear as percentile_linear, remove_outliers as remove_outliers
from ._second_association import second_association as second_association
from ._validity import (
    in_front_of_members as in_front_of_members,
    max_parallax_deg as max_parallax_deg,
    validity_gate as validity_gate,
)
from ._bpe_loss import bpe as bpe, group_bpe as group_bpe

# Calibration needs optimistix, a large import: loaded on first use (``import cdog_jax`` stays light).
_CALIBRATION = ("CalibrationHistory", "RefineInfo", "RigErrors", "align_rigs", "calibrate", "refine_rig", "rig_errors")
__all__ = [
    "bpe_jump_keep", "refine_points", "iqr_outliers", "node_scores", "percentile_linear", "remove_outliers",
    "second_association", "in_front_of_members", "max_parallax_deg", "validity_gate", "bpe", "group_bpe",
    *_CALIBRATION,
]


def __getattr__(name: str):
    if name in _CALIBRATION:
        from . import _calibration

        return getattr(_calibration, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(__all__)
