"""Case files: a patient's teeth and a treatment plan, read from TOML and validated whole.

A case names its model (the parametric dentition, a folder of per-tooth meshes, or an
Open-Full-Jaw folder), the extractions, the loads (on a tooth or a group: a force in cN along a
direction of the arch or a vector, applied at a point, and/or a moment in cN*mm), the wire
(rectangular or round) and the timing (duration and step, days). Every problem in the file is
reported before any work starts, one line naming the file, the field and the fix. See
`cases/*.toml` for annotated examples; the full schema is in README.md.
"""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from orthosim.model import fdi as F
from orthosim.collision.detectors import DETECTORS
from orthosim.errors import CaseError
from orthosim.exchange.casefields import FieldReader, teeth_list
from orthosim.staging.target import CaseStaging, read_case_staging


def _cases_dir() -> Path:
    """The shipped case files: `orthosim/cases/` in an installed wheel (package data), else the
    checkout's top-level `cases/` folder (an editable install or a source tree)."""
    package = Path(__file__).resolve().parents[1]
    installed = package / "cases"
    return installed if installed.is_dir() else package.parent / "cases"


CASES_DIR = _cases_dir()
DEFAULT_CASE = CASES_DIR / "case1_first_premolar_extraction.toml"  # the demo's and the bench's case
DIRECTIONS = ("mesial", "distal", "labial", "lingual", "occlusal", "apical")
POINTS = ("bracket", "crown_center", "center_of_resistance")
MOMENT_AXES = ("mesiodistal", "labiolingual", "long_axis")
MOVEMENTS = ("auto", "translation", "tipping", "rotation", "extrusion", "intrusion")
WIRES = ("rectangular", "round")
MODEL_KINDS = ("parametric", "meshes", "open-full-jaw")
# What each wire can do (the paper's wire models): a round wire only rotates the tooth, about the
# point at 1/3 of root length; a rectangular wire translates under a force and rotates under a torque.
WIRE_MOVEMENTS = {
    "rectangular": ("auto", "translation", "extrusion", "intrusion", "rotation", "tipping"),
    "round": ("auto", "tipping", "rotation"),
}


@dataclass(frozen=True)
class ModelSpec:
    kind: str = "parametric"
    resolution: str | int = "smooth"  # parametric: ring points or a preset name
    third_molars: bool = False  # parametric
    diastema_mm: float = 0.0  # space opened between the central incisors, both arches (any kind)
    folder: Path | None = None  # meshes / open-full-jaw (open-full-jaw: the first of `folders`)
    files: dict[str, int] = field(default_factory=dict)  # meshes: file name (may name a subfolder) -> FDI
    scale: float = 1.0  # meshes: multiply coordinates (e.g. 1000 for metres)
    folders: tuple[Path, ...] = ()  # open-full-jaw: the scan's folders (maxilla, mandible), one transform
    frame: str = "arch"  # meshes: "arch" (already in the arch frame) or "scan" (fit one rigid transform)
    max_triangles_per_tooth: int | None = None  # meshes / open-full-jaw: simplify above it (None: meshload's default)

    def present_teeth(self) -> set[int]:
        """FDI numbers the model will have, known without loading any mesh."""
        if self.kind == "parametric":
            positions = range(1, 9) if self.third_molars else range(1, 8)
            return {10 * q + p for q in F.QUADRANTS for p in positions}
        if self.kind == "meshes":
            return set(self.files.values())
        present = set()
        for path in (p for f in (self.folders or (self.folder,)) for p in f.glob("tooth_*.stl")):
            try:
                present.add(F.universal_to_fdi(int(path.stem.split("_", 1)[1])))
            except ValueError:
                continue
        return present


@dataclass(frozen=True)
class Load:
    teeth: tuple[int, ...]  # FDI numbers the load acts on (each tooth gets the full load)
    force_cN: float = 0.0
    direction: str | tuple[float, float, float] = "mesial"  # along the arch, or an arch-frame vector
    point: str | tuple[float, float, float] = "bracket"  # where the force acts; tuple: local mm
    moment_cNmm: float = 0.0
    moment_axis: str = "mesiodistal"  # tooth-frame axis of the moment
    movement: str = "auto"


