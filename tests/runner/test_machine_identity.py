"""A run names the machine that trained it (host, boot time, CPU model), so that runs of one
hardware class from different machines can be told apart."""

import calendar
import time

import torch

from higbench.runner import environment


def test_a_runs_environment_names_its_machine():
    env = environment.environment(torch.device("cpu"))
    booted = calendar.timegm(time.strptime(env["boot_time"], "%Y-%m-%dT%H:%M:%SZ"))
    assert 0 < time.time() - booted < 10 * 365 * 86400  # a boot in the past, read as UTC
    again = calendar.timegm(time.strptime(environment.boot_time(), "%Y-%m-%dT%H:%M:%SZ"))
    assert abs(again - booted) <= 2  # the same machine, the same boot (psutil may round it by a second)
    assert isinstance(env["cpu_model"], str) and env["cpu_model"].strip() and env["hostname"]
