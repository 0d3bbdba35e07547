"""The ligament's mechanics measured and tabled: what `docs/notes/tooth-mechanics.md` shows, reproducibly.

  stiffness_timing    ms to work out one tooth's ligament (`orthosim.mechanics.ligament`) on a real
                      tooth of about 40k triangles (or a parametric molar refined to that size)
  step_timing         ms per simulation step with the ligament against the literature rule, same
                      case, same detector, in the same run (the ratio is the figure of record)
  resistance_table    per tooth type: the ligament's centre of resistance (share of the embedded
                      root below the crest) beside the rule's and the published interval; molars:
                      bracket to centre along the long axis beside the finite-element row
  rotation_table      a tooth's centre of rotation as M/F at its bracket goes from 0 to 14 mm, and
                      the movement class each falls in
  spread_table        real-jaw case 1 on crowns with estimated roots: each moving tooth's range over
                      the plausible roots beside the real-root result
Run `python -m orthosim_bench.mechanics` for the tables as Markdown (real teeth from ../shared/data
when present). Measurement, not product: the CLI's bench and this script call it, orthosim never does.
"""

from __future__ import annotations

import statistics
import time
from dataclasses import replace

import numpy as np

from orthosim.mechanics.biomechanics import bracket_point
from orthosim.mechanics.ligament import DEFAULT, LigamentProperties, _root_support
from orthosim.mechanics.resistance import center_of_resistance
from orthosim.model import fdi as F

# published intervals the tables hold the model against (sources: orthosim/evidence/evidence.toml)
SINGLE_ROOTED_SHARE = (0.33, 0.42)  # Papageorgiou 2005: share of the root length below the crest
UPPER_MOLAR_BRACKET_TO_CR_MM = (6.20, 9.52)  # FE study of maxillary first molars: 7.86 +/- 1.66 mm
MF_RANGE_MM = tuple(float(x) for x in range(15))


def _type_name(fdi: int) -> str:
    arch = "upper" if F.arch_of(fdi) is F.Arch.UPPER else "lower"
    return f"{arch} {F.tooth_type(fdi).name.lower().replace('_', ' ')}"


