"""The digest of some modules' source text, for cache keys: code that was edited never gets a result
that its older self stored (`orthosim.model.dentition_cache`, `orthosim.spheretree.cache`)."""

from __future__ import annotations

import hashlib
from collections.abc import Iterable
from pathlib import Path


def source_digest(folder: Path, modules: Iterable[str]) -> str:
    """Hex SHA-256 over each module's name and the bytes of `folder/<name>.py`, in the order given."""
    h = hashlib.sha256()
    for name in modules:
        h.update(name.encode())
        h.update((folder / f"{name}.py").read_bytes())
    return h.hexdigest()
