"""The API reference (docs/api, Sphinx autodoc) builds from the public names' docstrings with warnings as errors."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.slow  # a Sphinx build imports the whole library: over the fast tier's 2 s budget
def test_the_api_reference_builds_with_warnings_as_errors_and_documents_every_public_name(tmp_path):
    pytest.importorskip("sphinx")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", str(ROOT / "docs" / "api"),
                           str(tmp_path)], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stdout + done.stderr
    page = (tmp_path / "index.html").read_text()
    import orthosim

    for name in orthosim.__all__[1:]:  # every public name but __version__, with its own docstring
        assert f'id="orthosim.{name}"' in page, name
    assert 'id="orthosim_render.render_frame"' in page and "uint8" in page
