"""Batch over recordings and joints on Dask, and the fleet report (``gearspec batch``).

:func:`batch` analyses every (recording, joint) as ``gearspec fit`` would, serially or on Dask, into
one table; :func:`trend_tests` finds the joints whose parameters changed over the dates by more than
their uncertainty allows (:func:`flagged_joints`); :func:`gearspec.report.fleet.write_fleet_report`
writes the report with its figures.  The fleet twin is :func:`gearspec.simulate.fleet.fleet_twin`.
"""

from .runner import BASE_COLUMNS, DIRECTIONS, analyse_one, batch, pair_counts, tasks
from .trend import flagged_joints, holm, trend_tests

__all__ = ["batch", "analyse_one", "tasks", "pair_counts", "BASE_COLUMNS", "DIRECTIONS", "trend_tests",
           "flagged_joints", "holm"]
