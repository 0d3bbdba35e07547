"""orthosim's pytest plugin: image regression tests of renders against committed golden PNGs.

Registered through the `pytest11` entry point, so every pytest run of a project that installs
orthosim loads it (ours too). It therefore imports nothing but pytest at import time; numpy, the
comparison and OpenGL load inside the fixture, when a test asks for it.

    from orthosim_render.regression import render_case_frame

    def test_case1_last_step(orthosim_image_regression):
        orthosim_image_regression.check(render_case_frame("cases/case1_first_premolar_extraction.toml", view="frontal"))

Conventions follow pytest-regressions': a golden lives in a folder named after the test module,
beside it (tests/test_x.py -> tests/test_x/), named after the test (`request.node.name`, non-word
characters as "_") unless `check` is given a name; a missing golden is written and the test fails
saying so; `--orthosim-force-regen` rewrites the goldens of failing checks and still fails them;
`--orthosim-regen-all` rewrites every golden checked and lets the tests pass, and the run's summary
lists every golden rewritten. Override the `orthosim_golden_dir` fixture (in a conftest or a
module) to keep goldens elsewhere. On a failure the candidate and the diff image are written into
the test's tmp_path and named in the assertion message.

Names: pytest-regressions (often installed beside us) already defines the fixture
`image_regression` and the options `--force-regen` and `--regen-all`. A second plugin adding the
same option makes argparse refuse both (pytest then cannot start at all), and a second fixture of
the same name silently replaces the other, depending on plugin order, in tests written for it.
Hence every name here carries the `orthosim` prefix.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

_REWRITTEN = pytest.StashKey[list]()


def pytest_addoption(parser) -> None:
    group = parser.getgroup("orthosim", "orthosim image regression")
    group.addoption("--orthosim-force-regen", action="store_true", default=False,
                    help="Rewrite the golden PNG and sidecar of every image check that fails; those tests still fail.")
    group.addoption("--orthosim-regen-all", action="store_true", default=False,
                    help="Rewrite the golden PNG and sidecar of every image check run; the tests pass and the "
                         "summary lists every golden rewritten.")


def pytest_configure(config) -> None:
    config.stash[_REWRITTEN] = []


def pytest_terminal_summary(terminalreporter, exitstatus, config) -> None:
    rewritten = config.stash.get(_REWRITTEN, [])
    if rewritten:
        terminalreporter.section("orthosim goldens rewritten")
        for line in rewritten:
            terminalreporter.write_line(line)
        terminalreporter.write_line(f"{len(rewritten)} golden image(s) rewritten: review them (git diff) before committing")


class ImageRegression:
    """The `orthosim_image_regression` fixture's value: `check(image, name=None)`."""

    def __init__(self, request, golden_dir: Path, tmp_path: Path):
        self._request = request
        self.golden_dir = Path(golden_dir)
        self._tmp_path = tmp_path
        self._config = request.config

    def golden_path(self, name: str | None = None) -> Path:
        basename = name or re.sub(r"\W", "_", self._request.node.name)
        return self.golden_dir / f"{basename}.png"

    def check(self, image, name: str | None = None, *, max_level: int = 3, max_fraction: float = 0.001) -> None:
        """Compare `image` with the golden `name` (default: the test's name); fail with the diff image's path.

        `image`: a `orthosim_render.regression.RenderedFrame` (its sidecar says what drew it), a (h, w, 3|4)
        uint8 array drawn in this process (this machine's GL is assumed), or a PNG path (its own
        sidecar if it has one, else this machine's GL). The mode (exact or within `max_level` levels
        on at most `max_fraction` of the pixels) comes from the sidecars, as for `orthosim imgdiff`.
        """
        __tracebackhide__ = True
        import numpy as np

        from orthosim_render import imgdiff
        from orthosim_render.regression import RenderedFrame, gl_identity

        if isinstance(image, RenderedFrame):
            pixels, sidecar = image.image, image.sidecar
        elif isinstance(image, (str, Path)):
            pixels, sidecar = imgdiff.read_png(image, "candidate"), imgdiff.read_sidecar(image) or gl_identity()
        else:
            pixels, sidecar = np.asarray(image), gl_identity()
        if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
            raise TypeError(f"check() takes (h, w, 3|4) uint8 images, got {pixels.dtype} {pixels.shape}")
        golden = self.golden_path(name)
        options = self._config.option

        if options.orthosim_regen_all:
            self._rewrite(golden, pixels, sidecar, "--orthosim-regen-all")
            return
        if not golden.exists():
            self._rewrite(golden, pixels, sidecar, "new")
            pytest.fail(f"golden {golden} did not exist: written with its sidecar {imgdiff.sidecar_path(golden)}; "
                        f"look at it, commit it, and run the test again", pytrace=False)
        tolerance = imgdiff.Tolerance(max_level, max_fraction)
        try:
            reference = imgdiff.read_png(golden, "golden")
            comparison = imgdiff.compare_images(reference, pixels, imgdiff.read_sidecar(golden), sidecar, tolerance,
                                                names=(str(golden), "the image checked"))
        except imgdiff.ImageInputError as err:
            if options.orthosim_force_regen:
                self._rewrite(golden, pixels, sidecar, "--orthosim-force-regen")
                pytest.fail(f"{err}; --orthosim-force-regen: rewrote {golden} and its sidecar", pytrace=False)
            pytest.fail(f"{err}; or rewrite the golden with pytest --orthosim-force-regen", pytrace=False)
        if comparison.matched:
            for note in comparison.notes:
                import warnings

                warnings.warn(f"{golden}: {note}; regenerate it with pytest --orthosim-force-regen", stacklevel=2)
            return
        obtained = self._tmp_path / f"{golden.stem}.obtained.png"
        from orthosim.storage.atomic import write_bytes

        from orthosim_render.png import encode_png

        write_bytes(obtained, encode_png(np.ascontiguousarray(pixels)))
        diff = imgdiff.write_diff_image(self._tmp_path / f"{golden.stem}.diff.png", reference, pixels, comparison)
        message = f"{golden}: {comparison.summary()}; diff image: {diff}; candidate: {obtained}"
        if options.orthosim_force_regen:
            self._rewrite(golden, pixels, sidecar, "--orthosim-force-regen")
            pytest.fail(f"{message}; --orthosim-force-regen: rewrote the golden and its sidecar", pytrace=False)
        raise AssertionError(f"{message} (if the change is intended: pytest --orthosim-force-regen)")

    def _rewrite(self, golden: Path, pixels, sidecar, why: str) -> None:
        from orthosim_render import imgdiff

        imgdiff.write_golden(golden, pixels, sidecar)
        self._config.stash[_REWRITTEN].append(f"{golden} ({why}; sidecar {imgdiff.sidecar_path(golden).name})")


@pytest.fixture
def orthosim_golden_dir(request) -> Path:
    """Where this test's goldens live: tests/test_x.py -> tests/test_x/ (pytest-regressions' datadir layout)."""
    return request.path.parent / request.path.stem


@pytest.fixture
def orthosim_image_regression(request, orthosim_golden_dir, tmp_path) -> ImageRegression:
    """Compare renders with golden PNGs: `orthosim_image_regression.check(image, name=None)`."""
    return ImageRegression(request, orthosim_golden_dir, tmp_path)
