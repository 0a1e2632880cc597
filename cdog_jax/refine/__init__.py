"""Group-level stages: IQR outliers (Alg. 3), BPE jump filter (§IV-E), second association
(reference), the validity gate every valid group passes, least-squares refinement
(optimistix). Calibration (cameras refined from associations, the BPE as a differentiable
loss) is in :mod:`cdog_jax.calibration`."""

# No public names: the stages are parts of C-DOG (cdog_jax.Config runs them); their rules
# are tested one by one from their modules.
