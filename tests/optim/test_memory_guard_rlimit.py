"""The memory guard under ``ulimit -v``: a capped address space is what the process can have,
whatever the machine's available memory says (RLIMIT_AS read through ``resource.getrlimit``)."""

from __future__ import annotations

import resource

import psutil
import pytest

from higbench.errors import ConfigError
from higbench.optim import memory_guard

MB = 2**20


def cap_address_space(monkeypatch, headroom: int) -> None:
    """RLIMIT_AS's soft limit as if ``ulimit -v`` left ``headroom`` bytes above this process's size now."""
    real = resource.getrlimit

    def getrlimit(which):
        if which == resource.RLIMIT_AS:
            return psutil.Process().memory_info().vms + headroom, resource.RLIM_INFINITY
        return real(which)

    monkeypatch.setattr(resource, "getrlimit", getrlimit)


def test_a_capped_address_space_is_what_the_guard_sees(monkeypatch):
    available = psutil.virtual_memory().available
    cap_address_space(monkeypatch, 64 * MB)
    seen, source = memory_guard.available_bytes()
    assert seen < available and 32 * MB < seen <= 64 * MB and "RLIMIT_AS" in source  # the process grows a little


def test_no_cap_leaves_the_available_memory(monkeypatch):
    real = resource.getrlimit
    monkeypatch.setattr(resource, "getrlimit", lambda w: (resource.RLIM_INFINITY,) * 2 if w == resource.RLIMIT_AS else real(w))
    seen, source = memory_guard.available_bytes()
    assert source == "available memory" and seen > 0
    assert memory_guard.address_space_headroom() is None


def test_a_cap_above_the_available_memory_changes_nothing(monkeypatch):
    cap_address_space(monkeypatch, 1 << 50)
    assert memory_guard.available_bytes()[1] == "available memory"


def test_a_step_beyond_the_cap_is_refused_with_the_batch_that_fits(monkeypatch):
    cap_address_space(monkeypatch, 64 * MB)
    needs = memory_guard.estimate_bytes(1024, 8, 2000, "float32", "auto", jacobian="structured").total
    assert 64 * MB < needs < psutil.virtual_memory().available  # fits the machine, not the cap
    with pytest.raises(ConfigError, match=r"RLIMIT_AS \(ulimit -v\)\); largest batch size that fits: \d+") as err:
        memory_guard.check(1024, 8, 2000, jacobian="structured")
    assert err.value.key == "batch_size"


def test_a_hig_run_under_the_cap_is_refused_in_one_line(higbench, monkeypatch):
    """The issue's case: a HIG run under ``ulimit -v`` ended in a traceback; now one line, exit 2."""
    cap_address_space(monkeypatch, 0)
    code, _out, err = higbench("problem=toy", "optimizer=hig", "batch_size=64")
    assert code == 2, err
    (line,) = err.strip().splitlines()
    assert line.startswith("higbench: error: batch_size=64: ") and "RLIMIT_AS" in line, line
