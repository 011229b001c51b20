"""A local launch on a machine already busy says so before its runs start (their budgets in
seconds would buy less than on an idle machine); nothing is trained here."""

from higbench import jobs


def test_busy_machine_line_only_when_the_runs_would_share_cores():
    assert jobs.busy_machine(2, busy=0.1, cores=2) is None  # an idle 2-core machine, two runs
    assert jobs.busy_machine(1, busy=1.0, cores=2) is None  # one core held elsewhere, one run beside it
    line = jobs.busy_machine(2, busy=1.0, cores=2)
    assert line.startswith("[jobs] busy machine: 1.0 of 2 cores in use before 2 run(s) at once start")


def _one_missing_job(monkeypatch, busy):
    job = jobs.Job(figure="x", sweep="x", overrides={"seed": 0}, seed=0)
    monkeypatch.setattr(jobs, "busy_cores", lambda: busy)
    monkeypatch.setattr(jobs, "run_index", lambda root: {})
    monkeypatch.setattr(jobs, "launch", lambda js, root, **kw: None)

    def resolve(js, index):
        job.status = "missing"

    monkeypatch.setattr(jobs, "resolve", resolve)
    monkeypatch.setattr(jobs, "mark_final", lambda js, ledger: None)
    return job


def test_run_missing_warns_on_a_busy_machine(monkeypatch, tmp_path):
    lines = []
    job = _one_missing_job(monkeypatch, busy=float(jobs.available_cores()))
    jobs.run_missing([job], tmp_path, n_jobs=1, launcher="basic", log=lines.append, progress=False)
    assert sum(line.startswith("[jobs] busy machine:") for line in lines) == 1


def test_run_missing_is_quiet_on_an_idle_machine(monkeypatch, tmp_path):
    lines = []
    job = _one_missing_job(monkeypatch, busy=0.0)
    jobs.run_missing([job], tmp_path, n_jobs=1, launcher="basic", log=lines.append, progress=False)
    assert not any("busy" in line for line in lines)
