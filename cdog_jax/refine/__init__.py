"""Group-level stages: IQR outliers (Alg. 3), BPE jump filter (§IV-E), second association
(reference), the validity gate every valid group passes, least-squares refinement
(optimistix). Calibration (cameras refined from associations, the BPE as a differentiable
loss) is in :mod:`cdog_jax.calibration`."""

from ._bpe_filter import bpe_jump_keep as bpe_jump_keep
from ._least_squares import refine_points as refine_points
from ._outliers import (
    iqr_outliers as iqr_outliers,
    node_scores as node_scores,
    percentile_linear as percentile_linear,
    remove_outliers as remove_outliers,
)
from ._second_association import second_association as second_association
from ._validity import (
    in_front_of_members as in_front_of_members,
    max_parallax_deg as max_parallax_deg,
    validity_gate as validity_gate,
)
