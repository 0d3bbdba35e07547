"""Image regression: a candidate render against a golden PNG, exactly or within a tolerance, and where they differ.

Renders are bit-identical on one machine and Mesa build (DEVELOPERS.md), and not across Mesa
builds. So a golden PNG carries a sidecar (`GOLDEN.json`: the offscreen backend, GL renderer string
and Mesa version it was drawn with, its size, camera view, orthosim version, case file hash and
frame index), and the comparison picks its mode from it:
  - exact: the candidate was drawn through the same backend (EGL device kind or OSMesa,
    `orthosim_render.offscreen_backend`), GL renderer and Mesa version as the golden; any pixel that differs
    is a failure (a sidecar written before orthosim drew through EGL names no backend: OSMesa drew it);
  - tolerance: otherwise (or when either side's GL is unknown); a pixel differs when one of its
    channels is off by more than `max_level` levels (default 3), and the images match while at
    most `max_fraction` of the pixels (default 0.1 %) differ. SSIM (scikit-image) is reported
    beside, as a figure for the reader, not as the verdict.
The diff image shows golden | candidate | the differences in a strong colour over a grey copy of
the golden, side by side. `orthosim imgdiff` (the CLI) and the pytest fixture
(`orthosim_render.pytest_plugin`) are both thin layers over `compare_files` / `compare_images`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.storage.atomic import write_bytes, write_json

from orthosim_render.imageerrors import ImageInputError  # defined apart (no import cycle), still imgdiff.ImageInputError
from orthosim_render.png import encode_png

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
DIFF_COLOUR = (255, 0, 220)  # differences beyond tolerance: a magenta no lit tooth or grey can take
WITHIN_COLOUR = (60, 150, 255)  # differences within tolerance (tolerance mode only): a quieter blue
TOLERATED_COLOUR = (235, 200, 40)  # differences left out by label (a tolerated shift, an ignored kind): amber
BOX_MARGIN = 4  # px: the box drawn around all differences, so that a single changed pixel is found


@dataclass(frozen=True)
class Tolerance:
    """Tolerance mode's limits: `max_level` levels (0-255) per channel, `max_fraction` of the pixels (0-1)."""

    max_level: int = 3
    max_fraction: float = 0.001

    def __post_init__(self):
        if not 0 <= self.max_level <= 255:
            raise ImageInputError(None, "--max-level", f"{self.max_level} is not a level from 0 to 255", "give 0 to 255")
        if not (0.0 <= self.max_fraction <= 1.0) or math.isnan(self.max_fraction):
            raise ImageInputError(None, "--max-fraction", f"{self.max_fraction} is not a fraction from 0 to 1",
                                  "give e.g. 0.001 for 0.1 %")


@dataclass(frozen=True)
class GoldenSidecar:
    """What a golden (or candidate) image was drawn with; stored as GOLDEN.json beside GOLDEN.png.

    `frame_index` is the simulation step shown (0 = before treatment), not an animation frame:
    animation frames per step are a rendering option, steps are the case's. `case_file` is the
    file's name only (no machine path); `case_sha256` lets a reader see that the golden was made
    from another version of the case.
    """

    gl_renderer: str | None = None  # GL_RENDERER, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"
    mesa_version: str | None = None  # from GL_VERSION, e.g. "22.3.6"
    gl_backend: str | None = None  # GLBackend.label: "egl/gpu", "egl/software", "egl/default" or "osmesa"
    size: tuple[int, int] | None = None  # (width, height) px
    view: str | None = None  # camera preset (orthosim_render.cameras)
    orthosim_version: str | None = __version__
    case_file: str | None = None
    case_sha256: str | None = None
    frame_index: int | None = None  # simulation step shown

    def to_json(self) -> dict:
        data = dataclasses.asdict(self)
        data["size"] = list(self.size) if self.size is not None else None
        return data

    @classmethod
    def from_json(cls, data, where) -> "GoldenSidecar":
        if not isinstance(data, dict):
            raise ImageInputError(where, None, "is not a JSON object", "rewrite it with orthosim imgdiff --update")
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ImageInputError(where, unknown[0], "is not a sidecar field",
                                  f"remove it; the fields are {', '.join(sorted(names))}")
        for name in ("gl_renderer", "mesa_version", "gl_backend", "view", "orthosim_version", "case_file", "case_sha256"):
            if data.get(name) is not None and not isinstance(data[name], str):
                raise ImageInputError(where, name, f"is {data[name]!r}, not a string or null",
                                      "rewrite it with orthosim imgdiff --update")
        size = data.get("size")
        if size is not None:
            if not (isinstance(size, list) and len(size) == 2 and all(isinstance(v, int) and v > 0 for v in size)):
                raise ImageInputError(where, "size", f"is {size!r}, not [width, height] in pixels",
                                      "rewrite it with orthosim imgdiff --update")
            size = (size[0], size[1])
        frame = data.get("frame_index")
        if frame is not None and (not isinstance(frame, int) or isinstance(frame, bool)):
            raise ImageInputError(where, "frame_index", f"is {frame!r}, not a step number or null",
                                  "rewrite it with orthosim imgdiff --update")
        return cls(**{**{k: data.get(k) for k in names}, "size": size})


