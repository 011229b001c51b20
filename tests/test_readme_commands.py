"""Every shell command the README and the recipe show names something that exists.

A fast static check (no command is run): each `make` target is in the Makefile, each console
script in pyproject.toml, each `python -m` module importable and each script or file present,
each `problem=`/`optimizer=`/`+experiment=` value a config, each `pip install -e ".[x]"`
extra declared, and each relative link of the README a file. Running the commands is what
a fresh clone is for (the README lists them in order).
"""

from __future__ import annotations

import importlib.metadata
import importlib.util
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
DOCS = [ROOT / "README.md", ROOT / "docs" / "recipe.md"]
# From the installed package's metadata (Python 3.10 has no tomllib): `make install` installs
# this checkout in editable mode, so these are pyproject.toml's.
SCRIPTS = {e.name for e in importlib.metadata.entry_points(group="console_scripts") if e.value.startswith("higbench")}
EXTRAS = set(importlib.metadata.metadata("higbench").get_all("Provides-Extra") or [])
CONF_DIRS = [ROOT / "conf", ROOT / "examples" / "heat" / "conf"]


def shell_commands(path: Path) -> list[str]:
    """Commands of the ```bash blocks: comments dropped, continuation lines joined."""
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", path.read_text(), flags=re.S):
        joined = re.sub(r"\\\n\s*", " ", block)
        for line in joined.splitlines():
            line = re.sub(r"\s+#.*$", "", line).strip()
            if line and not line.startswith("#"):
                commands.append(line)
    return commands


COMMANDS = [(p.name, c) for p in DOCS for c in shell_commands(p)]


def make_targets() -> set[str]:
    return set(re.findall(r"^([A-Za-z][\w-]*):", (ROOT / "Makefile").read_text(), flags=re.M))


def config_exists(group: str, name: str) -> bool:
    return any((d / group / f"{name}.yaml").is_file() for d in CONF_DIRS)


def check_overrides(words: list[str]) -> None:
    for word in words:
        key, _, value = word.partition("=")
        group = {"problem": "problem", "optimizer": "optimizer", "+experiment": "experiment"}.get(key)
        if group:
            for name in value.split(","):
                assert config_exists(group, name), f"{word}: no conf/{group}/{name}.yaml"


def check(command: str) -> None:
    if " && " in command:
        for part in command.split(" && "):
            check(part)
        return
    words = shlex.split(command)
    head, rest = words[0], words[1:]
    if head == "mkdir":
        assert rest == ["-p", "outputs"], f"{command}: only outputs/ is made"
    elif head == "cp":
        assert (ROOT / rest[0]).is_file(), f"cp {rest[0]}: no such file"
    elif head == "jupyter":  # a copy of a shipped notebook, executed in outputs/
        assert rest[0] == "execute" and (ROOT / "examples" / Path(rest[-1]).name).is_file(), f"{command}: no such notebook"
    elif head == "python" and rest[0] == "-c":
        compile(rest[1], "<README>", "exec")
    elif head == "make":
        for target in (w for w in rest if "=" not in w):
            assert target in make_targets(), f"make {target}: no such target"
    elif head in SCRIPTS:
        check_overrides(rest)
        for word in rest:  # a path argument that should exist in a checkout
            if word.startswith(("scripts/", "examples/", "docs/")):
                assert (ROOT / word).exists(), f"{word}: no such file"
    elif head == "python":
        if rest[0] == "-m":
            assert importlib.util.find_spec(rest[1]) is not None, f"python -m {rest[1]}: no such module"
        else:
            assert (ROOT / rest[0]).is_file(), f"python {rest[0]}: no such file"
    elif head == "source":
        assert rest == [".venv/bin/activate"] and "VENV ?= .venv" in (ROOT / "Makefile").read_text()
    elif head == "export":
        name, _, value = rest[0].partition("=")
        assert name == "PYTHONPATH" and (ROOT / value).is_dir(), f"export {rest[0]}: no such folder"
    elif head == "pip":
        extras = re.findall(r"\[([\w,]+)\]", command)
        assert extras and set(",".join(extras).split(",")) <= EXTRAS, f"{command}: unknown extra"
    else:
        pytest.fail(f"a command this test does not know how to check: {command}")


@pytest.mark.parametrize(("doc", "command"), COMMANDS, ids=[c for _, c in COMMANDS])
def test_command_names_real_things(doc, command):
    check(command)


def test_commands_were_found():
    assert len(COMMANDS) >= 20 and any(c.startswith("make run") for _, c in COMMANDS)


def test_activation_comes_before_the_first_tool_command():
    commands = shell_commands(ROOT / "README.md")
    first_tool = next(i for i, c in enumerate(commands) if c.split()[0] in SCRIPTS | {"python"})
    assert commands.index("source .venv/bin/activate") < first_tool


def test_readme_links_exist():
    text = (ROOT / "README.md").read_text()
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not target.startswith("http"):
            assert (ROOT / target).exists(), f"README links to {target}, which does not exist"


def test_check_catches_a_wrong_command():
    with pytest.raises(AssertionError):
        check("make rnu")
    with pytest.raises(AssertionError):
        check("higbench problem=oscilator")
    with pytest.raises(AssertionError):
        check("python scripts/no_such_script.py")
