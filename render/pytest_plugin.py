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

Semantic goldens: a `RenderedFrame` carries what each pixel shows (`orthosim_render.semantic_labels`); the
golden keeps it beside its PNG, and a failure then says what changed, tooth by tooth
(`orthosim_render.explain`), e.g. `tooth 13 moved 2.1 px (0.40 mm) distally; 27 other teeth
unchanged`. `check(frame, ignore=["gingiva", 13], max_shift_px=1)` leaves those things' pixels out
of the verdict. A golden without labels (or an array checked) compares pixels as before.
`--orthosim-results DIR` writes, after the session, DIR/index.html (one self-contained page: every
check that failed or was rewritten, golden | candidate | diff, what changed, the figures) and
DIR/summary.json, for a CI job to keep as its artifact.

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
_RESULTS = pytest.StashKey[list]()  # orthosim_render.report.regression_page.CheckRecord, in check order
_PARTS = ".orthosim-worker-parts"  # DIR/<this>/<worker>.json: each pytest-xdist worker's checks, for the controller


def pytest_addoption(parser) -> None:
    group = parser.getgroup("orthosim", "orthosim image regression")
    group.addoption("--orthosim-force-regen", action="store_true", default=False,
                    help="Rewrite the golden PNG and sidecar of every image check that fails; those tests still fail.")
    group.addoption("--orthosim-regen-all", action="store_true", default=False,
                    help="Rewrite the golden PNG and sidecar of every image check run; the tests pass and the "
                         "summary lists every golden rewritten.")
    group.addoption("--orthosim-results", metavar="DIR", default=None,
                    help="After the session write DIR/index.html (self-contained page of every image check that "
                         "failed or was rewritten: golden | candidate | diff, what changed) and DIR/summary.json.")


def pytest_configure(config) -> None:
    config.stash[_REWRITTEN] = []
    config.stash[_RESULTS] = []
    results = config.getoption("orthosim_results", None)
    if results and Path(results).exists() and not Path(results).is_dir():
        raise pytest.UsageError(f"--orthosim-results {results}: is a file, not a folder (fix: give a folder path)")
    if results and not hasattr(config, "workerinput"):  # the controller, before its workers start
        import shutil

        shutil.rmtree(Path(results) / _PARTS, ignore_errors=True)  # an interrupted session's leftovers are not this one's