def sidecar_path(png: str | Path) -> Path:
    """GOLDEN.png -> GOLDEN.json."""
    return Path(png).with_suffix(".json")


def read_sidecar(png: str | Path) -> GoldenSidecar | None:
    """The sidecar of `png`, or None when it has none; ImageInputError when it is malformed."""
    path = sidecar_path(png)
    if not path.is_file():
        return None
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise ImageInputError(path, None, f"is unreadable ({type(err).__name__}: {err})",
                              "rewrite it with orthosim imgdiff --update, or delete it") from None
    return GoldenSidecar.from_json(data, path)


def read_png(path: str | Path, role: str = "image") -> np.ndarray:
    """(h, w, 3) RGB or (h, w, 4) RGBA uint8 pixels of the PNG at `path`; ImageInputError when unusable.

    Pillow decodes (it checks every chunk's CRC and refuses a truncated stream by default); the
    signature is checked first so that a JPEG or a text file is named as "not a PNG", not as broken.
    """
    from PIL import Image, UnidentifiedImageError

    path = Path(path)
    fix = f"give the path of the {role} PNG"
    if not path.exists():
        raise ImageInputError(path, None, f"{role} not found", fix)
    if not path.is_file():
        raise ImageInputError(path, None, f"{role} is not a file", fix)
    try:
        with path.open("rb") as f:
            head = f.read(len(PNG_SIGNATURE))
    except OSError as err:
        raise ImageInputError(path, None, f"{role} is unreadable ({err.strerror or err})", "check its permissions") from None
    if head != PNG_SIGNATURE:
        what = "is empty" if not head else "is not a PNG (wrong signature)"
        raise ImageInputError(path, None, f"{role} {what}", "give a PNG file")
    try:
        with Image.open(path) as im:
            im.load()
            mode = "RGBA" if ("A" in im.mode or "transparency" in im.info) else "RGB"
            pixels = np.asarray(im.convert(mode))
    except (OSError, SyntaxError, ValueError, zlib.error, UnidentifiedImageError, EOFError) as err:
        problem = "is truncated" if "truncat" in str(err).lower() else f"is damaged ({type(err).__name__}: {err})"
        raise ImageInputError(path, None, f"{role} {problem}",
                              f"restore the {role} (git checkout, or regenerate it)" if role == "golden"
                              else f"render the {role} again") from None
    return np.ascontiguousarray(pixels, dtype=np.uint8)


def write_golden(png: str | Path, image: np.ndarray, sidecar: GoldenSidecar, labels=None) -> None:
    """Write `image` as the golden PNG and its sidecar, each atomically (zlib level 9: goldens are committed).

    `labels`: the image's `orthosim_render.semantic_labels.LabelFrame`, written beside it; None removes any
    label files left from an earlier golden (they would describe other pixels).
    """
    from orthosim_render.semantic_labels import remove_labels, write_labels

    image = np.ascontiguousarray(image, dtype=np.uint8)
    if labels is not None:
        write_labels(png, labels, image)
    else:
        remove_labels(png)
    write_bytes(png, encode_png(image, level=9))
    h, w = image.shape[:2]
    write_json(sidecar_path(png), dataclasses.replace(sidecar, size=(w, h)).to_json())


