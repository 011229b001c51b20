"""Where a run ran: versions, revision, host, threads, device; and its memory use."""

from __future__ import annotations

import os
import platform
import socket
import sys
import time

import numpy as np
import psutil
import torch

import higbench
from higbench.runfile.writer import H5PY_VERSION
from higbench.runner.revision import git_revision


def resolve_device(name: str) -> torch.device:
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name == "cuda" and not torch.cuda.is_available():
        raise ValueError("device='cuda': CUDA is not available on this machine (use cpu or auto)")
    return torch.device(name)


def environment(device: torch.device, parallel_jobs: int = 1) -> dict:
    env = {
        "higbench_version": higbench.__version__,
        "torch_version": str(torch.__version__),
        "numpy_version": np.__version__,
        "h5py_version": H5PY_VERSION,
        "python_version": sys.version.split()[0],
        "platform": platform.platform(),
        "hostname": socket.gethostname(),
        "boot_time": boot_time(),  # with the host, which machine: one class of hardware can differ in speed
        "cpu_model": cpu_model(),
        "git_revision": git_revision(),
        "torch_threads": torch.get_num_threads(),
        "cpu_count": os.cpu_count() or 0,
        "device": str(device),
        "device_name": torch.cuda.get_device_name(device)
        if device.type == "cuda"
        else platform.processor() or platform.machine(),
        "slurm_job_id": os.environ.get("SLURM_JOB_ID", ""),
        "parallel_jobs": int(parallel_jobs),  # jobs of its sweep sharing the machine (the plan's)
    }
    return env


def boot_time() -> str:
    """When this machine booted (UTC, to the second): a replaced or rebooted machine gets a new one."""
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime(psutil.boot_time()))


def cpu_model() -> str:
    """The CPU's model name (/proc/cpuinfo where there is one), else what platform says."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


_PROCESS = psutil.Process()


class CpuUse:
    """How much of its cores a run had since it started: the process's CPU seconds over wall
    seconds times its threads (about 1 alone on its cores; lower when other work shared them),
    and the machine's load averages when it finished. A timing is only as good as these.

    A resumed run counts every segment up to its checkpoint (``earlier``, from ``totals``): a
    run slowed for most of its budget and resumed for its last minute on an idle core would
    otherwise record the last minute's share alone."""

    def __init__(self, threads: int, earlier: dict | None = None):
        self.threads = max(1, threads)
        self.cpu0, self.wall0 = _cpu_seconds(), _wall_seconds()
        self.earlier = earlier or {"cpu_seconds": 0.0, "core_seconds": 0.0, "segments": 0}

    def totals(self) -> dict:
        """CPU seconds, core seconds (wall seconds times threads) and segments so far, this one included."""
        core = (_wall_seconds() - self.wall0) * self.threads
        return {"cpu_seconds": self.earlier["cpu_seconds"] + _cpu_seconds() - self.cpu0,
                "core_seconds": self.earlier["core_seconds"] + core, "segments": self.earlier["segments"] + 1}  # fmt: skip

    def summary(self) -> dict:
        total = self.totals()
        share = total["cpu_seconds"] / total["core_seconds"] if total["core_seconds"] > 0 else float("nan")
        load = " ".join(f"{x:.2f}" for x in os.getloadavg()) if hasattr(os, "getloadavg") else ""
        return {"cpu_share": round(share, 3), "load_at_finish": load, "cpu_segments": total["segments"]}


def _cpu_seconds() -> float:
    t = _PROCESS.cpu_times()
    return t.user + t.system


def _wall_seconds() -> float:
    return time.perf_counter()


def current_rss_mb() -> float:
    """Resident set size of this process now."""
    return _PROCESS.memory_info().rss / 2**20


class MemoryMonitor:
    """Peak RSS sampled over the run (ru_maxrss cannot be reset per run) and CUDA peak."""

    def __init__(self, device: torch.device):
        self.device = device
        self.baseline_mb = current_rss_mb()
        self.peak_rss_mb = self.baseline_mb
        if device.type == "cuda":
            torch.cuda.reset_peak_memory_stats(device)

    def sample(self) -> float:
        rss = current_rss_mb()
        self.peak_rss_mb = max(self.peak_rss_mb, rss)
        return rss

    def cuda_peak_mb(self) -> float:
        return torch.cuda.max_memory_allocated(self.device) / 2**20 if self.device.type == "cuda" else 0.0

    def summary(self) -> dict:
        self.sample()
        return {"peak_rss_mb": self.peak_rss_mb, "baseline_rss_mb": self.baseline_mb, "cuda_peak_mb": self.cuda_peak_mb()}
