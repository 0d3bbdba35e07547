"""Where the real-tooth data shared beside the repository lives, found once for code and tests.

orthosim never ships patient data (its licence forbids it). Evaluations and tests read it from
`$ORTHOSIM_SHARED_DATA` when that is set, else from `shared/data/` beside the repository
(`<repository>/../shared/data`). Callers check that the folder exists and skip or say so when it
does not; nothing here fails.
"""

from __future__ import annotations

import os
from pathlib import Path

OPEN_FULL_JAW = "open-full-jaw-patient26"


def shared_data_dir() -> Path:
    """The shared data folder: `$ORTHOSIM_SHARED_DATA`, else `../shared/data` from the repository root."""
    env = os.environ.get("ORTHOSIM_SHARED_DATA")
    if env:
        return Path(env).expanduser()
    return Path(__file__).resolve().parents[2].parent / "shared" / "data"


def open_full_jaw_dir(arch: str = "maxilla") -> Path:
    """One arch's folder of the Open-Full-Jaw patient 26 set ("maxilla" or "mandible")."""
    return shared_data_dir() / OPEN_FULL_JAW / arch
