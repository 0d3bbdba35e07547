"""The image-regression page a CI job keeps: every check of a pytest session that failed or rewrote its golden.

`pytest --orthosim-results DIR` (orthosim_render.pytest_plugin) collects one `CheckRecord` per such
check and, after the session, `write_results` writes DIR/index.html, a single self-contained page
(images inlined as data URIs, no script, nothing fetched) showing golden | candidate | differences
side by side with what changed tooth by tooth and the comparison's figures, and DIR/summary.json,
the same facts for a machine. Each file is written atomically; a session with nothing to show
still writes both, saying so, so that a CI job's artifact step always finds them.
"""

from __future__ import annotations

import base64
import dataclasses
import datetime
import html
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.storage.atomic import write_json, write_text

SUMMARY_FORMAT = "orthosim-image-regression/1"


@dataclass(frozen=True)
class CheckRecord:
    """One check for the page: which test and golden, what became of it, the figures and the images (PNG bytes)."""

    test: str  # pytest node id
    golden: str  # path of the golden PNG
    status: str  # "failed" | "regenerated" | "new"
    summary: str  # the comparison's one line, or what was written
    explanation: dict | None  # orthosim_render.explain.Explanation.to_json(), when both sides carry labels
    figures: dict | None  # mode, pixels compared / differing / beyond tolerance / left out by label, SSIM
    golden_png: bytes | None
    candidate_png: bytes
    diff_png: bytes | None  # the differences panel alone
    changes_png: bytes | None = None  # each changed thing where it was and where it is (labels on both sides)

    @classmethod
    def of(cls, test: str, status: str, golden: Path, reference, candidate, comparison=None, explanation=None,
           mask=None) -> "CheckRecord":
        """Build the record from the arrays the check had; a rewritten golden is compared with what it replaced."""
        from orthosim_render import imgdiff
        from orthosim_render.png import encode_png

        candidate = np.ascontiguousarray(candidate, np.uint8)
        same = reference is not None and np.shape(reference)[:2] == candidate.shape[:2]
        if comparison is None and same:
            comparison = imgdiff.compare_images(reference, candidate)
        diff = None
        if comparison is not None and same:
            w = candidate.shape[1]
            diff = encode_png(np.ascontiguousarray(imgdiff.diff_image(reference, candidate, comparison, mask)[:, 2 * w:]))
        figures = None
        if comparison is not None:
            figures = {"mode": comparison.mode, "mode_reason": comparison.mode_reason, "size": list(comparison.size),
                       "pixels_compared": comparison.pixels, "differing_pixels": comparison.differing_pixels,
                       "beyond_tolerance_pixels": comparison.beyond_pixels, "masked_pixels": comparison.masked_pixels,
                       "largest_level": comparison.largest_level,
                       "ssim": None if np.isnan(comparison.ssim) else round(comparison.ssim, 5)}
        summary = comparison.summary() if comparison is not None else (
            "golden written (there was none)" if status == "new" else "golden rewritten")
        changes = None
        if explanation is not None and explanation.changes and reference is not None:
            changes = encode_png(np.ascontiguousarray(explanation.picture(reference)))
        return cls(test, str(golden), status, summary, explanation.to_json() if explanation is not None else None,
                   figures, encode_png(np.ascontiguousarray(reference, np.uint8)) if reference is not None else None,
                   encode_png(candidate), diff, changes)

    def to_json(self) -> dict:
        data = asdict(self)
        for name in ("golden_png", "candidate_png", "diff_png", "changes_png"):
            data.pop(name)
        return data


def _data_uri(png: bytes | None) -> str | None:
    return None if png is None else "data:image/png;base64," + base64.b64encode(png).decode("ascii")


def render_page(records: list[CheckRecord], created: str) -> str:
    """index.html for `records` (Jinja2, autoescaped)."""
    from jinja2 import Environment, FileSystemLoader, StrictUndefined, select_autoescape

    env = Environment(loader=FileSystemLoader(Path(__file__).parent / "templates"),
                      autoescape=select_autoescape(["html", "j2"]), undefined=StrictUndefined,
                      trim_blocks=True, lstrip_blocks=True)
    checks = [{"record": r, "anchor": f"check-{i}", "golden_uri": _data_uri(r.golden_png),
               "candidate_uri": _data_uri(r.candidate_png), "diff_uri": _data_uri(r.diff_png),
               "changes_uri": _data_uri(r.changes_png)}
              for i, r in enumerate(records, 1)]
    counts = {status: sum(r.status == status for r in records) for status in ("failed", "regenerated", "new")}
    return env.get_template("regression.html.j2").render(checks=checks, counts=counts, created=created,
                                                         version=__version__, escape=html.escape)


_BYTES_FIELDS = ("golden_png", "candidate_png", "diff_png", "changes_png")


def write_worker_part(path: Path, records: list[CheckRecord]) -> None:
    """A pytest-xdist worker's checks as JSON (PNG bytes in base64), written atomically for the controller."""

    rows = []
    for r in records:
        row = dataclasses.asdict(r)
        for key in _BYTES_FIELDS:
            row[key] = None if row[key] is None else base64.b64encode(row[key]).decode("ascii")
        rows.append(row)
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    write_json(path, {"format": SUMMARY_FORMAT, "checks": rows})


def read_worker_part(path: Path) -> list[CheckRecord]:
    """The checks a worker wrote (`write_worker_part`); a part that is not whole and well formed is
    refused in one line (`ImageInputError`), never half used."""
    import binascii
    import json

    try:
        data = json.loads(Path(path).read_text())
        if data.get("format") != SUMMARY_FORMAT:
            raise ValueError(f"format {data.get('format')!r}")
        fields = {f.name for f in dataclasses.fields(CheckRecord)}
        records = []
        for row in data["checks"]:
            if set(row) != fields:
                raise ValueError("a check with other fields")
            for key in _BYTES_FIELDS:
                row[key] = None if row[key] is None else base64.b64decode(row[key], validate=True)
            records.append(CheckRecord(**row))
        return records
    except (OSError, ValueError, KeyError, TypeError, AttributeError, binascii.Error) as exc:
        from orthosim_render.imageerrors import ImageInputError

        raise ImageInputError(path, None, f"a worker's image-check results are damaged ({exc})",
                              "run the session again") from None


def write_results(folder: Path, records: list[CheckRecord]) -> tuple[Path, Path]:
    """DIR/summary.json, then DIR/index.html, each atomically; returns their paths."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    created = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    summary = {"format": SUMMARY_FORMAT, "orthosim_version": __version__, "created": created,
               "failed": sum(r.status == "failed" for r in records),
               "regenerated": sum(r.status == "regenerated" for r in records),
               "new": sum(r.status == "new" for r in records),
               "checks": [r.to_json() for r in records]}
    write_json(folder / "summary.json", summary)
    write_text(folder / "index.html", render_page(records, created))
    return folder / "index.html", folder / "summary.json"
