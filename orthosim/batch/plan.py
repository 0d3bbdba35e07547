"""Planning a batch: which runs a `orthosim batch` command asks for, each checked before any work.

A batch is every case found (a folder means its `*.toml`, sorted) times every asked detector times
every `--set KEY=V1,V2` value (the Cartesian product). KEY is a dotted path into the case file:
`treatment.step_days`, `simulation.force_share`, `loads.0.force_cN` (a number indexes an array of
tables). Each combination is a `Variant`: the exact TOML text that will run (written as
`DIR/<run-id>/case.toml`, so every run can be reproduced alone with `orthosim run`), validated
whole with `orthosim.exchange.case.load_case` here, so that a bad value in the sweep stops the batch before
anything is simulated, with one line naming the variant and the field.
"""

from __future__ import annotations

import hashlib
import itertools
import re
import tempfile
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import tomli_w

from orthosim.exchange.case import DETECTORS, load_case
from orthosim.errors import CaseError, OrthosimError


class BatchError(OrthosimError):
    """A batch request is malformed (an option, a sweep, a case of the sweep) or its folder is busy."""


@dataclass(frozen=True)
class Sweep:
    """One `--set KEY=V1,V2,...`: a dotted path into the case file and the values it takes."""

    key: str
    texts: tuple[str, ...]  # as written, for run ids and the batch table
    values: tuple[Any, ...]  # as TOML reads them: numbers, booleans, text, arrays


@dataclass(frozen=True)
class Variant:
    """One run of the batch: the case text that runs and where it came from."""

    run_id: str
    source: Path  # the case file the variant was made from
    detector: str  # the detector that runs (asked with --detector, else the variant's own)
    settings: tuple[tuple[str, str], ...]  # (KEY, value as written) per --set
    case_text: str  # TOML, written to DIR/<run_id>/case.toml
    case_name: str
    steps: int
    model_key: str  # equal for variants whose dentition (and so sphere trees) is the same

    @property
    def case_sha256(self) -> str:
        return hashlib.sha256(self.case_text.encode()).hexdigest()

    @property
    def label(self) -> str:
        """How the variant is named in messages: the detector and the swept values."""
        return ", ".join([f"detector={self.detector}", *(f"{k}={v}" for k, v in self.settings)])


def find_cases(paths: Sequence[str | Path]) -> list[Path]:
    """The case files named: files as given, folders as their *.toml (sorted); each once."""
    found: list[Path] = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            inside = sorted(p for p in path.glob("*.toml") if p.is_file())
            if not inside:
                raise BatchError(path, None, "holds no *.toml case files", "give case files or a folder of them")
            found.extend(inside)
        elif path.is_file():
            found.append(path)
        else:
            raise BatchError(path, None, "no such case file or folder", "check the path; shipped cases are in cases/")
    unique: dict[Path, Path] = {}
    for p in found:
        unique.setdefault(p.resolve(), p)
    return list(unique.values())


def _split_top_level(text: str) -> list[str]:
    """Split on commas outside brackets and quotes, so `[1, 0, 0],[0, 1, 0]` is two values."""
    parts, depth, quote, start = [], 0, None, 0
    for i, ch in enumerate(text):
        if quote:
            if ch == quote:
                quote = None
        elif ch in "\"'":
            quote = ch
        elif ch in "[{":
            depth += 1
        elif ch in "]}":
            depth -= 1
        elif ch == "," and depth == 0:
            parts.append(text[start:i])
            start = i + 1
    parts.append(text[start:])
    return [p.strip() for p in parts]


