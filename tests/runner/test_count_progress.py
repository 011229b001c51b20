"""Progress of work counted in pieces: one wording, quiet when disabled, a line per tenth piped."""

from higbench.runner.progress import CountProgress, count_text


def test_count_text_says_done_total_failed_and_time_left():
    assert count_text("figures", 7, 24, seconds_left=180, failed=1) == "[figures] 7 of 24 runs done (1 failed), about 3 min left"
    assert count_text("sweep", 3, 3, "jobs", seconds_left=10) == "[sweep] 3 of 3 jobs done"
    assert count_text("league", 0, 500, seconds_left=9000).endswith("about 2.5 h left")


def test_piped_progress_prints_about_a_line_per_tenth_and_the_last(capsys):
    progress = CountProgress(True, "league", 100)
    for done in range(101):
        progress.update(done)
    progress.close()
    lines = capsys.readouterr().err.splitlines()
    assert lines[0] == "[league] 0 of 100 runs done" and lines[-1] == "[league] 100 of 100 runs done"
    assert 10 <= len(lines) <= 12


def test_disabled_progress_prints_nothing(capsys):
    progress = CountProgress(False, "league", 10)
    for done in range(11):
        progress.update(done, seconds_left=5)
    progress.close()
    assert capsys.readouterr().err == ""
