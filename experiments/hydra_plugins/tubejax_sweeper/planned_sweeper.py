"""``hydra/sweeper: planned`` (``conf/hydra/sweeper/planned.yaml``): Hydra's basic sweeper,
launching only the jobs that ``experiments/sweep_jobs.py`` planned to run.

Hydra accepts sweepers only from the ``hydra_plugins`` namespace package, hence this module;
the planning itself (validation, duplicates, finished jobs) is :class:`sweep_jobs.SweepCheck`,
run by Hydra before the sweeper starts.
"""

from __future__ import annotations

import os
from pathlib import Path

from hydra._internal.core_plugins.basic_sweeper import BasicSweeper

import sweep_jobs


class PlannedSweeper(BasicSweeper):
    """Hydra's basic sweeper without the jobs :class:`sweep_jobs.SweepCheck` planned to skip
    (duplicates, jobs finished already). Without a plan (the callback removed with
    ``~hydra.callbacks.sweep_check``) every job runs."""

    def get_job_batch(self):
        batch = super().get_job_batch()
        skip = sweep_jobs.planned_skips(Path(os.path.abspath(str(self.config.hydra.sweep.dir)))) or {}
        return [j for j in batch if tuple(j) not in skip]

    def validate_batch_is_legal(self, batch) -> None:
        """Hydra composes every job's config here; the sweep check did that for every job already."""
        if sweep_jobs.planned_skips(Path(os.path.abspath(str(self.config.hydra.sweep.dir)))) is None:
            super().validate_batch_is_legal(batch)
