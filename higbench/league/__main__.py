"""``higbench-league`` / ``python -m higbench.league``: the league's command (higbench.league.driver)."""

import sys

import pandas as pd


def main(argv=None) -> int:
    from higbench.league.driver import main as league_main

    pd.set_option("display.width", 250)
    return league_main(argv)


if __name__ == "__main__":
    sys.exit(main())
