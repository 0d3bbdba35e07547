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
from orthosim.errors import CaseError, OrthosimError
from orthosim.exchange.casefields import FieldReader
from orthosim.exchange.ligamentfields import Anchorage, CaseLigament, read_anchorage, read_ligament
from orthosim.exchange.target import CaseStaging, read_case_staging


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
MODEL_KINDS = ("parametric", "meshes", "open-full-jaw", "labelled-scan")
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
    upper: Path | None = None  # labelled-scan: the upper arch scan (its label JSON beside it)
    lower: Path | None = None  # labelled-scan: the lower arch scan

    def present_teeth(self) -> set[int]:
        """FDI numbers the model will have, known without loading any mesh."""
        if self.kind == "parametric":
            positions = range(1, 9) if self.third_molars else range(1, 8)
            return {10 * q + p for q in F.QUADRANTS for p in positions}
        if self.kind == "meshes":
            return set(self.files.values())
        if self.kind == "labelled-scan":
            from orthosim.exchange.labelledscan import labelled_teeth

            return labelled_teeth(self.upper, self.lower)
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
    # centre of resistance and motion: "ligament" (the root's stiffness, `orthosim.mechanics.ligament`),
    # "literature" or "paper" (rules, `orthosim.mechanics.resistance`); a case file that leaves it out gets
    # `default_resistance_rule`
    resistance_rule: str = "literature"
    resistance_fraction: float = 0.4  # literature rule: share (1/3..1/2) of the embedded root below the crest
    # how much deeper (mm) teeth of the two arches in contact may sink while sliding; None: the
    # model's own (`orthosim.collision.interpenetration.default_occlusal_slide_mm`)
    occlusal_slide_mm: float | None = None


@dataclass(frozen=True)
class Biomechanics:
    """The rate law's constants ([biomechanics] table; see `orthosim.mechanics.biomechanics`).

    parameters: the named set the table starts from: "paper" (the paper's replication values, the
    default, so cases written before the table keep their numbers) or "clinical" (fitted to the
    evidence table, `orthosim evidence`). Each number the table gives replaces the set's own;
    None keeps it. Units: cN, mm per month (365.25/12 days), mm^2, a plain factor."""

    parameters: str = "paper"
    threshold_cN: float | None = None
    saturation_cN: float | None = None
    max_rate_mm_per_month: float | None = None
    reference_root_area_mm2: float | None = None
    mandibular_bone_factor: float | None = None

    def overrides(self) -> dict[str, float | None]:
        """The table's own numbers by RateLaw field name (max_rate still per month)."""
        return {k: getattr(self, k) for k in _BIOMECHANICS[1:]}


@dataclass(frozen=True)
class Occlusion:
    """How the bite closes after each step ([occlusion] table; see orthosim.movement.closure)."""

    closure: str | None = None  # "hinge" or "none"; None: hinge for mesh models with both arches, none for parametric
    # right and left condyle centres (arch frame, mm) for a known patient; None: estimated from the arch
    condylar_axis: tuple[tuple[float, float, float], tuple[float, float, float]] | None = None
    max_opening_deg: float = 8.0  # the widest the mandible opens from rest (degrees)


@dataclass(frozen=True)
class Case:
    """A validated case file (`load_case`): a patient's teeth and a treatment plan.

    `model`: which teeth (the parametric dentition, tooth meshes, an Open-Full-Jaw folder or
    labelled scans); `extractions`: FDI numbers taken out; `loads`: forces (cN) and moments (cN*mm)
    on teeth; `wire`: rectangular or round; `duration_days` and `step_days` (days; `steps` of
    them); `detector`: the collision detector a run uses; `simulation`, `biomechanics`,
    `occlusion`: the movement model's settings; `staging`: the [start] and [target] of an aligner
    set-up, or None. `build_dentition()` gives its teeth (cached on disk).
    """

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
    biomechanics: Biomechanics = Biomechanics()  # the [biomechanics] table: the rate law's constants
    occlusion: Occlusion = Occlusion()
    ligament: CaseLigament = CaseLigament()  # the [ligament] table (`orthosim.exchange.ligamentfields`)
    anchorage: tuple[Anchorage, ...] = ()  # the [[anchorage]] tables

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
        if m.kind == "labelled-scan":
            from orthosim.exchange.labelledscan import labels_path_for

            scans = [p for p in (m.upper, m.lower) if p is not None]
            return ({"kind": m.kind, "arches": [p.stem for p in scans], "diastema_mm": m.diastema_mm, **budget},
                    scans + [labels_path_for(p) for p in scans])
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
        elif m.kind == "labelled-scan":
            from orthosim.exchange.labelledscan import load_labelled_scans

            dent = load_labelled_scans(m.upper, m.lower, max_triangles=budget)
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


