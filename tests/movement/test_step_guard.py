"""Guard: every shipped case with every detector yields the same step records, bit for bit.

Each case in `cases/` that the simulator runs (the parametric ones; the real-jaw ones under
`real_data`) is simulated for a bounded number of steps with each detector, and every field of
every `StepRecord` is reduced to a digest of its exact values (floats and arrays by their bytes,
so poses are compared bit for bit). The digests are compared with `tests/golden/step_records.json`.

A change that is meant to alter results (a fixed bug, a new model) regenerates the file, and its
commit says why:

    ORTHOSIM_REGEN_STEP_GUARD=1 .venv/bin/python -m pytest tests/movement/test_step_guard.py -q

(only the cases that run are rewritten; the others keep their stored digests).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

from orthosim.exchange.case import load_case
from orthosim.collision import DETECTORS
from orthosim.movement import MovementModel, simulate

ROOT = Path(__file__).resolve().parents[2]
GOLDEN = Path(__file__).resolve().parents[1] / "golden" / "step_records.json"
REGEN = os.environ.get("ORTHOSIM_REGEN_STEP_GUARD") == "1"

# the models are built once for the module (`_models`): the module is scheduled first (tests/conftest.py)
pytestmark = pytest.mark.heavy_setup

PARAMETRIC_STEPS = 20  # at most: the paper's cases whole (their collisions come from step 2 to 19)
REAL_STEPS = 2  # a real jaw's step costs seconds
PARAMETRIC = ("case1_first_premolar_extraction", "case2_second_premolar_extraction",
              "case3_incisor_space_closure", "normal_occlusion",
              # the evidence table's treatments (issue 33), on the clinical rate law
              "canine_retraction_upper", "canine_retraction_upper_reinforced", "canine_retraction_lower",
              "canine_retraction_lower_reinforced", "en_masse_retraction")
REAL = ("open_full_jaw_case1_first_premolar_extraction", "open_full_jaw_case2_second_premolar_extraction",
        "open_full_jaw_case3_diastema", "open_full_jaw_patient26")


def canonical(x) -> str:
    """A string that changes whenever any value in x changes by one bit (floats by their hex form,
    arrays by dtype, shape and bytes); independent of the classes holding the values."""
    if x is None or isinstance(x, (bool, np.bool_, str)):
        return repr(x if not isinstance(x, np.bool_) else bool(x))
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    if isinstance(x, (float, np.floating)):
        return float(x).hex()
    if isinstance(x, np.ndarray):
        a = np.ascontiguousarray(x)
        return f"{a.dtype.str}{a.shape}:{hashlib.sha256(a.tobytes()).hexdigest()}"
    if dataclasses.is_dataclass(x):
        return "(" + ",".join(f"{f.name}={canonical(getattr(x, f.name))}" for f in dataclasses.fields(x)) + ")"
    if isinstance(x, dict):
        items = sorted((canonical(k), canonical(v)) for k, v in x.items())
        return "{" + ",".join(f"{k}:{v}" for k, v in items) + "}"
    if isinstance(x, (set, frozenset)):
        return "{" + ",".join(sorted(canonical(v) for v in x)) + "}"
    if isinstance(x, (list, tuple)):
        return "[" + ",".join(canonical(v) for v in x) + "]"
    raise TypeError(f"no canonical form for {type(x).__name__}")


# fields added to StepRecord after digests were stored, left out where a run leaves them None (a
# run without the bite's closure has no `bite`), so that records which did not change keep their digests
LATER_FIELDS = ("bite",)


def digests(record) -> dict[str, str]:
    """field name -> sha256 (first 16 hex digits) of its canonical form, for one StepRecord."""
    return {f.name: hashlib.sha256(canonical(getattr(record, f.name)).encode()).hexdigest()[:16]
            for f in dataclasses.fields(record) if not (f.name in LATER_FIELDS and getattr(record, f.name) is None)}


_models: dict[str, MovementModel] = {}


def _model(name: str) -> MovementModel:
    if name not in _models:
        _models[name] = MovementModel.build(load_case(ROOT / "cases" / f"{name}.toml"))
    return _models[name]


def _stored() -> dict:
    return json.loads(GOLDEN.read_text()) if GOLDEN.exists() else {}


def _check(name: str, detector: str, steps: int):
    key = f"{name}/{detector}"
    got = [digests(r) for r in simulate(_model(name), detector, steps=steps)]
    if REGEN:
        stored = _stored()
        stored[key] = got
        GOLDEN.parent.mkdir(parents=True, exist_ok=True)
        tmp = GOLDEN.with_suffix(".json.tmp")
        tmp.write_text(json.dumps(dict(sorted(stored.items())), indent=1) + "\n")
        tmp.replace(GOLDEN)
        return
    want = _stored().get(key)
    assert want is not None, f"{GOLDEN.name} has no digests for {key}: regenerate (see this file's docstring)"
    assert len(got) == len(want), f"{key}: {len(got)} records, {len(want)} stored"
    for step, (g, w) in enumerate(zip(got, want)):
        changed = sorted(f for f in set(g) | set(w) if g.get(f) != w.get(f))
        assert not changed, f"{key}: step {step} differs in {', '.join(changed)}"


@pytest.mark.slow
@pytest.mark.parametrize("detector", DETECTORS)
@pytest.mark.parametrize("name", PARAMETRIC)
def test_parametric_case_records_unchanged(name, detector):
    _check(name, detector, min(PARAMETRIC_STEPS, _model(name).case.steps))


@pytest.mark.slow
@pytest.mark.real_data
@pytest.mark.parametrize("detector", DETECTORS)
@pytest.mark.parametrize("name", REAL)
def test_real_jaw_case_records_unchanged(name, detector):
    _check(name, detector, REAL_STEPS)


def test_every_shipped_simulation_case_is_guarded():
    """A case added to cases/ with loads to simulate is added to the guard too (staging cases plan
    aligner stages and are not simulated)."""
    shipped = {p.stem for p in (ROOT / "cases").glob("*.toml") if not p.stem.startswith("staging_")}
    assert shipped == set(PARAMETRIC) | set(REAL)


def test_digest_sees_one_bit():
    """The digest of a pose changes when one float of it moves by one ulp."""
    T = np.eye(4)
    T2 = T.copy()
    T2[0, 3] = np.nextafter(0.0, 1.0)
    assert canonical({11: T}) != canonical({11: T2})
    assert canonical(0.1) != canonical(np.nextafter(0.1, 1.0))
