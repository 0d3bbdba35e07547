"""The library's face: `import orthosim` is light, and its names give what `orthosim run` computes."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import orthosim

SMALL_CASE = """\
[case]
name = "small"

[model]
kind = "parametric"
resolution = "coarse"

[treatment]
extractions = [14, 24]
duration_days = 4
step_days = 2
detector = "discrete"

[[loads]]
teeth = [13, 23]
force_cN = 150
direction = "distal"
"""


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("api") / "small.toml"
    path.write_text(SMALL_CASE)
    return path


def test_import_orthosim_loads_no_numerical_library():
    code = ("import sys, orthosim\n"
            "orthosim.OrthosimError, orthosim.__version__\n"
            "print(sorted(m for m in ('numpy', 'trimesh', 'fcl', 'scipy', 'numba') if m in sys.modules))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "[]"


@pytest.mark.slow  # imports the whole library: over the fast tier's 2 s budget under load
def test_every_public_name_resolves_and_says_what_it_is():
    for name in orthosim.__all__:
        value = getattr(orthosim, name)
        if name != "__version__":
            doc = (value.__doc__ or "").strip()
            assert doc and not doc.startswith(f"{name}("), f"orthosim.{name} has no docstring of its own"
    with pytest.raises(AttributeError):
        orthosim.no_such_name


def test_a_bad_case_file_is_an_orthosim_error(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(SMALL_CASE.replace("step_days = 2", "step_days = -2"))
    with pytest.raises(orthosim.OrthosimError, match="treatment.step_days"):
        orthosim.load_case(bad)


@pytest.mark.slow  # builds a model (teeth, sphere trees) and simulates: over the fast tier's 2 s budget
def test_simulate_gives_each_step_and_contacts_finds_what_the_step_found(small):
    model = orthosim.build(small)
    records = list(orthosim.simulate(model, steps=2, detector="continuous"))
    assert [r.step for r in records] == [0, 1, 2] and [r.time_days for r in records] == [0.0, 2.0, 4.0]
    moved = False
    for record in records:
        assert all(np.shape(T) == (4, 4) for T in record.poses.values())
        assert orthosim.contacts(model, record.poses, "continuous").touching == record.touching
        moved |= not np.allclose(record.poses[13], records[0].poses[13])
    assert moved  # the loaded canine moved


@pytest.mark.slow  # draws with the offscreen renderer: over the fast tier's 2 s budget
def test_render_frame_draws_a_step_as_the_image_regression_helpers_do(small):
    from orthosim_render import Frame, render_frame
    from orthosim_render.regression import DEFAULT_SIZE, render_case_frame

    model = orthosim.build(small)
    last = list(orthosim.simulate(model))[-1]
    frame = render_frame(model, last, "right_buccal", DEFAULT_SIZE)
    assert isinstance(frame, Frame) and frame.shape == (DEFAULT_SIZE[1], DEFAULT_SIZE[0], 3) and frame.dtype == np.uint8
    assert frame._repr_png_().startswith(b"\x89PNG\r\n\x1a\n")
    reference = render_case_frame(small, -1, "right_buccal", DEFAULT_SIZE, labels=False)
    assert np.array_equal(np.asarray(frame), np.asarray(reference))
