import pytest


@pytest.mark.process  # the pipe is the point
def test_results_into_a_closed_pipe_is_quiet(tmp_path):
    """`higbench-results ROOT | head -1`: no BrokenPipeError traceback when the reader leaves."""
    import subprocess
    import sys

    from synthetic import write_run

    for i in range(200):
        write_run(tmp_path / f"r{i}" / "run.h5", optimizer="sgd", test_loss=[1.0, 0.5])
    cmd = f"{sys.executable} -m higbench.results {tmp_path} | head -1"
    proc = subprocess.run(cmd, shell=True, capture_output=True, text=True, timeout=120)
    assert "Traceback" not in proc.stderr and "BrokenPipe" not in proc.stderr, proc.stderr[-2000:]
