"""The console script finds conf/ from a non-editable install (wheel), not only a checkout."""

import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

pytestmark = pytest.mark.process  # a wheel installed into a venv of its own

ROOT = Path(__file__).resolve().parent.parent


def test_wheel_install_finds_packaged_configs(tmp_path):
    wheels = tmp_path / "wheels"
    build = subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels), str(ROOT)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert build.returncode == 0, build.stderr
    # A clean build: no deprecated license table, no config folder missing from `packages`.
    for warning in ("BuildBackendWarning", "SetuptoolsDeprecationWarning", "is absent from the `packages`"):
        assert warning not in build.stderr, build.stderr
    (wheel,) = wheels.glob("higbench-*.whl")
    # A venv that holds its own (non-editable) higbench and borrows torch/hydra from *this*
    # environment. Not `--system-site-packages`: that exposes the base interpreter's
    # packages, not this venv's, and a fresh machine's base Python has none.
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, timeout=120)
    py = venv / "bin" / "python"
    venv_site = Path(
        subprocess.run(
            [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        ).stdout.strip()
    )
    # Plain path lines in a .pth are appended after the venv's own site-packages, and .pth
    # files inside them are not run, so this environment's editable higbench stays invisible.
    ours = {sysconfig.get_paths()["purelib"], sysconfig.get_paths()["platlib"]}
    (venv_site / "_higbench_test_deps.pth").write_text("\n".join(sorted(ours)) + "\n")
    install = subprocess.run(
        [str(py), "-m", "pip", "install", "-q", "--no-deps", "--force-reinstall", str(wheel)],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert install.returncode == 0, install.stderr
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    # The job-list sweeper (docs/sweeps.md: `higbench -m hydra/sweeper=joblist ...` from any
    # directory, no PYTHONPATH) comes with the wheel too.
    where = subprocess.run(
        [
            str(py),
            "-c",
            "import higbench.cli as c, hydra_plugins.higbench_joblist_sweeper as j; print(c.config_dir()); print(j.__file__)",
        ],
        cwd=elsewhere,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert where.returncode == 0, where.stderr
    conf, sweeper = map(Path, where.stdout.split())
    assert conf.is_relative_to(venv_site), f"{conf} is not inside the wheel install {venv_site}"
    assert sweeper.is_relative_to(venv_site), f"{sweeper} is not inside the wheel install {venv_site}"
    assert "site-packages" in str(conf) and (conf / "config.yaml").is_file() and (conf / "problem" / "dipole_cnn.yaml").is_file()
    job = subprocess.run(
        [str(venv / "bin" / "higbench"), "problem=oscillator", "optimizer=adam", "--cfg", "job"],
        cwd=elsewhere,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert job.returncode == 0, job.stderr
    assert "name: oscillator" in job.stdout and "lr: 0.0003" in job.stdout  # the (problem, optimizer) specialisation


def test_every_subpackage_is_listed_in_pyproject():
    import tomllib

    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.parent.relative_to(ROOT).parts) for p in (ROOT / "higbench").rglob("__init__.py")}
    # conf/ ships as higbench.conf; each config group folder is a data-only package.
    found |= {".".join(("higbench", *p.relative_to(ROOT).parts)) for p in (ROOT / "conf").rglob("*") if p.is_dir()}
    found.add("higbench.conf")
    assert found <= listed, f"add {sorted(found - listed)} to [tool.setuptools] packages"