_TOP = ("case", "model", "treatment", "wire", "loads", "simulation", "start", "target", "biomechanics", "occlusion",
        "ligament", "anchorage")
_CASE = ("name", "description")
_MODEL = ("kind", "resolution", "third_molars", "diastema_mm", "folder", "files", "scale", "frame",
          "max_triangles_per_tooth", "upper", "lower")
MIN_TRIANGLES_PER_TOOTH = 10_000  # fewer would flatten a molar's cusps and fossae (the smooth parametric molar has 7,000)
MAX_TRIANGLES_PER_TOOTH = 2_000_000  # 32 teeth of that hold about 3 GB of mesh arrays
MAX_RESOLUTION = 256  # ring points: four times the finest preset
# What a real mouth allows, per numeric field: (low, high, unit, why); README "Allowed ranges" says the
# same with sources. A value outside is refused in one line before any work.
RANGES = {
    "diastema_mm": (0.0, 10.0, "mm", "wider than a central incisor's crown (8.5 mm) is no gap tooth movement closes"),
    "scale": (1e-4, 1e4, "", "mm per file unit: 0.001 for micrometres, 25.4 for inches, 1000 for metres"),
    "duration_days": (0.0, 1825.0, "days", "five years; fixed-appliance treatment lasts 20 months on average"),
    "step_days": (0.0, 365.0, "days", "a year; visits are 4-8 weeks apart and aligners change every 1-2 weeks"),
    "force_cN": (0.0, 500.0, "cN", "orthodontic forces on a tooth are 10-120 cN; 500 cN is orthopaedic"),
    "moment_cNmm": (-5000.0, 5000.0, "cN*mm", "a 500 cN force at the 10 mm moment-to-force ratio of bodily movement"),
    "point": (-30.0, 30.0, "mm", "the longest tooth, a canine, is 27 mm from cusp tip to apex"),
}


def _bounded(r: FieldReader, key: str, default: float, positive: bool = False) -> float:
    """A number of the case within its `RANGES` entry (one-line CaseError naming field and range)."""
    low, high, unit, why = RANGES[key]
    return r.number(key, default, positive=positive, minimum=None if positive else low, maximum=high, unit=unit, why=why)
FRAMES = ("arch", "scan")
_TREATMENT = ("extractions", "duration_days", "step_days", "detector")
_WIRE = ("type",)
_OCCLUSION = ("closure", "condylar_axis", "max_opening_deg")
_SIMULATION = ("force_share", "restitution", "resistance_rule", "resistance_fraction", "occlusal_slide_mm")
RESISTANCE_RULES = ("ligament", "literature", "paper")
_BIOMECHANICS = ("parameters", "threshold_cN", "saturation_cN", "max_rate_mm_per_month", "reference_root_area_mm2",
                 "mandibular_bone_factor")
# (lowest, highest, unit, example) of each number of the [biomechanics] table
_BIOMECHANICS_RANGES = {"threshold_cN": (0.0, 300.0, "cN", "20"), "saturation_cN": (1.0, 1000.0, "cN", "150"),
                        "max_rate_mm_per_month": (0.01, 5.0, "mm per month", "1.0"),
                        "reference_root_area_mm2": (50.0, 1000.0, "mm^2", "200"),
                        "mandibular_bone_factor": (0.25, 4.0, "", "1.0")}
_LOAD = ("teeth", "force_cN", "direction", "point", "moment_cNmm", "moment_axis", "movement")


def load_case(path: str | Path) -> Case:
    """Read and validate a case file; raise its first problem as a CaseError (one line: file, field,
    fix). `read_case` gives every problem of the file."""
    case, problems = read_case(Path(path))
    if problems:
        raise problems[0]
    return case