@dataclass(frozen=True)
class Comparison:
    """The verdict of one comparison and the figures behind it."""

    matched: bool
    mode: str  # "exact" | "tolerance"
    mode_reason: str  # why this mode, e.g. "same llvmpipe ..., Mesa 22.3.6" or "Mesa 22.3.6 vs 23.1.0"
    size: tuple[int, int]  # (width, height) px
    differing_pixels: int  # pixels with any channel different
    beyond_pixels: int  # pixels with a channel off by more than tolerance.max_level
    largest_level: int  # largest per-channel difference seen (0-255)
    ssim: float  # structural similarity, scikit-image, 1.0 = identical
    tolerance: Tolerance
    notes: tuple[str, ...] = ()  # e.g. the golden was made from another version of its case
    masked_pixels: int = 0  # pixels left out by label (tolerated changes, ignored kinds); counted in none of the above

    @property
    def pixels(self) -> int:
        """The pixels compared: the image's, less those left out by label."""
        return self.size[0] * self.size[1] - self.masked_pixels

    @property
    def failing_pixels(self) -> int:
        """The pixels the verdict counts: every differing pixel in exact mode, those beyond tolerance otherwise."""
        return self.differing_pixels if self.mode == "exact" else self.beyond_pixels

    def summary(self) -> str:
        """One line: verdict, mode and why, the figures."""
        if self.mode == "exact":
            figures = (f"{self.differing_pixels} of {self.pixels} pixels differ "
                       f"({100 * self.differing_pixels / self.pixels:.3f} %)")
        else:
            figures = (f"{self.beyond_pixels} of {self.pixels} pixels beyond {self.tolerance.max_level} levels "
                       f"({100 * self.beyond_pixels / self.pixels:.3f} %, limit {100 * self.tolerance.max_fraction:.3f} %)")
        text = (f"{'match' if self.matched else 'differ'} ({self.mode}: {self.mode_reason}): {figures}, "
                f"largest difference {self.largest_level} level{'' if self.largest_level == 1 else 's'}, SSIM {self.ssim:.4f}")
        masked = [f"{self.masked_pixels} pixels left out by label"] if self.masked_pixels else []
        return "; ".join([text, *masked, *self.notes])


LEGACY_BACKEND = "osmesa"  # what drew a sidecar that names a GL renderer but no backend (orthosim drew only through OSMesa then)


def _backend(sidecar: GoldenSidecar) -> str:
    return sidecar.gl_backend or LEGACY_BACKEND


def choose_mode(golden: GoldenSidecar | None, candidate: GoldenSidecar | None) -> tuple[str, str]:
    """("exact" | "tolerance", why): exact only when backend, GL renderer and Mesa version are known and equal."""
    if golden is None:
        return "tolerance", "the golden has no sidecar"
    if not golden.gl_renderer or not golden.mesa_version:
        return "tolerance", "the golden's sidecar names no GL renderer and Mesa version"
    if candidate is None or not candidate.gl_renderer or not candidate.mesa_version:
        return "tolerance", "the candidate's GL renderer is unknown"
    if candidate.mesa_version != golden.mesa_version:
        return "tolerance", f"Mesa {golden.mesa_version} vs {candidate.mesa_version}"
    if candidate.gl_renderer != golden.gl_renderer:
        return "tolerance", f"GL renderer {golden.gl_renderer!r} vs {candidate.gl_renderer!r}"
    if _backend(candidate) != _backend(golden):
        return "tolerance", f"backend {_backend(golden)} vs {_backend(candidate)}"
    return "exact", f"same {golden.gl_renderer}, Mesa {golden.mesa_version}, through {_backend(golden)}"


