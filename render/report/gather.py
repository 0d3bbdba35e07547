"""Everything a report shows about one case, computed once: the runs grouped by case, the poses
(initial, and the final pose of each detector's run), the distance maps and contact areas of each
pose, the contact table, the space analysis, Bolton ratios and the sphere-tree fit.

Geometry work is done once per case and pose, never per picture: the initial pose is shared by
every detector's run, so its maps are computed once; the teeth are built once per model (cases
that share a model, like the paper's cases 1 and 2, share it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Sequence

import numpy as np

from orthosim.exchange.case import load_case
from orthosim.analysis.contacttable import ContactParts, PairContact, StepContacts, contact_table
from orthosim.evidence.matching import evidence_for_case
from orthosim.collision.detectors import DETECTORS as DETECTOR_ORDER
from orthosim.analysis.distancemap import DistanceMapModel, ToothDistances
from orthosim.errors import OrthosimError
from orthosim.model.occlusion import bolton_ratios
from orthosim.analysis.spaceanalysis import ArchSpace, arch_space, widths_mm

from orthosim_render.report.runs import RunData


class ReportInputError(OrthosimError):
    """The runs given to a report cannot be put together (e.g. two runs of one case and detector)."""


@dataclass(eq=False)
class CaseData:
    name: str
    case_file: Path
    case_sha256: str
    dentition: object
    extracted: tuple[int, ...]
    runs: dict[str, RunData]  # detector -> run, in DETECTOR_ORDER
    poses: dict[str, dict[int, np.ndarray]] = field(default_factory=dict)  # "initial" and each detector
    inter_arch: dict[str, dict[int, ToothDistances]] = field(default_factory=dict)
    contact_areas: dict[str, dict[int, ToothDistances]] = field(default_factory=dict)
    space: dict[str, dict[str, ArchSpace]] = field(default_factory=dict)
    contacts: dict[str, list[PairContact]] = field(default_factory=dict)
    bolton: dict | None = None
    widths_mm: dict[int, float] = field(default_factory=dict)
    fits: dict[int, object] = field(default_factory=dict)  # FDI -> FitReport
    evidence: list = field(default_factory=list)  # EvidenceMatch: the evidence rows the case's force systems fall under

    @property
    def detectors(self) -> list[str]:
        return list(self.runs)

    @property
    def pose_names(self) -> list[str]:
        return ["initial", *self.runs]

    @property
    def present(self) -> list[int]:
        return [n for n in self.dentition.fdis if n not in self.extracted]


def group_runs(runs: Sequence[RunData]) -> list[list[RunData]]:
    """Runs grouped by case (file and content), cases in the order first given, detectors in
    DETECTOR_ORDER; two runs of one case with one detector are refused."""
    groups: dict[tuple, dict[str, RunData]] = {}
    for r in runs:
        key = (r.case_file.resolve(), r.case_sha256)
        g = groups.setdefault(key, {})
        if r.detector in g:
            raise ReportInputError(r.run_dir, None, f"is a second run of {r.case_file} with the {r.detector} detector "
                                   f"(the first is {g[r.detector].run_dir})", "give one run per case and detector")
        g[r.detector] = r
    order = {d: i for i, d in enumerate(DETECTOR_ORDER)}
    return [sorted(g.values(), key=lambda r: order.get(r.detector, len(order))) for g in groups.values()]


def _build(case_file: Path):
    return load_case(case_file).build_dentition()


def build_dentitions(groups: Sequence[Sequence[RunData]]) -> dict:
    """The teeth of every distinct model among the cases, keyed as `gather_case` looks them up;
    two or more models are built at once, one process per core (a smooth parametric model is
    seconds of CPU, the largest share of a report). Call before any GL context exists (fork)."""
    import multiprocessing
    import os
    from concurrent.futures import ProcessPoolExecutor

    todo: dict[str, Path] = {}
    for g in groups:
        todo.setdefault(repr(load_case(g[0].case_file).model), g[0].case_file)
    workers = min(len(todo), os.cpu_count() or 1)
    if workers < 2:
        return {key: _build(path) for key, path in todo.items()}
    with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
        return dict(zip(todo, pool.map(_build, todo.values())))


def gather_case(runs: Sequence[RunData], dentitions: dict | None = None, fits: bool = True) -> CaseData:
    """The CaseData of one case's runs (one per detector). `dentitions` caches built teeth by model."""
    first = runs[0]
    case = load_case(first.case_file)
    dentitions = {} if dentitions is None else dentitions
    key = repr(case.model)
    if key not in dentitions:
        dentitions[key] = case.build_dentition()
    dent = dentitions[key]
    data = CaseData(first.case_name, first.case_file, first.case_sha256, dent, first.extracted,
                    {r.detector: r for r in runs})
    initial = first.initial_poses
    for r in runs[1:]:
        if any(not np.allclose(r.initial_poses[n], initial[n], atol=1e-9) for n in initial):
            raise ReportInputError(r.run_dir, "metrics.json", f"starts from other poses than {first.run_dir}",
                                   "give runs of the same case, written by this orthosim version")
    data.poses["initial"] = initial
    data.evidence = evidence_for_case(case)
    for r in runs:
        data.poses[r.detector] = r.final_poses
    model = _distance_model(dent, dentitions)
    data.widths_mm = widths_mm(dent)
    for name, poses in data.poses.items():
        data.inter_arch[name] = model.inter_arch(poses, data.extracted)
        data.contact_areas[name] = model.contacts(poses, data.extracted)
        data.space[name] = arch_space(dent, poses, data.extracted, data.widths_mm)
    parts = ContactParts(dent)
    for r in runs:
        data.contacts[r.detector] = contact_table(
            dent, (StepContacts(s["step"], s["time_days"], s["poses"], s["touching"]) for s in r.steps), parts)
    try:
        data.bolton = bolton_ratios(dent)
    except KeyError:  # a model without the 12 teeth the ratios are defined on
        data.bolton = None
    if fits:
        from orthosim.spheretree.fitcache import cached_fit

        data.fits = {n: cached_fit(dent.teeth[n].mesh) for n in dent.fdis}
    return data


def _distance_model(dent, cache: dict) -> DistanceMapModel:
    key = ("distance model", id(dent))
    if key not in cache:
        cache[key] = DistanceMapModel(dent)
    return cache[key]
