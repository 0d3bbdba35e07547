"""`pip install orthosim` as a new user does it: the built wheel, plain pip (no uv, no overrides), a
fresh virtual environment outside the checkout, an empty folder.

The wheel must resolve with and without the `cluster` extra, carry its shipped cases (`orthosim demo`
runs from an empty folder), install nothing generic at the top of site-packages, and give a user's
three-line image regression test the `orthosim_image_regression` fixture. pip reaches PyPI for the
dependencies; its downloads are kept in a cache under ~/.cache/orthosim so later runs take minutes,
not more. Skipped when PyPI cannot be reached.
"""

from __future__ import annotations

import json
import os
import socket
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PIP_CACHE = Path(os.environ.get("ORTHOSIM_CACHE", Path.home() / ".cache" / "orthosim")) / "pip-wheel-test"

# its tests share one costly set-up: the module is scheduled first (tests/conftest.py)
pytestmark = pytest.mark.heavy_setup

USER_TEST = textwrap.dedent("""
    from orthosim.exchange.case import DEFAULT_CASE
    from orthosim_render.regression import render_case_frame

    def test_case1_last_step(orthosim_image_regression):
        orthosim_image_regression.check(render_case_frame(DEFAULT_CASE, view="frontal"))
""")


def _pypi_reachable() -> bool:
    try:
        socket.create_connection(("pypi.org", 443), timeout=5).close()
        return True
    except OSError:
        return False


def _clean_env() -> dict:
    """No checkout on the path, no venv of ours, no GL choice: what a new user's shell has."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("PYTHONPATH", "VIRTUAL_ENV", "ORTHOSIM_GL", "PYOPENGL_PLATFORM", "PYTEST_ADDOPTS")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    return env


def _run(argv, cwd, timeout=600) -> subprocess.CompletedProcess:
    done = subprocess.run([str(a) for a in argv], cwd=cwd, capture_output=True, text=True, env=_clean_env(),
                          timeout=timeout)
    assert done.returncode == 0, f"{' '.join(map(str, argv))} exited {done.returncode}:\n{done.stdout[-3000:]}\n{done.stderr[-3000:]}"
    return done


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    if not _pypi_reachable():
        pytest.skip("PyPI cannot be reached: the wheel's dependencies come from there")
    out = tmp_path_factory.mktemp("wheel")
    # a copy of the sources, so that the build leaves no build/ or egg-info in the checkout
    src = out / "src"
    tracked = _run(["git", "ls-files", "-z"], ROOT).stdout.split("\0")
    for name in filter(None, tracked):
        if (ROOT / name).is_file():
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            (src / name).write_bytes((ROOT / name).read_bytes())
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--cache-dir", PIP_CACHE, "-w", out / "dist", src], out)
    (built,) = (out / "dist").glob("orthosim-*.whl")
    return built


@pytest.mark.slow
def test_the_wheel_installs_nothing_generic_and_carries_its_cases(wheel):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"orthosim", "orthosim_render", "orthosim_bench"}
    shipped = {Path(n).name for n in names if n.startswith("orthosim/cases/")}
    assert {f"{c}.toml" for c in ("case1_first_premolar_extraction", "case2_second_premolar_extraction",
                                  "case3_incisor_space_closure")} <= shipped
    assert shipped == {p.name for p in (ROOT / "cases").glob("*.toml")}


@pytest.mark.slow
def test_the_wheel_with_its_cluster_extra_resolves_with_plain_pip(wheel, tmp_path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], tmp_path)
    done = _run([venv / "bin" / "python", "-m", "pip", "install", "--dry-run", "--cache-dir", PIP_CACHE,
                 f"{wheel}[cluster]"], tmp_path)
    assert "Would install" in done.stdout and "distributed-" in done.stdout and "orthosim-0" in done.stdout


@pytest.mark.slow
def test_a_new_user_installs_the_wheel_runs_the_demo_and_an_image_regression_test(wheel, tmp_path):
    venv = tmp_path / "venv"
    _run([sys.executable, "-m", "venv", venv], tmp_path)
    py = venv / "bin" / "python"
    # --no-compile: pip's byte-compiling of every installed module (scipy's thousands) is 25 of the
    # install's 40 s here; Python compiles what the demo imports on first import instead
    _run([py, "-m", "pip", "install", "-q", "--no-compile", "--cache-dir", PIP_CACHE, wheel, "pytest"], tmp_path,
         timeout=900)
    empty = tmp_path / "empty"
    empty.mkdir()
    _run([venv / "bin" / "orthosim", "demo", "--size", "320x240", "-q"], empty)
    record = json.loads((empty / "out" / "demo" / "run.json").read_text())
    assert record["render"]["frames"] > 1 and record["render"]["gl_backend"]
    assert (empty / "out" / "demo" / "animation.mp4").stat().st_size > 0
    # the case came from inside the installed package, not from this checkout
    assert Path(record["case_file"]).resolve().is_relative_to(venv.resolve()), record["case_file"]

    project = tmp_path / "project"
    project.mkdir()
    (project / "test_render.py").write_text(USER_TEST)
    pytest_argv = [py, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_render.py"]
    first = subprocess.run(list(map(str, pytest_argv)), cwd=project, capture_output=True, text=True,
                           env=_clean_env(), timeout=600)
    assert first.returncode == 1 and "did not exist: written" in first.stdout  # a new golden is written, then looked at
    assert (project / "test_render" / "test_case1_last_step.png").is_file()
    _run(pytest_argv, project)  # the second run compares against it and passes
