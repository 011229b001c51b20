"""What a run shows: the bar's first frame, its width at 80 columns, sparse piped lines."""

import io
import sys

import pytest

from higbench.runner import progress as P


class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.fixture
def tty(monkeypatch):
    """A terminal as stderr (set in the test's call phase: pytest's capture resets sys.stderr per phase)."""
    return lambda: monkeypatch.setattr(sys, "stderr", Terminal())


def bar_line(p: P.Progress, ncols: int) -> str:
    p.bar.dynamic_ncols, p.bar.ncols = None, ncols
    p._postfix(p.bar.n)
    return str(p.bar)


def test_first_frame_shows_the_budget_left_not_a_rate_guess(tty):
    """Old code: '0/60.0s [00:00<13:53:29' (tqdm's ETA from a rate of ~0) and mixed '11/60.0s'."""
    tty()
    p = P.Progress(True, 60.0, name="oscillator/hig")
    line = bar_line(p, 120)
    assert " 0/60s [00:00, left 01:00," in line, line
    p._move(3, 11.4)
    assert " 11/60s [" in bar_line(p, 120) and "left 00:49" in bar_line(p, 120)
    p.close()


@pytest.mark.parametrize("ncols", [80, 100, 160])
def test_the_line_fits_the_terminal_with_a_real_bar(tty, ncols):
    """Old code: at 80 columns the bar shrank to one character and the line was cut."""
    tty()
    p = P.Progress(True, 60.0, name="dipole_cnn/hig")
    p.update(1234, 30.0, 1.2345e-3, 2.3456e-3)
    line = bar_line(p, ncols)
    assert len(line) <= ncols and line.endswith("]"), line
    bar = line.split("|")[1]
    assert len(bar) >= P.MIN_BAR, line
    if ncols >= 120:
        assert "step 1234" in line and "test 2.346e-03" in line
    p.close()


def test_piped_output_is_sparse(monkeypatch):
    """Old code: a piped 30 s toy run printed one line per evaluation (121 lines)."""
    out = io.StringIO()
    monkeypatch.setattr(sys, "stderr", out)
    p = P.Progress(True, 30.0, name="toy/hig")
    for i in range(121):
        p.update(i * 10, i * 0.25, 1.0, 1.0)
    p.close()
    lines = out.getvalue().splitlines()
    assert 10 <= len(lines) <= P.PIPE_LINES + 2, len(lines)
    assert "step    1200" in lines[-1] and "t    30.00s" in lines[-1]  # the last evaluation always shows
    assert "step       0" in lines[0]


def test_piped_by_updates_and_without_budget(monkeypatch):
    out = io.StringIO()
    monkeypatch.setattr(sys, "stderr", out)
    p = P.Progress(True, None, name="toy/hig", max_updates=100)
    for i in range(101):
        p.update(i, i * 0.1, 1.0, 1.0)
    p.close()
    assert len(out.getvalue().splitlines()) == 11
