"""What changed between a golden and a candidate render, said tooth by tooth and contact by contact.

Both images carry their `LabelFrame` (orthosim_render.semantic_labels: what each pixel shows, and its
depth). For everything either frame shows (a tooth, the contact patch between two teeth, ...):
  - moved: the shift (column, row) that lays its pixels in the golden onto those in the candidate,
    first to the pixel by cross-correlating the two masks, then below a pixel by matching the two
    depth fields over the pixels it shows in both (Gauss-Newton on shift and depth offset: a curved
    crown's depth pins the shift down in both directions). Pixels become mm in the view plane
    through the pixel size at the thing's depth; the direction is put in dental terms from the
    tooth's axes as the golden's camera saw them, where the view shows them (an axis pointing at
    the camera has no direction in the image);
  - appeared, disappeared, changed shape: pixels it gained or lost that no occlusion explains. A
    pixel a tooth lost because something now lies in front of it (smaller depth), or gained
    because what lay in front has gone, is the other thing's change, not its own, so a moved
    tooth never makes its neighbours "change";
  - changed colour only: same pixels and depth, other colours (the moving tint, painted contacts);
  - a contact patch appeared, vanished, moved, grew or shrank (its visible area, in %).
`Explanation.text()` is one line, e.g. `tooth 13 moved 2.1 px (0.40 mm) distally; contact 13-14
gone; 27 other teeth unchanged`; `Explanation.tolerated_mask` turns per-label tolerances (ignore
these kinds or teeth, allow shifts up to N px) into the pixels a comparison may leave out.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from orthosim_render.semantic_labels import LabelEntry, LabelFrame, dental_terms

DEPTH_EPS_MM = 0.05  # depths closer than this are the same surface (24-bit depth, another Mesa build)
MIN_CHANGED_PX = 4  # fewer unexplained pixels than this (and than 1 % of the thing) are edge noise
MIN_SHIFT_PX = 0.25  # a smaller shift is rasterisation noise, not a move
MIN_DEPTH_SHIFT_MM = 0.05
SEARCH_PX = 48  # largest shift looked for, px
AREA_CHANGE = 0.10  # a contact patch grew or shrank when its visible area changed by more (fraction)
WAS_COLOUR, NOW_COLOUR, BOTH_COLOUR = (40, 170, 255), (255, 140, 0), (200, 200, 200)  # `Explanation.picture`
MIN_AXIS_FRACTION = 0.35  # a dental direction is named when the move along it is at least this share of the largest


@dataclass(frozen=True)
class Change:
    """One thing that changed. `shift_px` (column, row) and `shift_mm` (view plane) for a move;
    `depth_mm`: its move along the view axis (+ away from the camera); `area_px` (golden, candidate)."""

    subject: str  # "tooth 13", "contact 13-14", "gingiva", "background"
    key: tuple
    kind: str  # "moved" | "appeared" | "disappeared" | "changed shape" | "changed colour" | "grew" | "shrank"
    shift_px: tuple[float, float] | None = None
    shift_mm: float | None = None
    depth_mm: float | None = None
    direction: str | None = None  # e.g. "distally", "mesially and occlusally"; None where the view cannot say
    area_px: tuple[int, int] = (0, 0)

    @property
    def shift_length_px(self) -> float:
        return float(np.hypot(*self.shift_px)) if self.shift_px is not None else 0.0

    def text(self) -> str:
        if self.kind == "moved":
            words = f"{self.subject} moved {self.shift_length_px:.1f} px ({self.shift_mm:.2f} mm)"
            if self.direction:
                words += f" {self.direction}"
            if self.depth_mm is not None and abs(self.depth_mm) >= MIN_DEPTH_SHIFT_MM:
                words += f", {abs(self.depth_mm):.2f} mm {'away from' if self.depth_mm > 0 else 'toward'} the camera"
            return words
        if self.kind in ("grew", "shrank"):
            g, c = self.area_px
            return f"{self.subject} {self.kind} {abs(c - g) / max(g, 1) * 100:.0f} % ({g} -> {c} px)"
        if self.key[0] == "contact" and self.kind == "disappeared":
            return f"{self.subject} gone"
        return f"{self.subject} {self.kind}"

    def to_json(self) -> dict:
        return {"subject": self.subject, "kind": self.kind, "text": self.text(),
                "shift_px": list(self.shift_px) if self.shift_px is not None else None,
                "shift_length_px": round(self.shift_length_px, 3), "shift_mm": self.shift_mm,
                "depth_mm": self.depth_mm, "direction": self.direction, "area_px": list(self.area_px)}


@dataclass(frozen=True)
class Explanation:
    """Every change found, and how many teeth and contacts did not change."""

    changes: tuple[Change, ...]
    unchanged_teeth: int
    unchanged_contacts: int
    masks: dict = field(default_factory=dict, repr=False, compare=False)  # key -> ((h, w) bool golden, candidate)

    def text(self) -> str:
        parts = [c.text() for c in self.changes]
        teeth = f"{self.unchanged_teeth} {'other ' if self.changes else ''}teeth"
        rest = f"{teeth} and {self.unchanged_contacts} contacts" if self.unchanged_contacts else teeth
        parts.append(f"{rest} unchanged")
        return "; ".join(parts)

    def to_json(self) -> dict:
        return {"text": self.text(), "changes": [c.to_json() for c in self.changes],
                "unchanged_teeth": self.unchanged_teeth, "unchanged_contacts": self.unchanged_contacts}

    def tolerated_mask(self, shape: tuple[int, int], ignore=(), max_shift_px=0.0) -> np.ndarray:
        """(h, w) bool: the pixels a comparison may leave out under these tolerances.

        `ignore`: kinds ("tooth", "contact", "marker", "gingiva", "background") and teeth (FDI numbers,
        or "tooth 13", "contact 13-14") whose pixels, in either image, are left out; `max_shift_px`: a
        thing that only moved, by at most this many pixels, is left out too; a mapping gives each
        kind or tooth its own limit (e.g. {"contact": 2, 13: 1}; the first entry naming a thing counts,
        things it does not name get 0).
        """
        mask = np.zeros(shape, bool)
        for key, (in_golden, in_candidate) in self.masks.items():
            if matches(key, ignore):
                mask |= in_golden | in_candidate
        for change in self.changes:
            if _tolerated_move(change, max_shift_px) and change.key in self.masks:
                mask |= self.masks[change.key][0] | self.masks[change.key][1]
        return mask

    def picture(self, golden_image: np.ndarray) -> np.ndarray:
        """(h, w, 3) uint8: the golden, greyed, with each changed thing where it was (WAS_COLOUR) and
        where it is now (NOW_COLOUR; both where it overlaps itself), for a reader to see what the text says."""
        rgb = np.asarray(golden_image)[..., :3].astype(np.float32)
        grey = (60 + 0.45 * (rgb @ np.array([0.299, 0.587, 0.114], np.float32))).astype(np.uint8)
        out = np.repeat(grey[:, :, None], 3, axis=2)
        for change in self.changes:
            if change.key not in self.masks or change.key == ("background",):
                continue
            was, now = self.masks[change.key]
            out[was & ~now] = WAS_COLOUR
            out[now & ~was] = NOW_COLOUR
            out[was & now] = BOTH_COLOUR
        return out

    def untolerated(self, ignore=(), max_shift_px=0.0) -> tuple[Change, ...]:
        """The changes these tolerances do not allow."""
        return tuple(c for c in self.changes if not matches(c.key, ignore)
                     and not _tolerated_move(c, max_shift_px))


def _tolerated_move(change: Change, max_shift_px) -> bool:
    """Whether `change` is a move within its limit (a number, or a mapping label -> px; see tolerated_mask)."""
    if change.kind != "moved":
        return False
    if isinstance(max_shift_px, dict):
        limit = next((px for name, px in max_shift_px.items() if matches(change.key, (name,))), 0.0)
    else:
        limit = max_shift_px
    return change.shift_length_px <= limit


def check_tolerances(ignore, max_shift_px) -> tuple:
    """`ignore` as a tuple, each entry checked (a kind, an FDI number, "tooth 13", "contact 13-14"), and
    `max_shift_px` (px, or a mapping of such entries to px) checked; a one-line ImageInputError names
    the first that is neither."""
    import re

    from orthosim.model.fdi import is_fdi

    from orthosim_render.imageerrors import ImageInputError
    from orthosim_render.semantic_labels import KINDS

    if isinstance(ignore, (str, int)):
        ignore = (ignore,)
    limits = max_shift_px if isinstance(max_shift_px, dict) else {}
    for item in (*ignore, *limits):
        ok = (is_fdi(item) if isinstance(item, int) and not isinstance(item, bool) else
              isinstance(item, str) and (item in KINDS or item == "background" or re.fullmatch(r"tooth \d\d", item)
                                         or re.fullmatch(r"contact \d\d-\d\d", item)))
        if not ok:
            raise ImageInputError(None, "ignore", f"{item!r} names no label",
                                  "give a kind (tooth, contact, marker, gingiva, background), an FDI number such as 13, "
                                  "'tooth 13' or 'contact 13-14'")
    for value in limits.values() if limits else (max_shift_px,):
        if not (isinstance(value, (int, float)) and not isinstance(value, bool) and 0 <= value < float("inf")):
            raise ImageInputError(None, "max_shift_px", f"{value!r} is not a number of pixels >= 0",
                                  "give e.g. 1, or {'contact': 2, 13: 1}")
    return tuple(ignore)


def matches(key: tuple, ignore) -> bool:
    """Whether `key` (("tooth", 13), ("contact", 13, 14), ...) is named by an entry of `ignore`."""
    for item in ignore:
        if isinstance(item, int) and not isinstance(item, bool):
            if key[0] == "tooth" and key[1] == item:
                return True
        elif item == key[0] or item == _subject(key):
            return True
    return False


def _subject(key: tuple) -> str:
    if key[0] == "tooth":
        return f"tooth {key[1]}"
    if key[0] == "contact":
        return f"contact {key[1]}-{key[2]}"
    return key[0]


# ----------------------------------------------------------------------------------- the shift
def _integer_shift(mg: np.ndarray, mc: np.ndarray) -> tuple[int, int]:
    """(column, row) shift, whole pixels, maximising the overlap of mask `mg` moved onto `mc`."""
    from scipy.signal import fftconvolve

    rows, cols = np.nonzero(mg | mc)
    pad = SEARCH_PX
    r0, r1 = max(rows.min() - pad, 0), rows.max() + pad + 1
    c0, c1 = max(cols.min() - pad, 0), cols.max() + pad + 1
    g, c = mg[r0:r1, c0:c1].astype(np.float32), mc[r0:r1, c0:c1].astype(np.float32)
    corr = fftconvolve(c, g[::-1, ::-1], mode="full")  # corr[i, j]: overlap at shift (i - h + 1, j - w + 1)
    h, w = g.shape
    dy = np.arange(corr.shape[0]) - (h - 1)
    dx = np.arange(corr.shape[1]) - (w - 1)
    corr[np.abs(dy) > SEARCH_PX, :] = -1
    corr[:, np.abs(dx) > SEARCH_PX] = -1
    best = np.argwhere(corr >= corr.max() - 0.5)
    # ties: the smallest shift (a thing that did not move overlaps itself as well as anything)
    i, j = min(best, key=lambda ij: (dy[ij[0]] ** 2 + dx[ij[1]] ** 2, ij[0], ij[1]))
    return int(dx[j]), int(dy[i])


def _interior(mask: np.ndarray) -> np.ndarray:
    """The pixels two rings inside the silhouette: their depth is the thing's own surface, and so is
    that of every neighbour the depth gradient reads."""
    from scipy.ndimage import binary_erosion

    return binary_erosion(mask, iterations=2)


def _refine_shift(start: tuple[int, int], golden: LabelFrame, candidate: LabelFrame, mg, mc) -> tuple[np.ndarray, float]:
    """((column, row) shift, depth offset mm) below a pixel: candidate depth at p + shift = golden depth at p + offset."""
    from scipy.ndimage import map_coordinates

    inner_g, inner_c = _interior(mg), _interior(mc)
    rows, cols = np.nonzero(inner_g)
    zg = golden.depth_mm[rows, cols].astype(np.float64)
    # the gradient at an interior pixel reads only its neighbours, which are the thing's own pixels
    zc = np.where(mc, candidate.depth_mm, 0.0).astype(np.float64)
    grad_r, grad_c = np.gradient(zc)
    if not len(zg) or not inner_c.any():
        return np.array(start, float), 0.0
    shift, offset = np.array(start, float), float(np.median(zc[inner_c]) - np.median(zg))
    for _ in range(12):
        at = np.stack([rows + shift[1], cols + shift[0]])
        ok = map_coordinates(inner_c.astype(np.float32), at, order=1, mode="constant") > 0.999
        if ok.sum() < 12:
            break
        z = map_coordinates(zc, at[:, ok], order=1)
        J = np.stack([map_coordinates(grad_c, at[:, ok], order=1), map_coordinates(grad_r, at[:, ok], order=1),
                      -np.ones(ok.sum())], axis=1)
        residual = z - zg[ok] - offset
        step, *_ = np.linalg.lstsq(J, -residual, rcond=None)
        step[:2] = np.clip(step[:2], -1.0, 1.0)  # stay in the basin the whole-pixel search found
        shift += step[:2]
        offset += step[2]
        if np.abs(step[:2]).max() < 1e-3:
            break
    if np.abs(shift - np.array(start, float)).max() > 1.5 or not np.isfinite(shift).all():
        return np.array(start, float), 0.0  # the depth field did not pin it down: keep the whole pixels
    return shift, offset


def _direction(entry: LabelEntry | None, move_mm: np.ndarray) -> str | None:
    """The move ((3,) mm, camera frame) in dental terms, from the tooth's axes as its frame stored them:
    each axis along which it moved at least MIN_AXIS_FRACTION of its largest component."""
    if entry is None or entry.kind != "tooth" or entry.mesial is None:
        return None
    names = ("mesial", "occlusal", "facial")
    amounts = np.array([np.dot(move_mm, getattr(entry, name)) for name in names])
    terms = dental_terms(entry.teeth[0])
    largest = np.abs(amounts).max()
    order = np.argsort(-np.abs(amounts))
    words = [terms[names[i]][0 if amounts[i] > 0 else 1] for i in order
             if abs(amounts[i]) >= MIN_AXIS_FRACTION * largest and abs(amounts[i]) >= MIN_DEPTH_SHIFT_MM]
    return " and ".join(words) or None


# ------------------------------------------------------------------------------------- changes
def _unexplained(golden: LabelFrame, candidate: LabelFrame, mg, mc) -> tuple[int, int]:
    """(pixels gained, pixels lost) that no occlusion accounts for, plus depth changes where shown in both."""
    zg, zc = golden.depth_mm, candidate.depth_mm
    with np.errstate(invalid="ignore"):
        lost = mg & ~mc & ~(zc < zg - DEPTH_EPS_MM)  # not hidden by something now in front
        gained = mc & ~mg & ~(zg < zc - DEPTH_EPS_MM)  # not revealed by something gone from in front
        moved_surface = mg & mc & (np.abs(zc - zg) > DEPTH_EPS_MM)
    return int(gained.sum() + moved_surface.sum()), int(lost.sum() + moved_surface.sum())


def _significant(count: int, area: int) -> bool:
    return count >= MIN_CHANGED_PX and count >= 0.01 * area


def _explain_one(key, golden, candidate, g_image, c_image, colour_level) -> Change | None:
    gk, ck = golden.by_key().get(key), candidate.by_key().get(key)
    mg, mc = golden.mask(key), candidate.mask(key)
    ng, nc = int(mg.sum()), int(mc.sum())
    subject = _subject(key)
    gained, lost = _unexplained(golden, candidate, mg, mc)
    if ng == 0 or nc == 0:
        if _significant(gained if ng == 0 else lost, max(ng, nc)):
            return Change(subject, key, "appeared" if ng == 0 else "disappeared", area_px=(ng, nc))
        return None
    if key[0] == "contact" and gk is not None and ck is not None and gk.center_mm and ck.center_mm:
        return _contact_change(subject, key, golden, gk, ck, (ng, nc), gained + lost)
    shift, offset = _refine_shift(_integer_shift(mg, mc), golden, candidate, mg, mc)
    if np.hypot(*shift) >= MIN_SHIFT_PX or (abs(offset) >= MIN_DEPTH_SHIFT_MM and _significant(gained + lost, ng)):
        rows, cols = np.nonzero(mg)
        move = golden.camera.displacement_mm((cols.mean(), rows.mean()), float(np.nanmedian(golden.depth_mm[mg])),
                                             shift, offset)
        return Change(subject, key, "moved", (round(float(shift[0]), 3), round(float(shift[1]), 3)),
                      round(float(np.hypot(*move[:2])), 3), round(float(move[2]), 3), _direction(gk or ck, move), (ng, nc))
    if _significant(gained + lost, max(ng, nc)):
        if key[0] == "contact" and abs(nc - ng) > AREA_CHANGE * ng:
            return Change(subject, key, "grew" if nc > ng else "shrank", area_px=(ng, nc))
        return Change(subject, key, "changed shape", area_px=(ng, nc))
    both = mg & mc
    level = np.abs(g_image[..., :3].astype(np.int16) - c_image[..., :3].astype(np.int16)).max(axis=-1)
    if _significant(int((level[both] > colour_level).sum()), ng):
        return Change(subject, key, "changed colour", area_px=(ng, nc))
    return None


def _contact_change(subject, key, golden: LabelFrame, gk: LabelEntry, ck: LabelEntry, area, unexplained) -> Change | None:
    """A contact patch in both images: moved (its spheres' mean centre, when their number is the
    same), else grew or shrank (its visible area), else its visible pixels changed shape."""
    ng, nc = area
    a, b = np.asarray(gk.center_mm), np.asarray(ck.center_mm)
    move = b - a
    if gk.spheres == ck.spheres and np.linalg.norm(move) >= MIN_DEPTH_SHIFT_MM:
        shift = golden.camera.pixel_of(b) - golden.camera.pixel_of(a)
        if np.hypot(*shift) >= MIN_SHIFT_PX or abs(move[2]) >= MIN_DEPTH_SHIFT_MM:
            return Change(subject, key, "moved", (round(float(shift[0]), 3), round(float(shift[1]), 3)),
                          round(float(np.hypot(*move[:2])), 3), round(float(move[2]), 3), None, area)
    if abs(nc - ng) > AREA_CHANGE * max(ng, 1) and _significant(unexplained, max(ng, nc)):
        return Change(subject, key, "grew" if nc > ng else "shrank", area_px=area)
    if gk.spheres != ck.spheres or _significant(unexplained, max(ng, nc)):
        return Change(subject, key, "changed shape", area_px=area)
    return None


def explain(golden_image: np.ndarray, golden: LabelFrame, candidate_image: np.ndarray, candidate: LabelFrame,
            colour_level: int = 3) -> Explanation:
    """What changed from the golden to the candidate, thing by thing (see the module text).

    Images: (h, w, 3|4) uint8, the same size as their label frames; `colour_level`: a channel
    difference up to this many levels is no change of colour.
    """
    keys = sorted(set(golden.by_key()) | set(candidate.by_key()), key=lambda k: (k[0] != "tooth", k))
    changes, masks = [], {}
    unchanged = {"tooth": 0, "contact": 0}
    for key in keys:
        masks[key] = (golden.mask(key), candidate.mask(key))
        change = _explain_one(key, golden, candidate, golden_image, candidate_image, colour_level)
        if change is not None:
            changes.append(change)
        elif key[0] in unchanged:
            unchanged[key[0]] += 1
    empty = (golden.labels == 0) & (candidate.labels == 0)
    masks[("background",)] = (empty, empty)
    level = np.abs(golden_image[..., :3].astype(np.int16) - candidate_image[..., :3].astype(np.int16)).max(axis=-1)
    if _significant(int((level[empty] > colour_level).sum()), int(empty.sum())):
        changes.append(Change("background", ("background",), "changed colour", area_px=(int(empty.sum()),) * 2))
    return Explanation(tuple(changes), unchanged["tooth"], unchanged["contact"], masks)
