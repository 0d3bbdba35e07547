"""The centre-of-resistance and M/F rows, predicted by each tooth's periodontal ligament from its root alone.

Nothing here is fitted: a tooth's ligament (`orthosim.mechanics.ligament.root_support`, a thin
elastic layer over the root surface apical of the alveolar crest, with the published default
modulus, Poisson's ratio, thickness and crest depth) gives the root's 6x6 stiffness, and from it
the centre of resistance (the least-squares point where a force translates the tooth) and the
instantaneous motion of any force system. The rows then read off what the sources measured:
- where the centre of resistance sits: its depth below the crest as a share of the embedded root
  (crest to apex), or, for a molar, how far it lies gingival and lingual of the bracket (the
  centre of the buccal surface at mid-crown, `biomechanics.bracket_point`);
- for a lingual force at an incisor's bracket with a couple opposing its tipping, the M/F (mm)
  that puts the centre of rotation at the apex (controlled tipping) or sends it to infinity
  (translation). The centre of rotation is the point of the long axis (through the centre of
  resistance) that does not move along the force.
Each function returns (value, one-line note, Curve). Tooth frame: origin at the CEJ, +y toward the
crown, +z labial; mm, N, N*mm.
"""

from __future__ import annotations

import numpy as np

from orthosim.evidence.models import EvidenceModels
from orthosim.evidence.table import Curve, EvidenceRow
from orthosim.mechanics.biomechanics import bracket_point
from orthosim.mechanics.ligament import RootSupport

LINGUAL_FORCE_N = np.array([0.0, 0.0, -1.0])  # 1 N toward the tongue (the motion is linear in the load)
MF_RANGE_MM = (0.0, 14.0)  # the M/F the page plots, and the classical table spans


def _bars(values: dict[int, float], label: str) -> Curve:
    return Curve(np.arange(len(values), dtype=float), np.array(list(values.values())), "tooth (FDI)", label, "bars",
                 tuple(str(t) for t in values))


def _teeth(bench: EvidenceModels, row: EvidenceRow) -> list[int]:
    dent = bench.dentition(row.model)
    return [t for t in row.setup["teeth"] if t in dent.teeth]


def cr_share_of_embedded_root(bench: EvidenceModels, model: str, fdi: int) -> float:
    """% : the centre of resistance's depth below the crest over the embedded root's length (crest to apex)."""
    tooth, support = bench.dentition(model).teeth[fdi], bench.support(model, fdi)
    crest = support.crest_below_cej_mm
    return float(100.0 * (-crest - support.center_of_resistance[1]) / (tooth.root_length - crest))


def measure_cr_share(bench: EvidenceModels, row: EvidenceRow):
    shares = {t: cr_share_of_embedded_root(bench, row.model, t) for t in _teeth(bench, row)}
    crest = bench.ligament.crest_below_cej_mm
    note = (f"mean over {len(shares)} teeth of the ligament's centre of resistance, below a crest {crest:g} mm "
            f"under the CEJ, over the embedded root")
    return float(np.mean(list(shares.values()))), note, _bars(shares, "CR below the crest (% of the embedded root)")


def _bracket_offsets(bench: EvidenceModels, row: EvidenceRow) -> dict[int, np.ndarray]:
    """Per tooth: the bracket minus the centre of resistance (3,) mm, tooth frame."""
    dent = bench.dentition(row.model)
    return {t: bracket_point(dent.teeth[t]) - bench.support(row.model, t).center_of_resistance for t in _teeth(bench, row)}


def measure_cr_below_bracket(bench: EvidenceModels, row: EvidenceRow):
    depth = {t: float(d[1]) for t, d in _bracket_offsets(bench, row).items()}
    note = f"mean over teeth {', '.join(map(str, depth))}: the ligament's centre of resistance, along the long axis below the bracket"
    return float(np.mean(list(depth.values()))), note, _bars(depth, "CR gingival of the buccal surface centre (mm)")


def measure_cr_lingual_of_bracket(bench: EvidenceModels, row: EvidenceRow):
    lingual = {t: float(d[2]) for t, d in _bracket_offsets(bench, row).items()}
    note = f"mean over teeth {', '.join(map(str, lingual))}: the ligament's centre of resistance, lingual of the bracket"
    return float(np.mean(list(lingual.values()))), note, _bars(lingual, "CR lingual of the buccal surface centre (mm)")


# ---------------------------------------------------------------------------------------------
# M/F: a lingual force at the bracket and a couple opposing the tipping it makes


def _tipping_axis(support: RootSupport, bracket: np.ndarray) -> np.ndarray:
    moment = np.cross(bracket - support.center_of_resistance, LINGUAL_FORCE_N)
    return moment / np.linalg.norm(moment)