@dataclass(frozen=True)
class Wire:
    type: str = "rectangular"


@dataclass(frozen=True)
class Simulation:
    """Movement-model parameters ([simulation] table; see orthosim.movement)."""

    force_share: float = 0.5  # fraction (0..1) of a push passed on to the tooth it hits
    restitution: float = 0.5  # Newton's coefficient (0..1) of the reported impacts
    resistance_rule: str = "literature"  # centre of resistance: "literature" or "paper"
    resistance_fraction: float = 0.4  # literature rule: share (1/3..1/2) of the embedded root below the crest
    # how much deeper (mm) teeth of the two arches in contact may sink while sliding; None: the
    # model's own (`orthosim.collision.interpenetration.default_occlusal_slide_mm`)
    occlusal_slide_mm: float | None = None


@dataclass(frozen=True)
class Case:
    path: Path
    name: str
    description: str
    model: ModelSpec
    extractions: tuple[int, ...]
    loads: tuple[Load, ...]
    wire: Wire
    duration_days: float
    step_days: float
    detector: str
    simulation: Simulation = Simulation()
    staging: CaseStaging | None = None  # the [start] and [target] sections (aligner staging), or None

    @property
    def steps(self) -> int:
        return max(1, int(math.ceil(self.duration_days / self.step_days - 1e-9)))

    def build_dentition(self):
        """The tooth models this case names (all present teeth; extractions are state, not model)."""
        from orthosim.model.dentition import Dentition

        m = self.model
        if m.kind == "parametric":
            from orthosim.model.parametric import parametric_dentition

            dent: Dentition = parametric_dentition(m.resolution, m.third_molars, m.diastema_mm)
            return dent
        from orthosim.model.dentition_cache import cached_dentition

        parameters, input_files = self._mesh_model_key()
        return cached_dentition(parameters, self._load_meshes, input_files)

    def _mesh_model_key(self) -> tuple[dict, list[Path]]:
        """(parameters, input files) that decide a mesh model: the dentition cache's key."""
        m = self.model
        budget = {} if m.max_triangles_per_tooth is None else {"max_triangles_per_tooth": m.max_triangles_per_tooth}
        if m.kind == "meshes":
            return ({"kind": m.kind, "files": m.files, "scale": m.scale, "frame": m.frame, "diastema_mm": m.diastema_mm,
                     **budget}, [m.folder / f for f in m.files])
        folders = list(m.folders) or [m.folder]
        return ({"kind": m.kind, "folders": len(folders), "diastema_mm": m.diastema_mm, **budget},
                sorted(p for f in folders for p in f.iterdir() if p.is_file()))

    def _load_meshes(self):
        from orthosim.exchange.meshfolder import load_mesh_folder
        from orthosim.exchange.meshload import DEFAULT_MAX_TRIANGLES
        from orthosim.exchange.openfulljaw import load_open_full_jaw

        m = self.model
        budget = DEFAULT_MAX_TRIANGLES if m.max_triangles_per_tooth is None else m.max_triangles_per_tooth
        if m.kind == "meshes":
            dent = load_mesh_folder(m.folder, m.files, scale=m.scale, frame=m.frame, max_triangles=budget)
        else:
            dent = load_open_full_jaw(list(m.folders) or m.folder, max_triangles=budget)
        if m.diastema_mm:
            from orthosim.model.dentition import open_midline_space

            dent = open_midline_space(dent, m.diastema_mm)
        return dent

    def dentition_is_cached(self) -> bool:
        """Whether `build_dentition` will load the teeth from the disk cache rather than build them."""
        from orthosim.model.dentition_cache import is_cached, parametric_parameters

        m = self.model
        if m.kind == "parametric":
            return is_cached(parametric_parameters(m.resolution, m.third_molars, m.diastema_mm))
        return is_cached(*self._mesh_model_key())