def stiffness_timing(tooth, repeats: int = 7, props: LigamentProperties = DEFAULT) -> dict:
    """Median ms of `repeats` fresh ligament computations of `tooth` (no memo), and its size."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        _root_support(tooth, props, props.crest_below_cej_mm)
        times.append((time.perf_counter() - t0) * 1e3)
    return {"fdi": tooth.fdi, "triangles": int(len(tooth.mesh.faces)), "ms": statistics.median(times),
            "target_ms": 50.0, "meets_target": statistics.median(times) < 50.0}


def largest_tooth(dentition):
    """The tooth of `dentition` with the most triangles."""
    return max(dentition.teeth.values(), key=lambda t: len(t.mesh.faces))


def step_timing(case, detector: str = "continuous", steps: int = 6, rounds: int = 3) -> dict:
    """ms per step of `case` with the ligament and with the literature rule (alternating rounds, the
    median of each) and their ratio (target: at most 1.10). The two runs move the teeth differently,
    so their collision work differs too; `same_states` times each model's step (and its forces and
    motions phases alone) from the same states, the rule run's: the ligament's own cost."""
    from orthosim.movement import MovementModel, simulate

    base = MovementModel.build(case)
    models = {rule: MovementModel.build(case, base.dentition, base.collision,
                                        replace(base.settings, resistance_rule=rule))
              for rule in ("ligament", "literature")}
    times: dict[str, list[float]] = {rule: [] for rule in models}
    for _ in range(rounds):
        for rule, model in models.items():
            records = simulate(model, detector, steps)
            next(records)  # the initial state is not a step
            t0 = time.perf_counter()
            n = sum(1 for _ in records)
            times[rule].append((time.perf_counter() - t0) * 1e3 / max(n, 1))
    ms = {rule: statistics.median(v) for rule, v in times.items()}
    ratio = ms["ligament"] / ms["literature"]
    return {"case": case.name, "detector": detector, "steps": steps, "ligament_ms": ms["ligament"],
            "literature_ms": ms["literature"], "ratio": ratio, "target_ratio": 1.10, "meets_target": ratio <= 1.10,
            "same_states": _motion_phase(models, detector, steps, rounds)}


def _motion_phase(models: dict, detector: str, steps: int, rounds: int) -> dict:
    """ms per step of each model from the same states (the literature run's): the whole step, and
    its forces and motions phases alone."""
    from orthosim.movement.forces import forces
    from orthosim.movement.motions import motions
    from orthosim.movement.simulation import initial_state, step

    rule_model = models["literature"]
    state, _ = initial_state(rule_model, detector)
    states = [state]
    for _ in range(steps):
        state, _ = step(rule_model, state)
        states.append(state)
    whole: dict[str, list[float]] = {rule: [] for rule in models}
    phase: dict[str, list[float]] = {rule: [] for rule in models}
    for _ in range(rounds):
        for rule, model in models.items():
            t0 = time.perf_counter()
            for st in states:
                step(model, st)
            whole[rule].append((time.perf_counter() - t0) * 1e3 / len(states))
            t0 = time.perf_counter()
            for _ in range(5):
                for st in states:
                    motions(model, st, forces(model, st, st.centers), st.centers)
            phase[rule].append((time.perf_counter() - t0) * 1e3 / len(states) / 5)
    out = {}
    for name, times in (("step", whole), ("forces_motions", phase)):
        lig, lit = statistics.median(times["ligament"]), statistics.median(times["literature"])
        out[name] = {"ligament_ms": lig, "literature_ms": lit, "ratio": lig / lit}
    return out


def _share(tooth, y_mm: float, crest_mm: float = DEFAULT.crest_below_cej_mm) -> float:
    """Share of the embedded root (crest to apex) that a level y (mm, tooth frame) lies below the crest."""
    return (-crest_mm - y_mm) / max(tooth.root_length - crest_mm, 1e-9)


def resistance_rows(dentition) -> list[dict]:
    """One row per tooth: the ligament's centre of resistance against the literature rule's."""
    rows = []
    for n in dentition.fdis:
        tooth = dentition.teeth[n]
        s = _root_support(tooth, DEFAULT, DEFAULT.crest_below_cej_mm)
        rule = center_of_resistance(tooth)
        bracket = bracket_point(tooth)
        c = s.center_of_resistance
        rows.append({"fdi": n, "type": _type_name(n), "root_mm": tooth.root_length, "share": _share(tooth, c[1]),
                     "rule_share": _share(tooth, rule[1]), "off_axis_mm": float(np.hypot(c[0], c[2])),
                     "residual_mm": s.resistance_residual_mm, "bracket_to_cr_mm": float(bracket[1] - c[1]),
                     "rule_bracket_to_cr_mm": float(bracket[1] - rule[1]), "molar": F.tooth_type(n).is_molar})
    return rows


def resistance_table(rows: list[dict]) -> str:
    """Markdown: per tooth type, medians of the rows (`resistance_rows`) and the published interval."""
    lines = ["| tooth type | teeth | root mm | ligament share | rule share | published share | inside | "
             "off axis mm | residual mm | bracket to CR mm (ligament / rule) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    types: dict[str, list[dict]] = {}
    for r in rows:
        types.setdefault(r["type"], []).append(r)
    for name, group in types.items():
        med = {k: statistics.median(r[k] for r in group) for k in ("root_mm", "share", "rule_share", "off_axis_mm",
                                                                 "residual_mm", "bracket_to_cr_mm", "rule_bracket_to_cr_mm")}
        if group[0]["molar"]:
            published, inside = "(molar: see the FE row)", "-"
        else:
            lo, hi = SINGLE_ROOTED_SHARE
            published = f"{lo:.2f}-{hi:.2f}"
            inside = f"{sum(lo <= r['share'] <= hi for r in group)}/{len(group)}"
        lines.append(f"| {name} | {' '.join(str(r['fdi']) for r in group)} | {med['root_mm']:.1f} | {med['share']:.3f} | "
                     f"{med['rule_share']:.3f} | {published} | {inside} | {med['off_axis_mm']:.2f} | {med['residual_mm']:.2f} | "
                     f"{med['bracket_to_cr_mm']:.2f} / {med['rule_bracket_to_cr_mm']:.2f} |")
    return "\n".join(lines)


def molar_table(rows: list[dict]) -> str:
    """Markdown: each molar's bracket-to-centre distance beside the finite-element row's interval."""
    lo, hi = UPPER_MOLAR_BRACKET_TO_CR_MM
    lines = ["| molar | bracket to CR, ligament mm | rule mm | FE row (upper first molars) | inside |", "|---|---|---|---|---|"]
    for r in rows:
        if r["molar"]:
            first_upper = r["fdi"] in (16, 26)
            inside = ("yes" if lo <= r["bracket_to_cr_mm"] <= hi else "no") if first_upper else "-"
            lines.append(f"| {r['fdi']} {r['type']} | {r['bracket_to_cr_mm']:.2f} | {r['rule_bracket_to_cr_mm']:.2f} | "
                         f"{f'{lo:.2f}-{hi:.2f}' if first_upper else '(other molar)'} | {inside} |")
    return "\n".join(lines)


def rotation_rows(tooth, mf_mm=MF_RANGE_MM) -> list[dict]:
    """Per M/F (mm): where a lingual force at the bracket and a couple opposing its tipping turn the
    tooth: the centre of rotation's offset apical of the centre of resistance (mm; inf: translation)
    and its class."""
    s = _root_support(tooth, DEFAULT, DEFAULT.crest_below_cej_mm)
    b = bracket_point(tooth)
    c = s.center_of_resistance
    force = np.array([0.0, 0.0, -1.0])  # N, lingual
    tip = np.cross(b - c, force)  # the force's moment about the centre of resistance
    unit = tip / np.linalg.norm(tip)
    to_apex = float(c[1] - tooth.apex[1])
    rows = []
    for mf in mf_mm:
        y = s.center_of_rotation_on_axis(force, b, -unit * mf)  # a couple of mf N*mm against the tipping
        x = float(c[1] - y) if np.isfinite(y) else np.inf
        rows.append({"mf_mm": mf, "apical_of_cr_mm": x, "class": rotation_class(x, to_apex)})
    return rows


def rotation_crossings(tooth) -> dict:
    """M/F (mm) at which the centre of rotation reaches the apex (controlled tipping) and at which the
    tooth translates (no tipping), for a lingual force at the bracket: roots of the tipping per mm of
    travel, which is a smooth function of M/F."""
    from scipy.optimize import brentq

    s = _root_support(tooth, DEFAULT, DEFAULT.crest_below_cej_mm)
    b, c = bracket_point(tooth), s.center_of_resistance
    force = np.array([0.0, 0.0, -1.0])
    unit = np.cross(b - c, force)
    unit /= np.linalg.norm(unit)
    to_apex = float(c[1] - tooth.apex[1])

    def inverse_offset(mf: float) -> float:  # 1 / (mm of the centre of rotation apical of the centre)
        t, w = s.motion(force, b, -unit * mf)
        return float(np.cross(w, [0.0, 1.0, 0.0]) @ force) / float((t + np.cross(w, c)) @ force)

    translation = brentq(inverse_offset, 0.0, 30.0)
    apex = brentq(lambda mf: inverse_offset(mf) - 1.0 / to_apex, 0.0, translation)
    return {"fdi": tooth.fdi, "controlled_tipping_mf_mm": apex, "translation_mf_mm": translation,
            "bracket_to_cr_mm": float(b[1] - c[1]), "cr_to_apex_mm": to_apex}


def rotation_class(apical_of_cr_mm: float, cr_to_apex_mm: float, apex_tolerance_mm: float = 1.5) -> str:
    """The classical movement a centre of rotation `apical_of_cr_mm` (mm apical of the centre of
    resistance) makes, for a tooth `cr_to_apex_mm` from centre to apex."""
    x = apical_of_cr_mm
    if not np.isfinite(x) or abs(x) > 100.0:
        return "translation"
    if x < 0:
        return "root movement"
    if x < cr_to_apex_mm - apex_tolerance_mm:
        return "uncontrolled tipping"
    return "controlled tipping"


def rotation_table(columns: dict[str, list[dict]]) -> str:
    """Markdown: M/F rows, one pair of columns (offset, class) per tooth named in `columns`."""
    names = list(columns)
    head = "| M/F mm | " + " | ".join(f"{n}: CRot mm apical of CR | {n}: class" for n in names) + " |"
    lines = [head, "|---|" + "---|---|" * len(names)]
    for i, mf in enumerate(MF_RANGE_MM):
        cells = []
        for n in names:
            r = columns[n][i]
            x = r["apical_of_cr_mm"]
            cells += ["inf" if not np.isfinite(x) else f"{x:.2f}", r["class"]]
        lines.append(f"| {mf:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _metrics_of(case) -> dict:
    """metrics.json's figures of a whole run of `case` in this process (`RunReport`)."""
    import warnings

    from orthosim.movement import MovementModel, simulate
    from orthosim.movement.report import RunReport

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        model = MovementModel.build(case)
        report = RunReport(model, case.detector)
        for record in simulate(model):
            report.add(record)
        return report.metrics()


def spread_rows(real_case_path, folder) -> list[dict]:
    """Real-jaw `real_case_path` on its CBCT teeth and on the same crowns with estimated roots (both
    arches written as labelled scans into `folder`, `orthosim_bench.scanarch`): per tooth that moves
    in either, moved mm with real roots, with estimated ones and the estimated run's range."""
    import tomllib
    from pathlib import Path

    from orthosim.exchange.case import load_case
    from orthosim_bench.scanarch import write_labelled_arch

    real_case = load_case(real_case_path)
    real = _metrics_of(real_case)
    folder = Path(folder)
    upper = write_labelled_arch(real_case.build_dentition(), "upper", folder, "p26")
    lower = write_labelled_arch(real_case.build_dentition(), "lower", folder, "p26")
    data = tomllib.loads(Path(real_case_path).read_text())
    loads = "".join(f"\n[[loads]]\nteeth = {ld['teeth']}\nforce_cN = {ld['force_cN']}\ndirection = \"{ld['direction']}\"\n"
                    f"movement = \"{ld.get('movement', 'auto')}\"\n" for ld in data["loads"])
    t = data["treatment"]
    text = (f'[case]\nname = "estimated roots"\n\n[model]\nkind = "labelled-scan"\nupper = "{upper.name}"\n'
            f'lower = "{lower.name}"\n\n[treatment]\nextractions = {t["extractions"]}\nduration_days = {t["duration_days"]}\n'
            f'step_days = {t["step_days"]}\ndetector = "{t["detector"]}"\n\n[wire]\ntype = "{data["wire"]["type"]}"\n{loads}')
    (folder / "case.toml").write_text(text)
    est = _metrics_of(load_case(folder / "case.toml"))
    rows = []
    for n in sorted(int(k) for k in real["teeth"]):
        r, e = real["teeth"][str(n)], est["teeth"].get(str(n))
        if e is None or "moved_mm_range" not in e:  # not a moving tooth (a lower one the hinge only carries)
            continue
        low, high = e["moved_mm_range"]
        rows.append({"fdi": n, "real_mm": r["moved_mm"], "estimated_mm": e["moved_mm"], "low_mm": low, "high_mm": high,
                     "inside": low - 1e-6 <= r["moved_mm"] <= high + 1e-6})
    return rows


def spread_table(rows: list[dict]) -> str:
    """Markdown of `spread_rows`."""
    lines = ["| tooth | moved, real roots mm | moved, estimated roots mm | range over plausible roots mm | real inside |",
             "|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['fdi']} | {r['real_mm']:.2f} | {r['estimated_mm']:.2f} | {r['low_mm']:.2f}-{r['high_mm']:.2f} | "
                     f"{'yes' if r['inside'] else 'no'} |")
    return "\n".join(lines)


def mechanics_timings(case_path) -> dict:
    """`orthosim bench`'s "mechanics" record: the ligament of the largest real tooth (a parametric
    lower molar refined past 40k triangles without the shared data) and the step with the ligament
    against the literature rule on `case_path`."""
    import trimesh

    from orthosim.exchange.case import load_case
    from orthosim.model.parametric import parametric_dentition

    real = _real_dentition()
    if real is not None:
        tooth, source = largest_tooth(real), "real (Open-Full-Jaw patient 26)"
    else:
        tooth = parametric_dentition("smooth").teeth[36]
        while len(tooth.mesh.faces) < 40_000:
            mesh = tooth.mesh.subdivide()
            tooth = replace(tooth, mesh=mesh, face_part=np.repeat(tooth.face_part, 4))
        source = "parametric lower first molar, subdivided"
    stiffness = {**stiffness_timing(tooth), "source": source}
    return {"stiffness": stiffness, "step": step_timing(load_case(case_path)), "load_avg_1min": _load()}


def _load() -> float:
    import os

    return os.getloadavg()[0]


def summary_line(record: dict) -> str:
    """The line `orthosim bench` prints for the "mechanics" record."""
    s, st = record["stiffness"], record["step"]
    return (f"ligament: {s['ms']:.1f} ms for a {s['triangles']}-triangle tooth (target < {s['target_ms']:.0f} ms); "
            f"step {st['ligament_ms']:.1f} ms against the rule's {st['literature_ms']:.1f} ms, ratio {st['ratio']:.2f} "
            f"(target <= {st['target_ratio']:.2f}); from the same states: step {st['same_states']['step']['ratio']:.2f}, "
            f"forces and motions {st['same_states']['forces_motions']['ratio']:.2f} ("
            f"load {record['load_avg_1min']:.1f})")


def _markdown() -> str:
    """Every table, with the real teeth where ../shared/data has them."""
    from orthosim.model.parametric import parametric_dentition

    parts = []
    parametric = parametric_dentition("smooth")
    columns = {"parametric 11": rotation_rows(parametric.teeth[11])}
    real = _real_dentition()
    if real is not None:
        rows = resistance_rows(real)
        parts += ["## Centre of resistance, 31 real teeth (patient 26)", resistance_table(rows), "", molar_table(rows), ""]
        columns["real 11"] = rotation_rows(real.teeth[11])
        columns["real 21"] = rotation_rows(real.teeth[21])
        parts += ["## Largest real tooth: ligament time", str(stiffness_timing(largest_tooth(real))), ""]
    prow = resistance_rows(parametric)
    parts += ["## Centre of resistance, parametric teeth", resistance_table(prow), "", molar_table(prow), ""]
    parts += ["## Centre of rotation against M/F (lingual force at the bracket)", rotation_table(columns), ""]
    teeth = [("parametric", parametric.teeth[11])] + ([] if real is None else [("real", real.teeth[11]), ("real", real.teeth[21])])
    parts += ["| tooth | bracket to CR mm | CR to apex mm | M/F at the apex (controlled tipping) mm | M/F of translation mm |",
              "|---|---|---|---|---|"]
    for name, tooth in teeth:
        x = rotation_crossings(tooth)
        parts.append(f"| {name} {tooth.fdi} | {x['bracket_to_cr_mm']:.2f} | {x['cr_to_apex_mm']:.2f} | "
                     f"{x['controlled_tipping_mf_mm']:.2f} | {x['translation_mf_mm']:.2f} |")
    return "\n".join(parts)


def _real_dentition():
    """Patient 26's 31 teeth through the shipped case (the dentition cache), or None without the data."""
    from pathlib import Path

    from orthosim.errors import OrthosimError
    from orthosim.exchange.case import load_case

    try:
        return load_case(Path(__file__).resolve().parents[1] / "cases" / "open_full_jaw_patient26.toml").build_dentition()
    except OrthosimError:  # no shared data here: the parametric tables only
        return None


if __name__ == "__main__":
    import sys

    if sys.argv[1:2] == ["spread"]:  # python -m orthosim_bench.mechanics spread CASE FOLDER
        print(spread_table(spread_rows(sys.argv[2], sys.argv[3])))
    else:
        print(_markdown())