def read_case(path: str | Path) -> tuple[Case | None, list[OrthosimError]]:
    """(the case, or None when the file has problems; every problem, in the order of its sections).

    Each problem is a one-line OrthosimError (`where`: the file, `field`: the dotted field): every
    unknown key, and in each section (each load its own) the first value that cannot be read. A
    file that is not valid TOML is one problem. What `orthosim check` lists."""
    path = Path(path)
    if not path.is_file():
        return None, [CaseError(path, None, "no such case file", "check the path; shipped cases are in cases/")]
    try:
        with path.open("rb") as fh:
            data = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        return None, [CaseError(path, None, f"not valid TOML: {err}", "fix the syntax at that line")]
    except (OSError, UnicodeDecodeError) as err:
        return None, [CaseError(path, None, f"cannot be read: {err}", "check the file is a readable TOML text file")]
    problems: list[OrthosimError] = []

    def section(read, fallback=None):
        """read() (one section), or its problem kept and `fallback` returned, so the next section is read."""
        try:
            return read()
        except OrthosimError as err:
            problems.append(err)
            return fallback

    top = FieldReader(path, "", data, _TOP, problems)

    def table(name: str, allowed: tuple[str, ...]) -> FieldReader:
        return FieldReader(path, name, top.get(name, {}), allowed, problems)

    meta = section(lambda: table("case", _CASE))
    name = section(lambda: meta.string("name", path.stem)) if meta else path.stem
    description = section(lambda: meta.string("description", "")) if meta else ""
    model = section(lambda: _read_model(path, table("model", _MODEL)))
    # a model that cannot be read has any tooth: the sections below report their own problems only
    present = section(model.present_teeth, ALL_TEETH) if model else ALL_TEETH
    extractions, duration, step, detector = section(lambda: _read_treatment(table("treatment", _TREATMENT), present),
                                                    ((), 90.0, 1.0, "continuous"))
    wire = section(lambda: Wire(table("wire", _WIRE).string("type", "rectangular", WIRES)), Wire())
    loads = tuple(section(lambda i=i, raw=raw: _read_load(path, i, raw, present, set(extractions), wire, problems))
                  for i, raw in enumerate(section(lambda: _load_tables(top), [])))
    biomechanics = section(lambda: _read_biomechanics(table("biomechanics", _BIOMECHANICS)))
    default_rule = default_resistance_rule(model.kind if model else "parametric",
                                           biomechanics.parameters if biomechanics else "paper")
    simulation = section(lambda: _read_simulation(table("simulation", _SIMULATION), default_rule))
    staging = section(lambda: read_case_staging(path, data, present, set(extractions)))
    occlusion = section(lambda: _read_occlusion(table("occlusion", _OCCLUSION)))
    ligament = section(lambda: read_ligament(path, top.get("ligament", {}), present))
    anchorage = section(lambda: read_anchorage(path, top.get("anchorage", []), present, set(extractions)))
    if problems:
        return None, problems
    return Case(path, name, description, model, extractions, loads, wire, duration, step, detector, simulation, staging,
                biomechanics, occlusion, ligament, anchorage), []


ALL_TEETH = frozenset(10 * q + p for q in F.QUADRANTS for p in range(1, 9))


def _load_tables(top: FieldReader) -> list:
    raw_loads = top.get("loads", [])
    if not isinstance(raw_loads, list):
        top.fail("loads", "must be an array of tables", "write each load as [[loads]]")
    return raw_loads


def _read_treatment(treat: FieldReader, present: set[int]) -> tuple[tuple[int, ...], float, float, str]:
    """(extractions, duration_days, step_days, detector) of the [treatment] table."""
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
    duration = _bounded(treat, "duration_days", 90.0, positive=True)
    step = _bounded(treat, "step_days", 1.0, positive=True)
    if step > duration:
        treat.fail("step_days", f"step ({step:g} days) is longer than the duration ({duration:g} days)",
                   "use a step no longer than duration_days")
    if duration / step > 100_000:
        treat.fail("step_days", f"{duration / step:.0f} steps is more than 100000", "use a longer step")
    return tuple(extractions), duration, step, treat.string("detector", "continuous", DETECTORS)