_TOP = ("case", "model", "treatment", "wire", "loads", "simulation", "start", "target")
_CASE = ("name", "description")
_MODEL = ("kind", "resolution", "third_molars", "diastema_mm", "folder", "files", "scale", "frame",
          "max_triangles_per_tooth")
MIN_TRIANGLES_PER_TOOTH = 10_000  # fewer would flatten a molar's cusps and fossae (the smooth parametric molar has 7,000)
FRAMES = ("arch", "scan")
_TREATMENT = ("extractions", "duration_days", "step_days", "detector")
_WIRE = ("type",)
_SIMULATION = ("force_share", "restitution", "resistance_rule", "resistance_fraction", "occlusal_slide_mm")
RESISTANCE_RULES = ("literature", "paper")
_LOAD = ("teeth", "force_cN", "direction", "point", "moment_cNmm", "moment_axis", "movement")


def load_case(path: str | Path) -> Case:
    """Read and validate a case file; raise CaseError (one line: file, field, fix) on any problem."""
    path = Path(path)
    if not path.is_file():
        raise CaseError(path, None, "no such case file", "check the path; shipped cases are in cases/")
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise CaseError(path, None, f"not valid TOML: {err}", "fix the syntax at that line") from None
    except (OSError, UnicodeDecodeError) as err:
        raise CaseError(path, None, f"cannot be read: {err}", "check the file is a readable TOML text file") from None

    top = FieldReader(path, "", data, _TOP)
    meta = FieldReader(path, "case", top.get("case", {}), _CASE)
    name = meta.string("name", path.stem)
    description = meta.string("description", "")

    model = _read_model(path, FieldReader(path, "model", top.get("model", {}), _MODEL))
    present = model.present_teeth()

    treat = FieldReader(path, "treatment", top.get("treatment", {}), _TREATMENT)
    raw_ext = treat.get("extractions", [])
    if not isinstance(raw_ext, list):
        treat.fail("extractions", f"must be a list of FDI numbers, got {raw_ext!r}", "write e.g. [14, 24]")
    extractions = []
    for i, t in enumerate(raw_ext):
        if F.is_fdi(t) and t not in present:
            treat.fail(f"extractions[{i}]", f"tooth {t} ({F.name(t)}) cannot be extracted: it is not in the model",
                       "remove it from the list")
        extractions.append(treat.tooth(f"extractions[{i}]", t, present))
    if len(set(extractions)) != len(extractions):
        treat.fail("extractions", "lists a tooth twice", "list each tooth once")
    duration = treat.number("duration_days", 90.0, positive=True)
    step = treat.number("step_days", 1.0, positive=True)
    if step > duration:
        treat.fail("step_days", f"step ({step:g} days) is longer than the duration ({duration:g} days)",
                   "use a step no longer than duration_days")
    if duration / step > 100_000:
        treat.fail("step_days", f"{duration / step:.0f} steps is more than 100000", "use a longer step")
    detector = treat.string("detector", "continuous", DETECTORS)

    wire = Wire(FieldReader(path, "wire", top.get("wire", {}), _WIRE).string("type", "rectangular", WIRES))

    raw_loads = top.get("loads", [])
    if not isinstance(raw_loads, list):
        top.fail("loads", "must be an array of tables", "write each load as [[loads]]")
    loads = tuple(_read_load(path, i, raw, present, set(extractions), wire) for i, raw in enumerate(raw_loads))
    simulation = _read_simulation(FieldReader(path, "simulation", top.get("simulation", {}), _SIMULATION))

    staging = read_case_staging(path, data, present, set(extractions))
    return Case(path, name, description, model, tuple(extractions), loads, wire, duration, step, detector, simulation, staging)


