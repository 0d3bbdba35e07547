"""certificate.json read back and held to its recomputation: what `orthosim stage verify` does with
the figures a certificate claims.

The verifier recomputes the whole certificate from the written stages (`certificate.certify_stages`
on the poses of stages.json, the case's teeth and the recorded IPR) and lays the two records side
by side (`compare`). Every figure the file claims is matched with the recomputed one: numbers within
the `tolerances` the certificate states (clearances to the branch and bound's tolerance, the rest to the
digits they are written with), flags, counts, FDI numbers, stage numbers and the case's SHA-256
exactly; list entries by what they are about (a pair by its two FDI numbers, a tooth by its FDI, a
transition by its stage), so a pair the file leaves out or adds is named too. The tolerances the file
states are themselves held to the verifier's (a widened one is a disagreement). A figure that
disagrees is a `Disagreement` (verify exits 1 naming it); a file whose fields are missing or of the
wrong type is refused in one line (`StagingFolderError`, exit 2).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

from orthosim.staging.stagesfile import StagingFolderError

CERTIFICATE_FILE = "certificate.json"
_NOT_FIGURES = ("case_file",)  # where the case was when staged: `stage verify --case` may name another copy
_ENTRY_KEYS = (("fdi_a", "fdi_b"), ("fdi",), ("stage",))  # what a list's entries are about, tried in order


@dataclass(frozen=True)
class Disagreement:
    """One figure of certificate.json that its recomputation does not confirm."""

    stage: int  # the stage the figure is about (0: the start and the file's own fields; N: the summary)
    figure: str  # where it sits, e.g. transitions[3].clearances[41-42].min_clearance_mm
    claimed: object
    recomputed: object
    tolerance: float = 0.0

    def text(self) -> str:
        within = f" (tolerance {self.tolerance:g})" if self.tolerance else ""
        return f"{CERTIFICATE_FILE}: {self.figure} claims {_show(self.claimed)}, recomputed {_show(self.recomputed)}{within}"


def _show(value) -> str:
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, (dict, list)):
        return "an entry" if value else "none"
    return json.dumps(value)


def read_certificate(folder: str | Path) -> tuple[Path, dict]:
    """(path, content) of the folder's certificate.json; StagingFolderError when it is missing or not a JSON object."""
    path = Path(folder) / CERTIFICATE_FILE
    if not path.is_file():
        raise StagingFolderError(Path(folder), CERTIFICATE_FILE, "is missing: nothing certifies this staging",
                                 "stage the case again: orthosim stage CASE --out DIR")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise StagingFolderError(path, None, f"is unreadable ({err.__class__.__name__})", "stage the case again") from None
    if not isinstance(data, dict):
        raise StagingFolderError(path, None, "is not a JSON object", "stage the case again")
    return path, data


def _kind(value) -> str:
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true or false"
    if isinstance(value, (int, float)):
        return "a number"
    return {str: "a string", list: "a list", dict: "an object"}.get(type(value), type(value).__name__)


def _tolerance(name: str, tolerances: dict) -> float:
    """The tolerance of a figure called `name` (0: exact)."""
    if name in ("min_clearance_mm", "lower_bound_mm"):
        key = "clearance_mm"
    elif name == "at_time":
        key = "time"
    elif name.startswith("ipr"):
        key = "ipr_mm"
    elif name in ("ratio", "largest_ratio"):
        key = "ratio"
    elif name.endswith(("_mm", "_deg")):  # a tooth's increment in a transition
        key = "increment"
    else:
        return 0.0
    return float(tolerances.get(key, 0.0))


def _entry_label(entry, keys) -> str | None:
    if not isinstance(entry, dict) or not all(k in entry for k in keys):
        return None
    return "-".join(str(entry[k]) for k in keys)


def _keyed(items: list) -> tuple[dict, tuple[str, ...]] | None:
    """Entries of a list of objects by what they are about ({label: entry}, the keys used); None for other lists."""
    for keys in _ENTRY_KEYS:
        labels = [_entry_label(e, keys) for e in items]
        if items and all(lab is not None for lab in labels) and len(set(labels)) == len(labels):
            return dict(zip(labels, items)), keys
    return None