def default_resistance_rule(model_kind: str, parameters: str) -> str:
    """The [simulation] resistance_rule of a case that leaves it out: the paper's parametric cases (a
    parametric model on the paper's rate law) keep the literature rule, so their figures stay the
    paper's; every other case moves teeth by their ligament's stiffness."""
    return "literature" if model_kind == "parametric" and parameters == "paper" else "ligament"


def _read_biomechanics(r: FieldReader) -> Biomechanics:
    from orthosim.mechanics.ratelaw import PARAMETER_SETS

    parameters = r.string("parameters", "paper", tuple(PARAMETER_SETS))
    values = {}
    for key, (low, high, unit, example) in _BIOMECHANICS_RANGES.items():
        if key not in r.table:
            continue
        v = r.number(key)
        if not low <= v <= high:
            r.fail(key, f"{v:g}{' ' + unit if unit else ''} is outside {low:g} to {high:g}",
                   f"use a value from {low:g} to {high:g}, e.g. {example}, or leave it out")
        values[key] = v
    base = PARAMETER_SETS[parameters]
    threshold = values.get("threshold_cN", base.threshold_cN)
    saturation = values.get("saturation_cN", base.saturation_cN)
    if saturation <= threshold:
        key = "saturation_cN" if "saturation_cN" in values else "threshold_cN"
        r.fail(key, f"the saturation force ({saturation:g} cN) must exceed the threshold ({threshold:g} cN)",
               f"raise saturation_cN above threshold_cN (the {parameters!r} set has {base.threshold_cN:g} and {base.saturation_cN:g})")
    return Biomechanics(parameters, **values)


def _read_occlusion(r: FieldReader) -> Occlusion:
    closure = r.string("closure", None, ("hinge", "none")) if "closure" in r.table else None
    axis = None
    if "condylar_axis" in r.table:
        raw = r.get("condylar_axis")
        if not (isinstance(raw, list) and len(raw) == 2):
            r.fail("condylar_axis", f"must be two points, got {raw!r}",
                   "write [[x, y, z], [x, y, z]]: the right and the left condyle centre, arch frame, mm")
        right, left = (r.vector(f"condylar_axis[{i}]", p) for i, p in enumerate(raw))
        if math.dist(right, left) < 40.0:
            r.fail("condylar_axis", f"the condyles are {math.dist(right, left):.1f} mm apart",
                   "give the two condyle centres, about 100 mm apart (Bonwill), in mm")
        axis = (right, left)
    widest = r.number("max_opening_deg", 8.0, positive=True)
    if widest > 30.0:
        r.fail("max_opening_deg", f"{widest:g} degrees is beyond a mouth's hinge opening", "use at most 30")
    return Occlusion(closure, axis, widest)


def _read_simulation(r: FieldReader, default_rule: str = "literature") -> Simulation:
    share = r.number("force_share", 0.5)
    if share >= 1.0:
        r.fail("force_share", f"must be below 1, got {share:g}", "use a fraction such as 0.5 (a tooth keeps part of its push)")
    restitution = r.number("restitution", 0.5)
    if restitution > 1.0:
        r.fail("restitution", f"must be at most 1, got {restitution:g}", "use a value from 0 (no bounce) to 1 (elastic)")
    rule = r.string("resistance_rule", default_rule, RESISTANCE_RULES)
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
        for key in ("folder", "files", "scale", "frame", "max_triangles_per_tooth", "upper", "lower"):
            if key in r.table:
                r.fail(key, "applies only to mesh models", "remove it, or set kind = \"meshes\"")
        resolution = r.get("resolution", "smooth")
        from orthosim.model.toothshape import RESOLUTIONS

        if isinstance(resolution, str):
            if resolution not in RESOLUTIONS:
                r.fail("resolution", f"unknown resolution {resolution!r}", f"use one of {', '.join(RESOLUTIONS)} or an even number >= 6")
        elif isinstance(resolution, bool) or not isinstance(resolution, int) or resolution < 6 or resolution % 2:
            r.fail("resolution", f"must be a preset name or an even number >= 6, got {resolution!r}", "use e.g. \"smooth\" or 40")
        if isinstance(resolution, int) and resolution > MAX_RESOLUTION:
            r.fail("resolution", f"{resolution} ring points is more than {MAX_RESOLUTION}", "use e.g. \"fine\" (64) or fewer points")
        return ModelSpec(kind, resolution, r.boolean("third_molars", False), _bounded(r, "diastema_mm", 0.0))

    for key in ("resolution", "third_molars"):
        if key in r.table:
            r.fail(key, "applies only to the parametric model", "remove it, or set kind = \"parametric\"")
    diastema = _bounded(r, "diastema_mm", 0.0)
    if kind == "labelled-scan":
        return _read_labelled_scan_model(path, r, diastema)
    for key in ("upper", "lower"):
        if key in r.table:
            r.fail(key, "applies only to kind = \"labelled-scan\"", "remove it, or set kind = \"labelled-scan\"")
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
    budget = _triangle_budget(r)
    return ModelSpec(kind, diastema_mm=diastema, folder=folder, files=files, scale=_bounded(r, "scale", 1.0),
                     folders=tuple(folders) if kind == "open-full-jaw" else (), frame=frame,
                     max_triangles_per_tooth=budget)