def rotation_centre_mm(support: RootSupport, bracket: np.ndarray, m_over_f_mm: float) -> float:
    """mm from the centre of resistance to the centre of rotation along the long axis (occlusal
    positive; inf: translation) under 1 N lingual at `bracket` and a couple of M/F N*mm opposing
    its tipping: the point (c_x, y, c_z) whose velocity has no component along the force."""
    c = support.center_of_resistance
    axis = _tipping_axis(support, bracket)
    t, w = support.motion(LINGUAL_FORCE_N, bracket, -axis * m_over_f_mm)
    unit = LINGUAL_FORCE_N
    at_cr = float((t + np.cross(w, c)) @ unit)
    per_mm = float(np.cross(w, [0.0, 1.0, 0.0]) @ unit)  # along the force, per mm up the axis
    return float("inf") if abs(per_mm) < 1e-12 * max(abs(at_cr), 1e-300) else -at_cr / per_mm


def turning(support: RootSupport, bracket: np.ndarray, m_over_f_mm: float) -> float:
    """rad per N the force system turns the tooth, positive the way the force alone tips it."""
    axis = _tipping_axis(support, bracket)
    _, w = support.motion(LINGUAL_FORCE_N, bracket, -axis * m_over_f_mm)
    return float(w @ axis)


def _bisect(g, lo: float, hi: float) -> float:
    a = g(lo)
    if a * g(hi) > 0:
        return float("nan")
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if (g(mid) > 0) == (a > 0):
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def mf_bracket(bench: EvidenceModels, row: EvidenceRow) -> tuple[RootSupport, np.ndarray, np.ndarray]:
    """(the tooth's ligament, its bracket (3,) mm, its apex (3,) mm): the tooth's own bracket, or one
    `bracket_above_cr_mm` occlusal of the centre of resistance on the labial surface (the source's)."""
    s = row.setup
    tooth = bench.dentition(row.model).teeth[s["tooth"]]
    support = bench.support(row.model, s["tooth"])
    bracket = bracket_point(tooth)
    if "bracket_above_cr_mm" in s:
        bracket = np.array([bracket[0], support.center_of_resistance[1] + float(s["bracket_above_cr_mm"]), bracket[2]])
    return support, bracket, np.asarray(tooth.apex, float)


def movement_class(support: RootSupport, bracket: np.ndarray, apex: np.ndarray, m_over_f_mm: float,
                   apex_tolerance_mm: float = 0.5) -> str:
    """The classical name of the motion: 'uncontrolled tipping' (centre of rotation between the
    centre of resistance and the apex), 'controlled tipping' (at the apex or beyond, within
    `apex_tolerance_mm` of it or apical of it), 'translation' (no turning), 'root movement' (the
    centre of rotation on the crown side)."""
    y = rotation_centre_mm(support, bracket, m_over_f_mm)
    apex_below = float(support.center_of_resistance[1] - apex[1])
    if not np.isfinite(y):
        return "translation"
    if y > 0:
        return "root movement"
    return "controlled tipping" if -y >= apex_below - apex_tolerance_mm else "uncontrolled tipping"


def mf_curve(support: RootSupport, bracket: np.ndarray, apex: np.ndarray) -> Curve:
    mf = np.linspace(*MF_RANGE_MM, 141)
    y = np.array([rotation_centre_mm(support, bracket, x) for x in mf])
    y[~np.isfinite(y) | (np.abs(y) > 40.0)] = np.nan  # off to infinity at translation: a gap, not a line
    lever = float(bracket[1] - support.center_of_resistance[1])
    return Curve(mf, y, "M/F at the bracket (mm)", "centre of rotation (mm, + occlusal of the CR)",
                 marks={"apex": float(apex[1] - support.center_of_resistance[1]), "bracket": lever})


def measure_mf_center(bench: EvidenceModels, row: EvidenceRow):
    support, bracket, apex = mf_bracket(bench, row)
    lever = float(bracket[1] - support.center_of_resistance[1])
    if row.setup["center"] == "apex":
        target = float(apex[1] - support.center_of_resistance[1])
        value = _bisect(lambda x: rotation_centre_mm(support, bracket, x) - target, 0.0, max(lever - 0.05, 0.1))
        what = "at the apex (controlled tipping)"
    else:
        value = _bisect(lambda x: turning(support, bracket, x), 0.0, 30.0)
        what = "at infinity (translation)"
    note = (f"tooth {row.setup['tooth']}, bracket {lever:.1f} mm occlusal of the ligament's centre of resistance: "
            f"the M/F putting the centre of rotation {what}")
    return value, note, mf_curve(support, bracket, apex)