def _same_channels(golden: np.ndarray, candidate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Both RGB, or both RGBA when either has alpha (an opaque side gets alpha 255)."""
    def channels(im):
        im = np.asarray(im)
        return im[:, :, None].repeat(3, axis=2) if im.ndim == 2 else im

    golden, candidate = channels(golden), channels(candidate)
    if golden.shape[2] != candidate.shape[2]:
        golden, candidate = (np.dstack([im, np.full(im.shape[:2], 255, np.uint8)]) if im.shape[2] == 3 else im
                             for im in (golden, candidate))
    return golden, candidate


def _ssim(golden: np.ndarray, candidate: np.ndarray) -> float:
    if np.array_equal(golden, candidate):
        return 1.0
    from skimage.metrics import structural_similarity

    win = min(7, *golden.shape[:2])
    win -= 1 - win % 2  # odd, as scikit-image requires
    if win < 3:
        return float("nan")  # too small an image for a structural measure
    return float(structural_similarity(golden, candidate, channel_axis=2, data_range=255, win_size=win))


def compare_images(golden: np.ndarray, candidate: np.ndarray, golden_sidecar: GoldenSidecar | None = None,
                   candidate_sidecar: GoldenSidecar | None = None, tolerance: Tolerance = Tolerance(),
                   names: tuple[str, str] = ("golden", "candidate"), mask: np.ndarray | None = None) -> Comparison:
    """Compare two (h, w, 3|4) uint8 images; the mode comes from the sidecars (see `choose_mode`).

    ImageInputError when the sizes differ. `names` name the two images in that message. `mask`:
    None, or (h, w) bool, True where a pixel is left out (a tolerated change, found by label; see
    `orthosim_render.explain`); the verdict and every figure count the other pixels only.
    """
    golden, candidate = _same_channels(golden, candidate)
    if golden.shape[:2] != candidate.shape[:2]:
        gh, gw = golden.shape[:2]
        ch, cw = candidate.shape[:2]
        raise ImageInputError(names[1], None, f"is {cw}x{ch} pixels but the golden {names[0]} is {gw}x{gh}",
                              f"render the candidate at {gw}x{gh}, or replace the golden with --update")
    mode, reason = choose_mode(golden_sidecar, candidate_sidecar)
    level = np.abs(golden.astype(np.int16) - candidate.astype(np.int16)).max(axis=2)
    h, w = level.shape
    masked = 0
    if mask is not None:
        mask = np.asarray(mask, bool)
        masked = int(mask.sum())
        level = np.where(mask, 0, level)
    differing = int(np.count_nonzero(level))
    beyond = int(np.count_nonzero(level > tolerance.max_level))
    if mode == "exact":
        matched = differing == 0
    else:
        matched = beyond <= tolerance.max_fraction * (h * w - masked)
    notes = []
    if (golden_sidecar is not None and candidate_sidecar is not None and golden_sidecar.case_sha256
            and candidate_sidecar.case_sha256 and golden_sidecar.case_sha256 != candidate_sidecar.case_sha256):
        notes.append(f"the golden was made from another version of {golden_sidecar.case_file or 'its case file'} "
                     f"(sha256 {golden_sidecar.case_sha256[:12]} vs {candidate_sidecar.case_sha256[:12]} now)")
    return Comparison(matched, mode, reason, (w, h), differing, beyond, int(level.max(initial=0)),
                      _ssim(golden, candidate), tolerance, tuple(notes), masked)


def compare_labelled(golden: np.ndarray, candidate: np.ndarray, golden_sidecar: GoldenSidecar | None,
                     candidate_sidecar: GoldenSidecar | None, tolerance: Tolerance, names: tuple[str, str],
                     golden_labels=None, candidate_labels=None, ignore=(), max_shift_px=0.0):
    """`compare_images`, plus what changed when both images carry labels: (Comparison, Explanation or
    None, the mask of pixels left out or None).

    `ignore` (kinds such as "gingiva" or "contact", FDI numbers, "tooth 13", "contact 13-14") and
    `max_shift_px` (px: a thing that only moved this far is tolerated; or a mapping such as
    {"contact": 2, 13: 1}, see `Explanation.tolerated_mask`) leave those things' pixels out of
    the verdict; they need labels on both sides, and without them every pixel is compared (a note
    says so).
    """
    from orthosim_render.explain import check_tolerances

    ignore = check_tolerances(ignore, max_shift_px)
    explanation = mask = None
    asked = bool(ignore) or bool(max_shift_px)
    same_size = np.shape(golden)[:2] == np.shape(candidate)[:2]
    notes = ()
    if golden_labels is not None and candidate_labels is not None and golden_labels.camera != candidate_labels.camera:
        notes = (f"the labels were drawn from other cameras ({golden_labels.camera.view} vs "
                 f"{candidate_labels.camera.view}), so only pixels were compared",)
        golden_labels = candidate_labels = None
    if golden_labels is not None and candidate_labels is not None and same_size:
        g3, c3 = _same_channels(golden, candidate)
        if not np.array_equal(g3, c3):
            from orthosim_render.explain import explain

            explanation = explain(g3, golden_labels, c3, candidate_labels, tolerance.max_level)
            if asked:
                mask = explanation.tolerated_mask(np.shape(golden)[:2], ignore, max_shift_px)
    comparison = compare_images(golden, candidate, golden_sidecar, candidate_sidecar, tolerance, names, mask)
    comparison = dataclasses.replace(comparison, notes=comparison.notes + notes) if notes else comparison
    if asked and (golden_labels is None or candidate_labels is None):
        side = names[0] if golden_labels is None else names[1]
        comparison = dataclasses.replace(comparison, notes=comparison.notes + (
            f"{side} has no labels, so ignore/max_shift_px could not apply: every pixel was compared",))
    return comparison, explanation, mask


def diff_image(golden: np.ndarray, candidate: np.ndarray, comparison: Comparison,
               mask: np.ndarray | None = None) -> np.ndarray:
    """(h, 3w, 3) uint8: golden | candidate | differences over a grey copy of the golden.

    Pixels that count against the verdict are DIFF_COLOUR, with a box of the same colour around
    all of them (a one-pixel difference is otherwise hard to find); in tolerance mode, pixels that
    differ within tolerance are WITHIN_COLOUR; pixels that differ but were left out by `mask` (see
    `compare_images`) are TOLERATED_COLOUR.
    """
    golden, candidate = _same_channels(golden, candidate)
    level = np.abs(golden.astype(np.int16) - candidate.astype(np.int16)).max(axis=2)
    tolerated = np.zeros(level.shape, bool)
    if mask is not None:
        tolerated = np.asarray(mask, bool) & (level > 0)
        level = np.where(mask, 0, level)
    rgb_g, rgb_c = golden[:, :, :3], candidate[:, :, :3]
    luminance = rgb_g.astype(np.float32) @ np.array([0.299, 0.587, 0.114], np.float32)
    grey = (60 + 0.45 * luminance).astype(np.uint8)  # dimmed, so that the colours stand out
    panel = np.repeat(grey[:, :, None], 3, axis=2)
    failing = level > 0 if comparison.mode == "exact" else level > comparison.tolerance.max_level
    if comparison.mode != "exact":
        panel[(level > 0) & ~failing] = WITHIN_COLOUR
    panel[tolerated] = TOLERATED_COLOUR
    panel[failing] = DIFF_COLOUR
    if failing.any():
        rows, cols = np.nonzero(failing)
        h, w = failing.shape
        r0, r1 = max(rows.min() - BOX_MARGIN, 0), min(rows.max() + BOX_MARGIN, h - 1)
        c0, c1 = max(cols.min() - BOX_MARGIN, 0), min(cols.max() + BOX_MARGIN, w - 1)
        panel[[r0, r1], c0:c1 + 1] = DIFF_COLOUR
        panel[r0:r1 + 1, [c0, c1]] = DIFF_COLOUR
    return np.concatenate([rgb_g, rgb_c, panel], axis=1)


def write_diff_image(path: str | Path, golden: np.ndarray, candidate: np.ndarray, comparison: Comparison,
                     mask: np.ndarray | None = None) -> Path:
    write_bytes(path, encode_png(diff_image(golden, candidate, comparison, mask)))
    return Path(path)


def default_diff_path(candidate: str | Path) -> Path:
    """CANDIDATE.png -> CANDIDATE.diff.png, beside the candidate."""
    candidate = Path(candidate)
    return candidate.with_name(candidate.stem + ".diff.png")


@dataclass(frozen=True)
class ImgdiffOutcome:
    """What `orthosim imgdiff` did: exit code (0 match / 1 differ), its one line, the diff image written."""

    exit_code: int
    line: str
    comparison: Comparison | None
    diff_path: Path | None
    explanation: object | None = None  # orthosim_render.explain.Explanation when both images carry labels

    @property
    def lines(self) -> list[str]:
        """What the command prints: the verdict line, then what changed when the labels can say."""
        return [self.line] + ([f"what changed: {self.explanation.text()}"] if self.explanation is not None else [])


def imgdiff(golden_path: str | Path, candidate_path: str | Path, *, diff_path: str | Path | None = None,
            tolerance: Tolerance = Tolerance(), update: bool = False,
            this_machine=None, ignore=(), max_shift_px: float = 0.0) -> ImgdiffOutcome:
    """The `orthosim imgdiff` command without the command line (unusable input: ImageInputError).

    The candidate's GL renderer and Mesa version come from its own sidecar (CANDIDATE.json) when it
    has one; otherwise from `this_machine()` (a `GoldenSidecar` or None, called only then), since
    a candidate without a sidecar was normally just rendered here. The diff image is written to
    `diff_path` when given, else beside the candidate when the images differ. `update` makes the
    candidate the golden (PNG, sidecar and labels), reporting what the comparison found first.
    When both images carry labels (`orthosim_render.semantic_labels`) and differ, the outcome also says what
    changed, thing by thing (`orthosim_render.explain`), and DIFF.json beside the diff image holds the
    same; a label file that is damaged or belongs to other pixels is refused (ImageInputError), never
    half-used.
    """
    from orthosim_render.semantic_labels import read_labels

    golden_path, candidate_path = Path(golden_path), Path(candidate_path)
    candidate = read_png(candidate_path, "candidate")
    candidate_sidecar = read_sidecar(candidate_path)
    candidate_labels = read_labels(candidate_path, candidate)

    def candidate_gl() -> GoldenSidecar | None:
        # asked only when it can matter: starting a GL context to ask takes seconds
        return candidate_sidecar or (this_machine() if this_machine is not None else None)

    if update and not golden_path.exists():
        write_golden(golden_path, candidate, candidate_gl() or GoldenSidecar(), candidate_labels)
        return ImgdiffOutcome(0, f"created golden {golden_path} and {sidecar_path(golden_path)} from {candidate_path}",
                              None, None)
    try:
        golden = read_png(golden_path, "golden")
        golden_sidecar = read_sidecar(golden_path)
        golden_labels = read_labels(golden_path, golden)
        known = golden_sidecar is not None and golden_sidecar.gl_renderer and golden_sidecar.mesa_version
        comparison, explanation, mask = compare_labelled(
            golden, candidate, golden_sidecar, candidate_gl() if known or update else candidate_sidecar, tolerance,
            (str(golden_path), str(candidate_path)), golden_labels, candidate_labels, ignore, max_shift_px)
    except ImageInputError as err:
        if not update:
            raise
        write_golden(golden_path, candidate, candidate_gl() or GoldenSidecar(), candidate_labels)
        return ImgdiffOutcome(0, f"updated golden {golden_path} and {sidecar_path(golden_path)} from {candidate_path} "
                                 f"(the old one was unusable: {err.problem})", None, None)
    written = None
    if diff_path is not None or not comparison.matched:
        written = write_diff_image(diff_path or default_diff_path(candidate_path), golden, candidate, comparison, mask)
        if explanation is not None:  # what changed, for a machine, beside the diff image (DIFF.json)
            write_json(written.with_suffix(".json"), {"summary": comparison.summary(), **explanation.to_json()})
    line = comparison.summary() + (f" -> {written}" if written else "")
    if update:
        write_golden(golden_path, candidate, candidate_gl() or GoldenSidecar(), candidate_labels)
        return ImgdiffOutcome(0, f"updated golden {golden_path} and {sidecar_path(golden_path)} from {candidate_path} "
                                 f"(it was: {line})", comparison, written, explanation)
    return ImgdiffOutcome(0 if comparison.matched else 1, line, comparison, written, explanation)