class _Walk:
    """Both records walked together: `found` collects the disagreements; a missing field or one of
    another type stops the walk with a StagingFolderError naming it."""

    def __init__(self, path: Path, tolerances: dict, last_stage: int):
        self.path, self.tolerances, self.last_stage = path, tolerances, last_stage
        self.found: list[Disagreement] = []
        self.figures = 0  # leaves compared

    def refuse(self, figure: str, problem: str):
        raise StagingFolderError(self.path, figure, problem, "stage the case again: orthosim stage CASE --out DIR")

    def differ(self, stage: int, figure: str, claimed, recomputed, tolerance: float = 0.0) -> None:
        self.found.append(Disagreement(stage, figure, claimed, recomputed, tolerance))

    def value(self, stage: int, figure: str, name: str, claimed, recomputed) -> None:
        self.figures += not isinstance(recomputed, (dict, list))
        if recomputed is None or claimed is None:
            if (claimed is None) != (recomputed is None):
                self.differ(stage, figure, claimed, recomputed)
            return
        if _kind(claimed) != _kind(recomputed):
            self.refuse(figure, f"must be {_kind(recomputed)}, got {_kind(claimed)}")
        if isinstance(recomputed, dict):
            self.record(stage, figure, claimed, recomputed)
        elif isinstance(recomputed, list):
            self.entries(stage, figure, claimed, recomputed)
        elif _kind(recomputed) == "a number":
            exact = figure.startswith(("tolerances", "limits"))  # the terms of the check themselves
            tol = 0.0 if exact else _tolerance(name, self.tolerances)
            if not math.isfinite(claimed) or abs(claimed - recomputed) > tol + 1e-12 * max(1.0, abs(recomputed)):
                self.differ(stage, figure, claimed, recomputed, tol)
        elif claimed != recomputed:
            self.differ(stage, figure, claimed, recomputed)

    def record(self, stage: int, figure: str, claimed: dict, recomputed: dict) -> None:
        for name, value in recomputed.items():
            where = f"{figure}.{name}" if figure else name
            if name in _NOT_FIGURES:
                continue
            if name not in claimed:
                self.refuse(where, "is missing")
            at = self.last_stage if where.startswith("summary") else stage
            self.value(at, where, name, claimed[name], value)

    def entries(self, stage: int, figure: str, claimed: list, recomputed: list) -> None:
        theirs, ours = _keyed(claimed), _keyed(recomputed)
        if ours is None or theirs is None or theirs[1] != ours[1]:
            if len(claimed) != len(recomputed):
                self.differ(stage, f"{figure} (entries)", len(claimed), len(recomputed))
                return
            for i, (c, r) in enumerate(zip(claimed, recomputed)):
                self.value(stage, f"{figure}[{i}]", figure.rsplit(".", 1)[-1], c, r)
            return
        (by_label, keys), (mine, _) = theirs, ours
        for label, entry in mine.items():
            at = entry["stage"] if keys == ("stage",) else stage
            where = f"{figure}[{label}]"
            if label not in by_label:
                self.differ(at, where, None, entry)
            else:
                self.record(at, where, by_label[label], entry)
        for label in by_label.keys() - mine.keys():
            self.differ(stage, f"{figure}[{label}]", by_label[label], None)


def compare(path: Path, claimed: dict, recomputed: dict) -> tuple[list[Disagreement], int]:
    """(every figure of `claimed`, certificate.json's content read from `path`, that the `recomputed`
    record, `certificate.certificate_record` of the recomputation, does not confirm, in stage order;
    the count of figures compared)."""
    last = len(recomputed.get("transitions", []))
    walk = _Walk(path, recomputed["tolerances"], last)  # the file's own are held to these, exactly
    walk.record(0, "", claimed, recomputed)
    return sorted(walk.found, key=lambda d: d.stage), walk.figures
