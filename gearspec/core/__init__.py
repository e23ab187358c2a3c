"""The estimation core the three engines share (identify, diagnose, discover).

:mod:`.crossval`: folds of whole groups, the held-out loop, the held-out Z statistic and its
critical value, the parameter count.  :mod:`.reduction`: the pieces of the exact per-group
reductions (harmonic columns with phases about the group mean).
"""

from .crossval import (HeldOut, critical_z, deal_folds, group_summary, held_out, n_params, row_folds, splits,
                       z_statistic)
from .reduction import harmonic_columns

__all__ = ["HeldOut", "critical_z", "deal_folds", "group_summary", "held_out", "n_params", "row_folds", "splits",
           "z_statistic", "harmonic_columns"]
