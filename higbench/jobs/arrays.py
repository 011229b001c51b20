"""A round of jobs as one submitit job array (``submitit_local``, ``submitit_slurm``).

Hydra's submitit launcher submits a multirun batch by batch and waits for each whole batch
(Hydra issues #3091, #3058, #3201). Here the driver submits the missing jobs of a round as ONE
array (``executor.map_array``): task i runs the round's job-list multirun narrowed to job i
(``worker.array_task``), the entry point a local launch runs, which claims the job in the
ledger first. SLURM runs up to ``array_parallelism`` tasks at once.

Launcher settings are the keys of Hydra's submitit launcher (``partition=gpu``,
``timeout_min=90``, or ``hydra.launcher.partition=gpu``), mapped onto submitit's parameters.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

SUBMITIT = {"submitit_local": "local", "submitit_slurm": "slurm"}
# submitit's own names for the settings every cluster has (AutoExecutor's shared parameters)
SHARED = ("timeout_min", "mem_gb", "nodes", "cpus_per_task", "gpus_per_node", "tasks_per_node", "name", "stderr_to_stdout")
# Hydra's submitit launcher keys for SLURM-only settings: submitit's slurm_<key>
SLURM_ONLY = (
    "partition", "qos", "comment", "constraint", "exclude", "gres", "account", "cpus_per_gpu", "gpus_per_task",
    "mem_per_gpu", "mem_per_cpu", "array_parallelism", "signal_delay_s", "max_num_timeout", "additional_parameters",
    "setup", "srun_args", "use_srun", "wckey", "nodelist",
)  # fmt: skip
DEFAULT_SLURM_TIME_MIN = 60


class LauncherError(ValueError):
    """A launcher setting that cannot work: one line naming the key and the value."""


def submitit_parameters(name: str, settings: dict[str, Any]) -> dict[str, Any]:
    """submitit's ``update_parameters`` keywords for the launcher ``name`` and its settings
    (keys without their ``hydra.launcher.`` prefix); ``LauncherError`` on a key it has not."""
    cluster = SUBMITIT[name]
    known = SHARED + (SLURM_ONLY if cluster == "slurm" else ("visible_gpus",))
    params: dict[str, Any] = {}
    for key, value in settings.items():
        bare = key.removeprefix(f"{cluster}_")
        if bare not in known:
            raise LauncherError(
                f"hydra.launcher.{key}={value}: not a setting of the {name} launcher (known: {', '.join(sorted(known))})"
            )
        params[bare if bare in SHARED else f"{cluster}_{bare}"] = value
    if cluster == "slurm":
        params.setdefault("timeout_min", DEFAULT_SLURM_TIME_MIN)
    return params


def executor(name: str, folder: Path, settings: dict[str, Any]):
    """A submitit executor for the launcher ``name`` writing its files under ``folder``."""
    import submitit

    params = submitit_parameters(name, settings)  # refused before submitit is asked anything
    ex = submitit.AutoExecutor(folder=folder, cluster=SUBMITIT[name])
    try:
        ex.update_parameters(**params)
    except (AssertionError, NameError, ValueError, TypeError) as exc:  # a value of the wrong type
        raise LauncherError(f"{name} launcher: {' '.join(str(exc).split())[:300]}") from None
    return ex


def submit_array(ex, commands: Sequence[list[str]]) -> list:
    """Submit one task per command as one array (``map_array``); the submitit jobs."""
    from higbench.jobs.worker import array_task

    return ex.map_array(array_task, [list(c) for c in commands])  # one submission: an array on SLURM