def pytest_sessionfinish(session, exitstatus) -> None:
    """Write the results page once: a pytest-xdist worker hands its checks to the controller through
    a part file in DIR (its session ends before the controller's), the controller (or a session
    without workers) writes the page of every check."""
    config = session.config
    results = config.getoption("orthosim_results", None)
    if not results:
        return
    from orthosim_render.imageerrors import ImageInputError
    from orthosim_render.report.regression_page import read_worker_part, write_results, write_worker_part

    folder = Path(results)
    records = list(config.stash.get(_RESULTS, []))
    worker = getattr(config, "workerinput", None)
    if worker is not None:
        if records:
            write_worker_part(folder / _PARTS / f"{worker['workerid']}.json", records)
        return
    parts = sorted((folder / _PARTS).glob("*.json")) if (folder / _PARTS).is_dir() else []
    for part in parts:
        try:
            records += read_worker_part(part)
        except ImageInputError as err:  # refused whole, in one line: no page half made of it
            pytest.exit(f"orthosim: {err}", returncode=2)
        part.unlink()
    if parts:
        (folder / _PARTS).rmdir()
    write_results(folder, sorted(records, key=lambda r: r.test) if parts else records)


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

    def check(self, image, name: str | None = None, *, max_level: int = 3, max_fraction: float = 0.001,
              ignore=(), max_shift_px=0.0) -> None:
        """Compare `image` with the golden `name` (default: the test's name); fail with the diff image's path.

        `image`: a `orthosim_render.regression.RenderedFrame` (its sidecar says what drew it, its labels
        what each pixel shows), a (h, w, 3|4) uint8 array drawn in this process (this machine's GL is
        assumed), or a PNG path (its own sidecar and labels if it has them, else this machine's GL).
        The mode (exact or within `max_level` levels on at most `max_fraction` of the pixels) comes
        from the sidecars, as for `orthosim imgdiff`. With labels on both sides a failure says what
        changed, and `ignore` (kinds, FDI numbers, "contact 13-14") and `max_shift_px` leave the
        pixels of those things, or of things that only moved that far, out of the verdict
        (`max_shift_px` may map kinds or teeth to their own limits: {"contact": 2, 13: 1}).
        """
        __tracebackhide__ = True
        from orthosim_render import imgdiff

        pixels, sidecar, labels = self._candidate(image)
        golden = self.golden_path(name)
        options = self._config.option
        if options.orthosim_regen_all:
            self._rewrite(golden, pixels, sidecar, "--orthosim-regen-all", labels)
            return
        if not golden.exists():
            self._rewrite(golden, pixels, sidecar, "new", labels)
            pytest.fail(f"golden {golden} did not exist: written with its sidecar {imgdiff.sidecar_path(golden)}; "
                        f"look at it, commit it, and run the test again", pytrace=False)
        try:
            reference, golden_labels = self._golden(golden)
            comparison, explanation, mask = imgdiff.compare_labelled(
                reference, pixels, imgdiff.read_sidecar(golden), sidecar, imgdiff.Tolerance(max_level, max_fraction),
                (str(golden), "the image checked"), golden_labels, labels, ignore, max_shift_px)
        except imgdiff.ImageInputError as err:
            if options.orthosim_force_regen:
                self._rewrite(golden, pixels, sidecar, "--orthosim-force-regen", labels)
                pytest.fail(f"{err}; --orthosim-force-regen: rewrote {golden} and its sidecar", pytrace=False)
            pytest.fail(f"{err}; or rewrite the golden with pytest --orthosim-force-regen", pytrace=False)
        if comparison.matched:
            for note in comparison.notes:
                import warnings

                warnings.warn(f"{golden}: {note}; regenerate it with pytest --orthosim-force-regen", stacklevel=2)
            return
        self._fail(golden, reference, pixels, sidecar, labels, comparison, explanation, mask)

    def _candidate(self, image):
        """(pixels, sidecar, labels or None) of what `check` was given."""
        import numpy as np

        from orthosim_render import imgdiff
        from orthosim_render.semantic_labels import read_labels
        from orthosim_render.regression import RenderedFrame, gl_identity

        labels = None
        if isinstance(image, RenderedFrame):
            pixels, sidecar, labels = image.image, image.sidecar, image.labels
        elif isinstance(image, (str, Path)):
            pixels, sidecar = imgdiff.read_png(image, "candidate"), imgdiff.read_sidecar(image) or gl_identity()
            labels = read_labels(image, pixels)
        else:
            pixels, sidecar = np.asarray(image), gl_identity()
        if pixels.dtype != np.uint8 or pixels.ndim != 3 or pixels.shape[2] not in (3, 4):
            raise TypeError(f"check() takes (h, w, 3|4) uint8 images, got {pixels.dtype} {pixels.shape}")
        return pixels, sidecar, labels

    @staticmethod
    def _golden(golden: Path):
        from orthosim_render import imgdiff
        from orthosim_render.semantic_labels import read_labels

        reference = imgdiff.read_png(golden, "golden")
        return reference, read_labels(golden, reference)

    def _fail(self, golden, reference, pixels, sidecar, labels, comparison, explanation, mask) -> None:
        """Write the candidate (with its labels) and the diff image into tmp_path, record the check, fail."""
        __tracebackhide__ = True
        import numpy as np

        from orthosim.storage.atomic import write_bytes

        from orthosim_render import imgdiff
        from orthosim_render.semantic_labels import write_labels
        from orthosim_render.png import encode_png

        obtained = self._tmp_path / f"{golden.stem}.obtained.png"
        if labels is not None:
            write_labels(obtained, labels, pixels)
        write_bytes(obtained, encode_png(np.ascontiguousarray(pixels)))
        diff = imgdiff.write_diff_image(self._tmp_path / f"{golden.stem}.diff.png", reference, pixels, comparison, mask)
        changed = ""
        if explanation is not None:  # the same, for a machine, beside the diff image
            from orthosim.storage.atomic import write_json

            write_json(diff.with_suffix(".json"), {"summary": comparison.summary(), **explanation.to_json()})
            changed = f"; what changed: {explanation.text()}"
        message = f"{golden}: {comparison.summary()}{changed}; diff image: {diff}; candidate: {obtained}"
        regen = self._config.option.orthosim_force_regen
        self._record("regenerated" if regen else "failed", golden, reference, pixels, comparison, explanation, mask)
        if regen:
            self._rewrite(golden, pixels, sidecar, "--orthosim-force-regen", labels, record=False)
            pytest.fail(f"{message}; --orthosim-force-regen: rewrote the golden and its sidecar", pytrace=False)
        raise AssertionError(f"{message} (if the change is intended: pytest --orthosim-force-regen)")

    def _record(self, status, golden, reference, pixels, comparison=None, explanation=None, mask=None) -> None:
        """Keep this check for the --orthosim-results page (only when asked for: it holds the images)."""
        if not self._config.getoption("orthosim_results", None):
            return
        from orthosim_render.report.regression_page import CheckRecord

        self._config.stash[_RESULTS].append(CheckRecord.of(self._request.node.nodeid, status, golden, reference,
                                                           pixels, comparison, explanation, mask))

    def _rewrite(self, golden: Path, pixels, sidecar, why: str, labels=None, record: bool = True) -> None:
        from orthosim_render import imgdiff

        if record and self._config.getoption("orthosim_results", None):
            previous = None
            try:
                previous = imgdiff.read_png(golden, "golden") if golden.exists() else None
            except imgdiff.ImageInputError:
                pass  # an unusable golden being replaced: the page shows the new one alone
            self._record("new" if why == "new" else "regenerated", golden, previous, pixels)
        imgdiff.write_golden(golden, pixels, sidecar, labels)
        with_labels = f", labels {golden.stem}.labels.npz/.json" if labels is not None else ""
        self._config.stash[_REWRITTEN].append(f"{golden} ({why}; sidecar {imgdiff.sidecar_path(golden).name}{with_labels})")


@pytest.fixture
def orthosim_golden_dir(request) -> Path:
    """Where this test's goldens live: tests/test_x.py -> tests/test_x/ (pytest-regressions' datadir layout)."""
    return request.path.parent / request.path.stem


@pytest.fixture
def orthosim_image_regression(request, orthosim_golden_dir, tmp_path) -> ImageRegression:
    """Compare renders with golden PNGs: `orthosim_image_regression.check(image, name=None)`."""
    return ImageRegression(request, orthosim_golden_dir, tmp_path)