def _read_labelled_scan_model(path: Path, r: FieldReader, diastema: float) -> ModelSpec:
    """[model] kind = "labelled-scan": `upper` and/or `lower` scan files (label JSON beside each)."""
    from orthosim.exchange.labelledscan import labels_path_for

    for key in ("folder", "files", "scale", "frame"):
        if key in r.table:
            r.fail(key, "not used by labelled scans", "remove it; name the scans with upper = and lower =")
    if "upper" not in r.table and "lower" not in r.table:
        r.fail("upper", "no scan given", 'name at least one arch scan, e.g. upper = "P1_upper.obj"')
    scans = {}
    for key in ("upper", "lower"):
        if key not in r.table:
            continue
        scan = Path(r.string(key)).expanduser()
        scan = scan if scan.is_absolute() else (path.parent / scan).resolve()
        if not scan.is_file():
            r.fail(key, f"no such scan file {scan}", "give the scan's OBJ, STL or PLY, relative to the case file or absolute")
        if not labels_path_for(scan).is_file():
            r.fail(key, f"no label file {labels_path_for(scan).name} beside the scan",
                   "put the segmentation's JSON beside the mesh, with the same name")
        scans[key] = scan
    budget = _triangle_budget(r)
    return ModelSpec("labelled-scan", diastema_mm=diastema, max_triangles_per_tooth=budget,
                     upper=scans.get("upper"), lower=scans.get("lower"))


def _triangle_budget(r: FieldReader) -> int | None:
    budget = r.get("max_triangles_per_tooth")
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, int)
                               or not MIN_TRIANGLES_PER_TOOTH <= budget <= MAX_TRIANGLES_PER_TOOTH):
        r.fail("max_triangles_per_tooth", f"must be a whole number of at least {MIN_TRIANGLES_PER_TOOTH:,} and at most "
               f"{MAX_TRIANGLES_PER_TOOTH:,}, got {budget!r}", "write e.g. 100000 (the default), or leave it out")
    return budget


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


def _read_load(path: Path, i: int, raw: Any, present: set[int], extracted: set[int], wire: Wire,
               problems: list | None = None) -> Load:
    r = FieldReader(path, f"loads[{i}]", raw, _LOAD, problems)
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
    force = _bounded(r, "force_cN", 0.0)
    moment = _bounded(r, "moment_cNmm", 0.0)
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
    low, high, unit, why = RANGES["point"]
    if not isinstance(point, str) and not all(low <= x <= high for x in point):
        r.fail("point", f"{list(point)} is more than {high:g} {unit} from the tooth's CEJ centre",
               f"give tooth-frame coordinates from {low:g} to {high:g} {unit} ({why})")
    moment_axis = r.string("moment_axis", "mesiodistal", MOMENT_AXES)
    movement = r.string("movement", "auto", MOVEMENTS)
    if movement not in WIRE_MOVEMENTS[wire.type]:
        r.fail("movement", f"a {wire.type} wire cannot do {movement} (it only rotates the tooth)",
               f"use a rectangular wire, or one of: {', '.join(WIRE_MOVEMENTS[wire.type])}")
    if movement in ("rotation", "tipping") and wire.type == "rectangular" and moment == 0.0:
        r.fail("movement", f"{movement} with a rectangular wire needs a torque", "set moment_cNmm, or use movement = \"translation\"")
    return Load(teeth, force, direction, point, moment, moment_axis, movement)