def _read_simulation(r: FieldReader) -> Simulation:
    share = r.number("force_share", 0.5)
    if share >= 1.0:
        r.fail("force_share", f"must be below 1, got {share:g}", "use a fraction such as 0.5 (a tooth keeps part of its push)")
    restitution = r.number("restitution", 0.5)
    if restitution > 1.0:
        r.fail("restitution", f"must be at most 1, got {restitution:g}", "use a value from 0 (no bounce) to 1 (elastic)")
    rule = r.string("resistance_rule", "literature", RESISTANCE_RULES)
    fraction = r.number("resistance_fraction", 0.4)
    if not (1.0 / 3.0 - 1e-9 <= fraction <= 0.5 + 1e-9):
        r.fail("resistance_fraction", f"{fraction:g} is outside 1/3 to 1/2", "use a value between 0.333 and 0.5")
    slide = r.number("occlusal_slide_mm") if "occlusal_slide_mm" in r.table else None
    if slide is not None and slide > 3.0:
        r.fail("occlusal_slide_mm", f"{slide:g} mm is more than a cusp's height", "use a value from 0 to 3 mm")
    return Simulation(share, restitution, rule, fraction, slide)


def _read_model(path: Path, r: FieldReader) -> ModelSpec:
    kind = r.string("kind", "parametric", MODEL_KINDS)
    if kind == "parametric":
        for key in ("folder", "files", "scale", "frame", "max_triangles_per_tooth"):
            if key in r.table:
                r.fail(key, "applies only to mesh models", "remove it, or set kind = \"meshes\"")
        resolution = r.get("resolution", "smooth")
        from orthosim.model.toothshape import RESOLUTIONS

        if isinstance(resolution, str):
            if resolution not in RESOLUTIONS:
                r.fail("resolution", f"unknown resolution {resolution!r}", f"use one of {', '.join(RESOLUTIONS)} or an even number >= 6")
        elif isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 6 or resolution % 2:
            r.fail("resolution", f"must be a preset name or an even number >= 6, got {resolution!r}", "use e.g. \"smooth\" or 40")
        return ModelSpec(kind, resolution, r.boolean("third_molars", False), r.number("diastema_mm", 0.0))

    for key in ("resolution", "third_molars"):
        if key in r.table:
            r.fail(key, "applies only to the parametric model", "remove it, or set kind = \"parametric\"")
    diastema = r.number("diastema_mm", 0.0)
    folder_raw = r.get("folder")
    many = isinstance(folder_raw, list) and kind == "open-full-jaw"
    if many and (not folder_raw or not all(isinstance(f, str) for f in folder_raw)):
        r.fail("folder", f"must be a folder or a list of folders, got {folder_raw!r}", 'write e.g. ["maxilla", "mandible"]')
    folders = []
    for i, raw in enumerate(folder_raw if many else [r.string("folder")]):
        key = f"folder[{i}]" if many else "folder"
        folder = Path(raw).expanduser()
        if not folder.is_absolute():
            folder = (path.parent / folder).resolve()  # relative to the case file, so cases travel with their data
        folder = _shared_data_fallback(raw, folder)
        if not folder.is_dir():
            r.fail(key, f"no such folder {folder}", "give a folder of tooth meshes, relative to the case file or absolute")
        folders.append(folder)
    folder = folders[0]
    files: dict[str, int] = {}
    frame = r.string("frame", "arch", FRAMES) if kind == "meshes" else "arch"
    if kind != "meshes" and "frame" in r.table:
        r.fail("frame", "applies only to kind = \"meshes\" (open-full-jaw folders are always a scan frame)", "remove it")
    if kind == "meshes":
        raw_files = r.get("files")
        if not isinstance(raw_files, dict) or not raw_files:
            r.fail("files", "missing or empty", "add a table [model.files] mapping each mesh file to its FDI number")
        for fname, number in raw_files.items():
            if not F.is_fdi(number):
                r.fail(f"files.{fname}", f"unknown tooth {number!r}", "use an FDI number: 11-18, 21-28, 31-38 or 41-48")
            if not (folder / fname).is_file():
                r.fail(f"files.{fname}", f"no such file in {folder}", "check the file name")
            files[fname] = number
        if len(set(files.values())) != len(files):
            r.fail("files", "two files map to the same tooth", "give each FDI number once")
    elif "files" in r.table:
        r.fail("files", "not used by open-full-jaw folders (tooth_N.stl names the tooth)", "remove it")
    else:
        from orthosim.exchange.scanfolders import scan_folders

        if not many:
            folders = scan_folders(folder)  # a patient folder stands for its maxilla/ and mandible/
        for i, f in enumerate(folders):
            if not any(f.glob("tooth_*.stl")):
                r.fail(f"folder[{i}]" if many else "folder", f"no tooth_N.stl files in {f}",
                       "point it at an Open-Full-Jaw maxilla or mandible folder, or the patient folder holding both")
    budget = r.get("max_triangles_per_tooth")
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int) or budget < MIN_TRIANGLES_PER_TOOTH):
        r.fail("max_triangles_per_tooth", f"must be a whole number of at least {MIN_TRIANGLES_PER_TOOTH:,}, got {budget!r}",
               "write e.g. 100000 (the default), or leave it out")
    return ModelSpec(kind, diastema_mm=diastema, folder=folder, files=files, scale=r.number("scale", 1.0, positive=True),
                     folders=tuple(folders) if kind == "open-full-jaw" else (), frame=frame,
                     max_triangles_per_tooth=budget)