def _toml_value(text: str) -> Any:
    """A value as TOML reads it (50, 2.5, true, [1, 0, 0], "x"); bare words are text (paper)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_sweep(text: str) -> Sweep:
    """`KEY=V1,V2,...` -> Sweep; BatchError naming the option when malformed."""
    key, sep, values = text.partition("=")
    key = key.strip()
    where = f"--set {text}"
    if not sep or not key or not values.strip():
        raise BatchError(where, None, "is not KEY=V1,V2,...", "write e.g. --set treatment.step_days=1,2,5")
    if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*(\.([A-Za-z_][A-Za-z0-9_]*|\d+))*", key):
        raise BatchError(where, None, f"{key!r} is not a dotted path into the case file",
                         "write e.g. loads.0.force_cN or simulation.force_share")
    texts = tuple(_split_top_level(values))
    if any(not t for t in texts):
        raise BatchError(where, None, "has an empty value", "remove the extra comma")
    if len(set(texts)) != len(texts):
        raise BatchError(where, None, "lists a value twice", "list each value once")
    return Sweep(key, texts, tuple(_toml_value(t) for t in texts))


def set_path(data: dict, key: str, value: Any) -> None:
    """Set the dotted `key` in the parsed case; a table on the way is made when absent, an array
    index must exist. KeyError with the reason when the path does not fit the case."""
    parts = key.split(".")
    node: Any = data
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        here = ".".join(parts[: depth + 1])
        if isinstance(node, list):
            if not part.isdigit():
                raise KeyError(f"{'.'.join(parts[:depth])} is an array: index it with a number, e.g. {'.'.join(parts[:depth])}.0")
            i = int(part)
            if i >= len(node):
                raise KeyError(f"{here}: the case has {len(node)} entries in {'.'.join(parts[:depth])} (0 to {len(node) - 1})")
            if last:
                node[i] = value
            else:
                node = node[i]
        elif isinstance(node, dict):
            if part.isdigit():
                raise KeyError(f"{'.'.join(parts[:depth]) or 'the case'} is a table, not an array: {part} is no key")
            if last:
                node[part] = value
            elif part not in node and parts[depth + 1].isdigit():
                raise KeyError(f"{here}.{parts[depth + 1]}: the case has no {here}")
            else:
                node = node.setdefault(part, {})
        else:
            raise KeyError(f"{'.'.join(parts[:depth])} is a value, not a table: it has no {part}")


_UNSAFE = re.compile(r"[^A-Za-z0-9._=+-]+")
_MAX_ID = 120


def _run_id(stem: str, detector: str, settings: Sequence[tuple[str, str]]) -> str:
    parts = [stem, detector, *(f"{k}={v}" for k, v in settings)]
    rid = _UNSAFE.sub("_", "__".join(parts)).strip("._") or "run"
    if len(rid) > _MAX_ID:  # file names have limits; the hash keeps long ids apart
        rid = rid[: _MAX_ID - 9] + "-" + hashlib.sha256(rid.encode()).hexdigest()[:8]
    return rid


def _model_key(data: dict) -> str:
    model = data.get("model", {})
    return hashlib.sha256(tomli_w.dumps({"model": model}).encode()).hexdigest()


def _read_case_data(path: Path) -> dict:
    """The case as TOML data, its model folder made absolute (the variant file lives elsewhere)."""
    case = load_case(path)  # the source itself must be a valid case (one-line error otherwise)
    with path.open("rb") as fh:
        data = tomllib.load(fh)
    model = data.get("model")
    if isinstance(model, dict) and "folder" in model and case.model.folder is not None:
        model["folder"] = str(case.model.folder)  # resolved against the source's folder by load_case
    return data


def plan_batch(cases: Sequence[str | Path], detectors: Sequence[str] = (), sweeps: Sequence[Sweep] = ()) -> list[Variant]:
    """Every variant of the batch, each validated whole; BatchError (one line) on the first bad one.

    `detectors` empty means each variant's own detector. Order: case, then detector, then the
    sweeps' values in the order given (the first --set varies slowest).
    """
    for d in detectors:
        if d not in DETECTORS:
            raise BatchError("--detector", None, f"unknown detector {d!r}", f"use one of: {', '.join(DETECTORS)}")
    keys = [s.key for s in sweeps]
    for k in keys:
        if keys.count(k) > 1:
            raise BatchError(f"--set {k}", None, "is given twice", "give each KEY once, with all its values")
    variants: list[Variant] = []
    with tempfile.TemporaryDirectory(prefix="orthosim-batch-plan-") as tmp:
        check_file = Path(tmp) / "case.toml"
        for source in find_cases(cases):
            base = _read_case_data(source)
            for combo in itertools.product(*(tuple(zip(s.texts, s.values)) for s in sweeps)):
                data = tomllib.loads(tomli_w.dumps(base))  # a deep copy
                settings = tuple((s.key, text) for s, (text, _) in zip(sweeps, combo))
                label = ", ".join(f"{k}={v}" for k, v in settings) or "as written"
                for s, (_, value) in zip(sweeps, combo):
                    try:
                        set_path(data, s.key, value)
                    except KeyError as err:
                        raise BatchError(f"{source} [{label}]", f"--set {s.key}", str(err.args[0]),
                                         "use a path the case file has (see README, Case files)") from None
                text = tomli_w.dumps(data)
                check_file.write_text(text)
                try:
                    case = load_case(check_file)
                except CaseError as err:
                    raise BatchError(f"{source} [{label}]", err.field, err.problem, err.fix) from None
                for detector in detectors or (case.detector,):
                    variants.append(Variant(_run_id(source.stem, detector, settings), source, detector, settings,
                                            text, case.name, case.steps, _model_key(data)))
    return _unique_ids(variants)


def _unique_ids(variants: list[Variant]) -> list[Variant]:
    """Two cases of the same name in different folders would share a run id: add the source's hash."""
    import dataclasses

    counts: dict[str, int] = {}
    for v in variants:
        counts[v.run_id] = counts.get(v.run_id, 0) + 1
    out = []
    for v in variants:
        if counts[v.run_id] > 1:
            tag = hashlib.sha256(f"{v.source.resolve()}|{v.case_text}|{v.detector}".encode()).hexdigest()[:8]
            v = dataclasses.replace(v, run_id=f"{v.run_id}-{tag}")
        out.append(v)
    return out
