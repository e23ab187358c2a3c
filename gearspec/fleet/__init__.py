"""Batch over recordings and joints on Dask, and the fleet report (``gearspec batch``).

:func:`batch` analyses every (recording, joint) as ``gearspec fit`` would, serially or on Dask, into
one table; :func:`trend_tests` finds the joints whose parameters changed over the dates by more than
their uncertainty allows; :func:`write_fleet_report` writes the report with its figures.
"""

from .batch import BASE_COLUMNS, analyse_one, batch, tasks

__all__ = ["batch", "analyse_one", "tasks", "BASE_COLUMNS"]
