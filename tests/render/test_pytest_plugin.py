"""The pytest plugin a user gets by installing orthosim: cheap to load, clash-free, and the golden workflow.

Each test runs pytest in a child process on a small project in tmp_path, as a user's CI would.
"""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from render_helpers import pytest_in

from orthosim_render.imgdiff import read_png, read_sidecar, sidecar_path

ROOT = Path(__file__).resolve().parents[2]


def test_loading_the_plugin_imports_no_opengl_numpy_or_numba():
    code = ("import sys, orthosim_render.pytest_plugin; "
            "print(sorted(m for m in ('OpenGL', 'pyrender', 'numba', 'numpy', 'skimage', 'trimesh', 'PIL') if m in sys.modules))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "[]"


def test_the_plugin_is_registered_for_every_pytest_run():
    from importlib.metadata import entry_points

    (ep,) = [e for e in entry_points(group="pytest11") if e.name == "orthosim"]
    assert ep.value == "orthosim_render.pytest_plugin"


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_it_works_beside_a_plugin_with_pytest_regressions_names(tmp_path):
    """pytest-regressions defines `image_regression`, `--force-regen` and `--regen-all`: both load, both fixtures work."""
    (tmp_path / "regressions_like.py").write_text(textwrap.dedent("""
        import pytest

        def pytest_addoption(parser):
            group = parser.getgroup("regressions")
            group.addoption("--force-regen", action="store_true", default=False)
            group.addoption("--regen-all", action="store_true", default=False)

        @pytest.fixture
        def image_regression():
            return "theirs"
    """))
    (tmp_path / "test_both.py").write_text(textwrap.dedent("""
        def test_both(image_regression, orthosim_image_regression, request):
            assert image_regression == "theirs"
            assert hasattr(orthosim_image_regression, "check")
            assert request.config.getoption("force_regen") is True
            assert request.config.getoption("orthosim_force_regen") is False
    """))
    r = pytest_in(tmp_path, "-p", "regressions_like", "--force-regen", "test_both.py")
    assert r.returncode == 0, r.stdout + r.stderr


USER_TEST = """
import json
import numpy as np
from orthosim_render.png import encode_png

def test_plate(orthosim_image_regression, tmp_path):
    im = np.zeros((60, 80, 3), np.uint8)
    im[10:50, 20:60] = (int(open("shade.txt").read()), 180, 150)
    # a PNG path with its own sidecar (as `orthosim run` frames could carry): no GL context needed
    (tmp_path / "plate.png").write_bytes(encode_png(im))
    (tmp_path / "plate.json").write_text(json.dumps({"gl_renderer": "llvmpipe (test)", "mesa_version": "1.0"}))
    orthosim_image_regression.check(tmp_path / "plate.png")
"""


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_golden_workflow_new_pass_fail_with_diff_then_regenerate(tmp_path):
    project = tmp_path / "project"
    project.mkdir()
    (project / "test_user.py").write_text(USER_TEST)
    (project / "shade.txt").write_text("200")
    golden = project / "test_user" / "test_plate.png"  # pytest-regressions' layout: module folder, test name

    first = pytest_in(project, "test_user.py")
    assert first.returncode == 1 and f"golden {golden} did not exist" in first.stdout
    assert golden.is_file() and read_sidecar(golden).mesa_version == "1.0"  # the candidate's sidecar, kept
    assert pytest_in(project, "test_user.py").returncode == 0

    (project / "shade.txt").write_text("120")
    changed = pytest_in(project, "test_user.py", "--basetemp", str(tmp_path / "bt"))
    assert changed.returncode == 1
    diff = re.search(r"diff image: (\S+\.diff\.png)", changed.stdout).group(1)
    assert Path(diff).is_file() and Path(diff).is_relative_to(tmp_path / "bt")  # the test's tmp_path
    assert "differ (exact: same llvmpipe (test), Mesa 1.0, through osmesa)" in changed.stdout and "1600 of 4800 pixels differ" in changed.stdout
    panels = read_png(diff)
    assert panels.shape == (60, 240, 3)

    forced = pytest_in(project, "test_user.py", "--orthosim-force-regen")
    assert forced.returncode == 1 and "--orthosim-force-regen: rewrote the golden and its sidecar" in forced.stdout
    assert "orthosim goldens rewritten" in forced.stdout and str(golden) in forced.stdout
    assert read_png(golden)[20, 30, 0] == 120
    assert pytest_in(project, "test_user.py").returncode == 0

    (project / "shade.txt").write_text("90")
    regen = pytest_in(project, "test_user.py", "--orthosim-regen-all")
    assert regen.returncode == 0 and "1 golden image(s) rewritten" in regen.stdout and str(golden) in regen.stdout
    assert read_png(golden)[20, 30, 0] == 90 and sidecar_path(golden).is_file()


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_readme_example_test_runs_as_written(tmp_path):
    """The README's three-line regression test: the first run writes the golden, the second passes."""
    text = (ROOT / "README.md").read_text()
    section = text.split("## Image regression tests", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    body = [line for line in code.strip().splitlines() if line.strip()]
    assert len(body) == 3  # an import, the test's name, one line that renders and checks
    (tmp_path / "test_readme_example.py").write_text(code)
    args = (str(tmp_path / "test_readme_example.py"),)
    first = pytest_in(tmp_path, *args, cwd=ROOT)  # cwd: the example's case path is relative to a checkout
    assert first.returncode == 1 and "did not exist: written" in first.stdout, first.stdout + first.stderr
    goldens = list((tmp_path / "test_readme_example").glob("*.png"))
    assert len(goldens) == 1 and read_png(goldens[0]).shape == (240, 320, 3)
    second = pytest_in(tmp_path, *args, cwd=ROOT)
    assert second.returncode == 0, second.stdout + second.stderr
    assert np.any(read_png(goldens[0]) != read_png(goldens[0])[0, 0])  # not an empty frame
