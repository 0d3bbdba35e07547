"""The case files orthosim ships (`CASES_DIR`: the checkout's `cases/`, or `orthosim/cases/` in an
installed wheel), listed and copied by `orthosim cases` (`orthosim.cli.cases`), so that a user who installed orthosim with
pip can see what there is and start from a copy of their own.

Each case is read with the same reader as `orthosim run` (`load_case`), so the list shows what a
run would see; a case whose teeth come from the Open-Full-Jaw data is marked, because its mesh
folders are named relative to the case file and the data does not travel with orthosim.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

from orthosim.errors import CaseError


@dataclass(frozen=True)
class ShippedCase:
    """One shipped case file: `name` (file stem), its path, title, model kind and simulated days."""

    name: str
    path: Path
    title: str
    model_kind: str
    duration_days: float

    @property
    def needs_data(self) -> bool:
        """True when the teeth are read from mesh folders outside orthosim (the Open-Full-Jaw data)."""
        return self.model_kind != "parametric"


def shipped_cases() -> list[ShippedCase]:
    """Every shipped case, sorted by name (read from the TOML text; nothing is built)."""
    from orthosim.exchange.case import CASES_DIR

    cases = []
    for path in sorted(CASES_DIR.glob("*.toml")):
        data = tomllib.loads(path.read_text())
        cases.append(ShippedCase(name=path.stem, path=path, title=str(data.get("case", {}).get("name", path.stem)),
                                 model_kind=str(data.get("model", {}).get("kind", "parametric")),
                                 duration_days=float(data.get("treatment", {}).get("duration_days", 0.0))))
    return cases


def find_shipped_case(name: str) -> ShippedCase:
    """The shipped case called `name` (file stem, with or without .toml); CaseError naming the choices."""
    stem = name[:-5] if name.endswith(".toml") else name
    cases = {c.name: c for c in shipped_cases()}
    if stem not in cases:
        raise CaseError(name, None, "is not a shipped case",
                        f"give one of: {', '.join(cases)} (orthosim cases lists them)")
    return cases[stem]


def copy_shipped_case(name: str, dest: Path) -> Path:
    """Copy shipped case `name` into folder `dest` (or to the file `dest` when it ends in .toml).

    Never overwrites: an existing target, or an existing `dest` that is not a folder (whatever its
    suffix), is a CaseError naming it; the copy is written beside the target and linked in under
    its name, which fails rather than replace a file that appeared meanwhile. Returns the path written.
    """
    import os
    import tempfile

    case = find_shipped_case(name)
    dest = Path(dest)
    if dest.exists() and not dest.is_dir():
        raise CaseError(dest, None, "already exists and is not a folder: a copy never overwrites",
                        "give a folder, or a new file name ending in .toml")
    target = dest if str(dest).endswith(".toml") else dest / case.path.name
    if target.exists():
        raise CaseError(target, None, "already exists", "give another folder or file name, or remove it first")
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError:
        raise CaseError(target.parent, None, "cannot be made a folder (a file stands in its path)",
                        "give a folder, or a new file name ending in .toml") from None
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=f".{target.name}.", suffix=".tmp")
    mask = os.umask(0)
    os.umask(mask)
    try:
        os.fchmod(fd, 0o666 & ~mask)  # mkstemp makes 0600; a copied case is shared like any written file
        with os.fdopen(fd, "w") as f:
            f.write(case.path.read_text())
        os.link(tmp, target)  # fails on an existing name: never replaces it
    except FileExistsError:
        raise CaseError(target, None, "already exists", "give another folder or file name, or remove it first") from None
    finally:
        os.unlink(tmp)
    return target
