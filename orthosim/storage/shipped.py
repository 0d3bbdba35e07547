"""Cache entries shipped inside the package, so that a fresh install's first run of a shipped case
loads its teeth and sphere trees instead of building them (seconds of CPU, most of a cold demo).

`orthosim/storage/shipped/<kind>/<key>.npz` holds entries exactly as the on-disk caches write them
(`dentitions/`: `orthosim.model.dentition_cache`; `spheretrees/`: `orthosim.spheretree.cache`),
for the parametric model of the paper's cases. A cache that misses in the user's folder looks here
for the same file name, and reads what it finds through its own loader, so a shipped entry is
checked as every cache entry is (format, kind, key, SHA-256, contents) and a damaged one is
rebuilt with a warning. Keys carry the builders' source digests: after a change to a builder, the
entries no longer match and runs build as before, until `python tools/shipped_cache.py` writes them
again (`tests/storage/test_shipped_entries.py` fails until then). Nothing is ever written here at run time.
"""

from __future__ import annotations

from pathlib import Path

SHIPPED_DIR = Path(__file__).resolve().parent / "shipped"
KINDS = ("dentitions", "spheretrees")


def shipped_entry(kind: str, name: str) -> Path | None:
    """The shipped entry of `kind` (one of KINDS) with the file name `name`, or None when none ships."""
    if kind not in KINDS:
        raise ValueError(f"shipped cache entries are of kind {', '.join(KINDS)}, not {kind!r}")
    path = SHIPPED_DIR / kind / name
    return path if path.is_file() else None
