"""stages.json read back from disk and checked before use: what `orthosim stage verify` and the
staging page rebuild a staging from, without the planner.

Everything in the file is checked: its version, the limits (positive finite numbers), the teeth
(FDI numbers, each once), the stage numbering (0..N, consecutive), every pose (a finite 4x4
rigid transform: orthonormal rotation within `ROTATION_ATOL`, last row 0 0 0 1, mm), the
progress values and the IPR records (neighbours of the staging, amount in 0..MAX_IPR_MM, unit
direction). A file that fails any check is refused in one line (`StagingFolderError`, exit 2).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from orthosim import __version__
from orthosim.errors import OrthosimError
from orthosim.model import fdi as F
from orthosim.staging.ipr import MAX_IPR_MM, InterproximalReduction
from orthosim.staging.limits import StageLimits
from orthosim.exchange.target import COMPONENTS, UNITS

STAGES_FILE = "stages.json"
ROTATION_ATOL = 1e-6  # |R R^T - I| allowed in a written pose (JSON keeps 17 digits; this is slack)


class StagingFolderError(OrthosimError):
    """A staging folder that is missing, damaged, or does not belong to the case it names."""


@dataclass(frozen=True, eq=False)
class WrittenStaging:
    """A staging as stages.json holds it."""

    path: Path  # the stages.json read
    case_file: Path | None  # the case it names
    case_sha256: str | None  # of the case file when staged (None in files from before it was kept)
    limits: StageLimits
    teeth: tuple[int, ...]  # FDI
    poses: tuple[dict[int, np.ndarray], ...]  # per stage 0..N: FDI -> (4, 4) local -> arch frame, mm
    progress: np.ndarray  # (N + 1, teeth) fraction of each tooth's path, 0..1
    ipr: tuple[InterproximalReduction, ...]

    @property
    def n_stages(self) -> int:
        return len(self.poses) - 1


def _fail(path, field, problem):
    raise StagingFolderError(path, field, problem, "stage the case again: orthosim stage CASE --out DIR")


def _number(path, field, value, lo=-math.inf, hi=math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or not lo <= value <= hi:
        _fail(path, field, f"must be a number in [{lo:g}, {hi:g}], got {value!r}")
    return float(value)


def _pose(path, field, value) -> np.ndarray:
    try:
        T = np.array(value, dtype=float)
    except (TypeError, ValueError):
        _fail(path, field, "is not a 4x4 matrix of numbers")
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        _fail(path, field, f"is not a finite 4x4 matrix (shape {T.shape})")
    R = T[:3, :3]
    if (np.abs(T[3] - [0, 0, 0, 1]).max() > 1e-9 or np.abs(R @ R.T - np.eye(3)).max() > ROTATION_ATOL
            or np.linalg.det(R) <= 0):
        _fail(path, field, "is not a rigid motion (rotation not orthonormal, or last row not 0 0 0 1)")
    return T


def read_stages(folder: str | Path) -> WrittenStaging:
    """The staging written in `folder` (its stages.json), checked; StagingFolderError otherwise."""
    folder = Path(folder)
    path = folder / STAGES_FILE
    if not folder.is_dir():
        raise StagingFolderError(folder, None, "is not a folder", "give the folder `orthosim stage CASE --out DIR` wrote")
    if not path.is_file():
        raise StagingFolderError(folder, STAGES_FILE, "is missing (not a staging folder, or staging did not finish)",
                                 "give the folder `orthosim stage CASE --out DIR` wrote")
    try:
        data = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        _fail(path, None, f"is unreadable ({err.__class__.__name__})")
    if not isinstance(data, dict):
        _fail(path, None, "is not a JSON object")
    if data.get("orthosim_version") != __version__:
        _fail(path, "orthosim_version", f"{data.get('orthosim_version')!r} is not this orthosim ({__version__})")
    limits = _limits(path, data.get("limits"))
    teeth = _teeth(path, data.get("teeth"))
    poses, progress = _stages(path, data.get("poses"), teeth)
    if data.get("stages") != len(poses) - 1:
        _fail(path, "stages", f"says {data.get('stages')!r} but the file holds {len(poses) - 1} stages")
    ipr = _ipr(path, data.get("ipr"), teeth)
    case = data.get("case_file")
    if case is not None and not isinstance(case, str):
        _fail(path, "case_file", "must be a path")
    sha = data.get("case_sha256")
    return WrittenStaging(path, None if case is None else Path(case), sha if isinstance(sha, str) else None,
                          limits, teeth, tuple(poses), progress, ipr)


def _limits(path, raw) -> StageLimits:
    if not isinstance(raw, dict):
        _fail(path, "limits", "is missing")
    values = {}
    for c in COMPONENTS:
        key = f"{c}_{UNITS[c]}"
        if key not in raw:
            _fail(path, f"limits.{key}", "is missing")
        values[c] = _number(path, f"limits.{key}", raw[key], 1e-9)
    return StageLimits(**values)


def _teeth(path, raw) -> tuple[int, ...]:
    if not isinstance(raw, list) or not raw:
        _fail(path, "teeth", "must be a non-empty list of FDI numbers")
    for n in raw:
        if isinstance(n, bool) or not isinstance(n, int) or not F.is_fdi(n):
            _fail(path, "teeth", f"{n!r} is not an FDI tooth number")
    if len(set(raw)) != len(raw):
        _fail(path, "teeth", "names a tooth twice")
    return tuple(raw)


def _stages(path, raw, teeth) -> tuple[list[dict[int, np.ndarray]], np.ndarray]:
    if not isinstance(raw, list) or len(raw) < 1:
        _fail(path, "poses", "must be a list of stages")
    poses, progress = [], []
    names = {str(n) for n in teeth}
    for k, stage in enumerate(raw):
        where = f"poses[{k}]"
        if not isinstance(stage, dict) or stage.get("stage") != k:
            _fail(path, f"{where}.stage", f"must be stage {k} (stages numbered 0, 1, 2, ... in order)")
        p, prog = stage.get("poses"), stage.get("progress")
        if not isinstance(p, dict) or set(p) != names:
            _fail(path, f"{where}.poses", "must give a pose for every tooth of `teeth` and no other")
        if not isinstance(prog, dict) or set(prog) != names:
            _fail(path, f"{where}.progress", "must give the progress of every tooth of `teeth`")
        poses.append({n: _pose(path, f"{where}.poses.{n}", p[str(n)]) for n in teeth})
        progress.append([_number(path, f"{where}.progress.{n}", prog[str(n)], 0.0, 1.0) for n in teeth])
    return poses, np.array(progress)


def _ipr(path, raw, teeth) -> tuple[InterproximalReduction, ...]:
    if not isinstance(raw, list):
        _fail(path, "ipr", "must be a list (empty when there is no reduction)")
    out = []
    for i, r in enumerate(raw):
        where = f"ipr[{i}]"
        if not isinstance(r, dict):
            _fail(path, where, "must be an object with fdi_a, fdi_b, ipr_mm, direction")
        a, b = r.get("fdi_a"), r.get("fdi_b")
        if a not in teeth or b not in teeth or a == b:
            _fail(path, f"{where}.fdi_a", f"{a!r}-{b!r} is not a pair of the staged teeth")
        amount = _number(path, f"{where}.ipr_mm", r.get("ipr_mm"), 0.0, MAX_IPR_MM)
        try:
            u = np.array(r.get("direction"), dtype=float)
        except (TypeError, ValueError):
            u = np.zeros(0)
        if u.shape != (3,) or not np.all(np.isfinite(u)) or abs(np.linalg.norm(u) - 1.0) > 1e-6:
            _fail(path, f"{where}.direction", "must be a unit vector [x, y, z]")
        out.append(InterproximalReduction(int(a), int(b), amount, u))
    return tuple(out)
