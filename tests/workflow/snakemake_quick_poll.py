"""``python -m snakemake`` with the Slurm executor plugin's status checks at most :data:`POLL_S` apart
(tests/workflow/test_slurm.py runs the workflow through Slurm with this).

The plugin (snakemake-executor-plugin-slurm 2.8) polls ``sacct`` first after
``slurm-init-seconds-before-status-checks``, then waits 10 s longer after every poll that finds no
job finished (up to 180 s), and has no setting for that step: right for cluster jobs of minutes to
hours, but the test's jobs take 5-15 s each, one after another, so a third of its Slurm run was
waiting for the next poll. Everything else (submission, accounting, the profile) is the plugin's and
Snakemake's own.
"""
import sys

from snakemake.cli import main
from snakemake_executor_plugin_slurm import Executor

POLL_S = 3.0
"""The longest wait between two status checks, s."""

_wait = Executor.next_seconds_between_status_checks      # RemoteExecutor's property
Executor.next_seconds_between_status_checks = property(lambda self: min(_wait.fget(self), POLL_S), _wait.fset)

if __name__ == "__main__":
    sys.exit(main())
