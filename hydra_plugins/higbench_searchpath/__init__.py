"""Config folders of the user's own problems and optimizers, from ``HIGBENCH_SEARCHPATH``.

``higbench-league --searchpath DIR`` sets it (folders joined by ``os.pathsep``) before it
composes anything, so the league's own compositions, the identities of its jobs and the runs it
launches all find ``DIR/problem/<name>.yaml`` and ``DIR/optimizer/<name>.yaml``, as a run does
with ``hydra.searchpath=[file://DIR]``. Appended after higbench's conf/: a shipped config of
the same name wins. Unset, it adds nothing.
"""

import os

from hydra.core.config_search_path import ConfigSearchPath
from hydra.plugins.search_path_plugin import SearchPathPlugin

ENV = "HIGBENCH_SEARCHPATH"


class HigbenchSearchPath(SearchPathPlugin):
    def manipulate_search_path(self, search_path: ConfigSearchPath) -> None:
        for folder in filter(None, os.environ.get(ENV, "").split(os.pathsep)):
            search_path.append(provider="higbench-searchpath", path=f"file://{os.path.abspath(folder)}")
