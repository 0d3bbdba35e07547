"""The SHA-256 of a file: how a run folder, a staging and a report tell that a file is the one they
were made from (a case file edited since, an output changed by hand)."""

from __future__ import annotations

import hashlib
from pathlib import Path


def file_sha256(path: str | Path) -> str:
    """Hex SHA-256 of the file's bytes."""
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()