def _shared_data_fallback(raw: str, folder: Path) -> Path:
    """A folder written as `.../shared/data/<name>` that is not there is looked up in the shared data
    folder (`orthosim.exchange.shareddata`: $ORTHOSIM_SHARED_DATA), so a shipped case also runs from a clone
    or worktree that does not sit beside `shared/`."""
    marker = "shared/data/"
    text = raw.replace("\\", "/")
    if folder.is_dir() or marker not in text:
        return folder
    from orthosim.exchange.shareddata import shared_data_dir

    other = shared_data_dir() / text.split(marker, 1)[1]
    return other.resolve() if other.is_dir() else folder


def _read_load(path: Path, i: int, raw: Any, present: set[int], extracted: set[int], wire: Wire) -> Load:
    r = FieldReader(path, f"loads[{i}]", raw, _LOAD)
    teeth_raw = r.get("teeth")
    if isinstance(teeth_raw, int) and not isinstance(teeth_raw, bool):
        teeth_raw = [teeth_raw]
    if not isinstance(teeth_raw, list) or not teeth_raw:
        r.fail("teeth", "missing or empty", "name the tooth or teeth, e.g. teeth = [16, 26]")
    teeth = tuple(r.tooth(f"teeth[{j}]", t, present) for j, t in enumerate(teeth_raw))
    for j, t in enumerate(teeth):
        if t in extracted:
            r.fail(f"teeth[{j}]", f"tooth {t} is extracted in this case and cannot carry a load",
                   "load a tooth that stays, or remove it from treatment.extractions")
    force = r.number("force_cN", 0.0)
    moment = r.number("moment_cNmm", 0.0, minimum=None)
    if force == 0.0 and moment == 0.0:
        r.fail(None, "has neither a force nor a moment", "set force_cN (cN) and/or moment_cNmm (cN*mm)")
    direction_raw = r.get("direction", "mesial")
    if isinstance(direction_raw, str):
        direction = r.string("direction", "mesial", DIRECTIONS)
    else:
        direction = r.vector("direction", direction_raw)
        if np.linalg.norm(direction) == 0:
            r.fail("direction", "is the zero vector", "give a non-zero direction in the arch frame")
    point_raw = r.get("point", "bracket")
    point = r.string("point", "bracket", POINTS) if isinstance(point_raw, str) else r.vector("point", point_raw)
    moment_axis = r.string("moment_axis", "mesiodistal", MOMENT_AXES)
    movement = r.string("movement", "auto", MOVEMENTS)
    if movement not in WIRE_MOVEMENTS[wire.type]:
        r.fail("movement", f"a {wire.type} wire cannot do {movement} (it only rotates the tooth)",
               f"use a rectangular wire, or one of: {', '.join(WIRE_MOVEMENTS[wire.type])}")
    if movement in ("rotation", "tipping") and wire.type == "rectangular" and moment == 0.0:
        r.fail("movement", f"{movement} with a rectangular wire needs a torque", "set moment_cNmm, or use movement = \"translation\"")
    return Load(teeth, force, direction, point, moment, moment_axis, movement)
