"""The estimation core the three engines share (identify, diagnose, discover): :mod:`.crossval`
(folds, held-out loop, Z, parameter count) and :mod:`.reduction` (exact per-group reductions)."""

from .crossval import (HeldOut, critical_z, deal_folds, group_summary, held_out, n_params, row_folds, splits,
                       z_statistic)
from .reduction import GroupNormals, group_cross, harmonic_columns

__all__ = ["HeldOut", "critical_z", "deal_folds", "group_summary", "held_out", "n_params", "row_folds", "splits",
           "z_statistic", "GroupNormals", "group_cross", "harmonic_columns"]
