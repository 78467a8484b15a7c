"""Modal identification of free decays: damped modes shared by all gages (Matrix Pencil start,
variable-projection least squares), order selection, per-channel verdicts, the Cramér–Rao bound,
and the report's own peak-ratio decrement."""
