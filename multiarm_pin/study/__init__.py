"""Studies: sweeps and Monte Carlo runs of a scenario or grasp file, on Dask.

- :mod:`~multiarm_pin.study.spec`: study files, key paths, the cases they define;
- :mod:`~multiarm_pin.study.metrics`: per-case metrics (simulation or grasp);
- :mod:`~multiarm_pin.study.case`: running one case (a Dask task or a loop iteration);
- :mod:`~multiarm_pin.study.execution`: :class:`Study`, on a ``LocalCluster`` or a scheduler;
- :mod:`~multiarm_pin.study.store`: the results folder (rows written as cases finish);
- :mod:`~multiarm_pin.study.report`: ``report.md`` and plots;
- :mod:`~multiarm_pin.study.cli`: ``multiarm-pin sweep``.
"""

from multiarm_pin.study.execution import Study
from multiarm_pin.study.spec import Case, StudySpec, load_study
from multiarm_pin.study.store import read_table

__all__ = ["Case", "Study", "StudySpec", "load_study", "read_table"]
