"""Checksummed, versioned cache entries: the one way orthosim writes what it keeps under `$ORTHOSIM_CACHE`.

Every cache (built dentitions, sphere trees, tree fits) stores an entry as a payload plus a header
in the same file: the entry format (`ENTRY_FORMAT`), what the entry holds (`kind`), which entry it
is (its cache key, so that two entries' files swapped or renamed are told apart) and the SHA-256 of
the payload's content. A payload of named arrays is an .npz (no pickle) with the header as one more
member (`HEADER`); a JSON payload is `{"entry": header, "payload": ...}`. A read verifies the header
before anything is used and raises `DamagedFileError` with the reason on any failure (empty,
truncated, garbage, another format or kind or key, wrong checksum); the cache turns that into one
warning line naming the entry (a `DamagedEntryWarning`) and rebuilds it. A checksum and not just
plausibility checks, because a flipped bit in a vertex gives a finite, plausible, wrong tooth.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import re
import warnings
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from orthosim.errors import DamagedFileError
from orthosim.storage.atomic import atomic_path, write_text

ENTRY_FORMAT = 1  # bump when the header or the digest changes; it is part of every cache key too
HEADER = "__entry__"  # the .npz member holding the header


class DamagedEntryWarning(UserWarning):
    """A cache entry failed its checks and is rebuilt; the message names the entry and the reason."""


def arrays_digest(arrays: Mapping[str, np.ndarray]) -> str:
    """Hex SHA-256 over each array's name, dtype, shape and bytes, in name order."""
    h = hashlib.sha256()
    for name in sorted(arrays):
        a = np.ascontiguousarray(arrays[name])
        h.update(json.dumps([name, a.dtype.str, list(a.shape)]).encode() + b"\0")
        h.update(a.tobytes())
    return h.hexdigest()


def json_digest(payload: Any) -> str:
    """Hex SHA-256 of the payload's canonical JSON text (sorted keys, no spaces)."""
    return hashlib.sha256(json.dumps(payload, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def _header(kind: str, key: str, digest: str) -> dict:
    return {"format": ENTRY_FORMAT, "kind": kind, "key": key, "sha256": digest}


def damaged(path: str | Path, reason: str) -> DamagedFileError:
    """The error a cache reader raises for an entry that cannot be used (the caller rebuilds it)."""
    return DamagedFileError(path, None, reason, "delete it; orthosim rebuilds it")


def _verify(path: Path, header: Any, kind: str, key: str, digest: str) -> None:
    if not isinstance(header, dict):
        raise damaged(path, "its entry header is not a table")
    if header.get("format") != ENTRY_FORMAT:
        raise damaged(path, f"entry format {header.get('format')!r}, this orthosim reads {ENTRY_FORMAT}")
    if header.get("kind") != kind:
        raise damaged(path, f"holds a {header.get('kind')!r} entry where a {kind!r} one was expected")
    if header.get("key") != key:
        raise damaged(path, "holds another entry's content (files swapped or renamed)")
    if header.get("sha256") != digest:
        raise damaged(path, "checksum mismatch: its content changed after it was written")


def write_arrays(path: str | Path, kind: str, key: str, arrays: Mapping[str, np.ndarray]) -> None:
    """Write named arrays and their header as one .npz, atomically."""
    arrays = {name: np.asarray(a) for name, a in arrays.items()}
    if HEADER in arrays:
        raise ValueError(f"{HEADER!r} is the entry header's name")
    header = json.dumps(_header(kind, key, arrays_digest(arrays)))
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays, **{HEADER: np.array(header)})


def read_arrays(path: str | Path, kind: str, key: str) -> dict[str, np.ndarray]:
    """The arrays of an entry written by `write_arrays`, verified.

    Raises FileNotFoundError when there is no entry, `DamagedFileError` when it fails any check.
    """
    path = Path(path)
    try:
        arrays = _read_npz(path)
    except FileNotFoundError:
        raise
    except Exception as err:  # numpy and zipfile raise many types on a damaged file (EOFError, BadZipFile, ...)
        raise damaged(path, f"unreadable ({type(err).__name__}: {' '.join(str(err).split())[:120]})") from None
    raw = arrays.pop(HEADER, None)
    if raw is None or raw.shape != () or raw.dtype.kind != "U":
        raise damaged(path, "has no entry header (not written by this orthosim's cache)")
    try:
        header = json.loads(str(raw))
    except ValueError:
        raise damaged(path, "its entry header is garbage") from None
    _verify(path, header, kind, key, arrays_digest(arrays))
    return arrays


# The header `np.save` writes for a plain array (format 1.0): a dtype string, C order, a shape.
_NPY_HEADER = re.compile(rb"\{'descr': '([<>|][a-zA-Z]\d*)', 'fortran_order': False, 'shape': \(((?:\d+, ?)*\d*)\), \} *\n")


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    """The members of an .npz as arrays, as `np.load` gives them (writable, the same dtype, shape
    and bytes). Why not `np.load`: a dentition and its trees are about 700 small members, and numpy
    parses each member's header with `ast.literal_eval` (0.12 of 0.17 s of a warm start's cache
    reads, 2026-11-29). A member in the format `np.save` writes is read here; anything else (another
    format version, a structured dtype, a length that does not add up) goes to numpy's own reader,
    which raises on what it cannot read. The zip's CRC of each member is checked by `zipfile`."""
    arrays = {}
    with zipfile.ZipFile(path) as zf:
        for info in zf.infolist():
            raw = zf.read(info)
            array = None
            if raw[:8] == b"\x93NUMPY\x01\x00":
                end = 10 + int.from_bytes(raw[8:10], "little")
                m = _NPY_HEADER.fullmatch(raw, 10, end)
                if m:
                    dtype = np.dtype(m.group(1).decode())
                    shape = tuple(int(n) for n in m.group(2).split(b",") if n.strip())
                    count = math.prod(shape)
                    if len(raw) == end + count * dtype.itemsize:
                        array = np.frombuffer(bytearray(raw[end:]), dtype, count).reshape(shape)
            if array is None:
                array = np.lib.format.read_array(io.BytesIO(raw), allow_pickle=False)
            name = info.filename
            arrays[name[:-4] if name.endswith(".npy") else name] = array
    return arrays


def write_json(path: str | Path, kind: str, key: str, payload: Any) -> None:
    """Write a JSON payload with its header, atomically."""
    text = json.dumps({"entry": _header(kind, key, json_digest(payload)), "payload": payload}, indent=1)
    write_text(path, text + "\n")


def read_json(path: str | Path, kind: str, key: str) -> Any:
    """The payload of an entry written by `write_json`, verified (errors as `read_arrays`)."""
    path = Path(path)
    try:
        document = json.loads(path.read_bytes())
    except FileNotFoundError:
        raise
    except (OSError, ValueError) as err:
        raise damaged(path, f"unreadable ({type(err).__name__})") from None
    if not isinstance(document, dict) or "payload" not in document:
        raise damaged(path, "has no entry header (not written by this orthosim's cache)")
    payload = document["payload"]
    _verify(path, document.get("entry"), kind, key, json_digest(payload))
    return payload


def warn_damaged(what: str, error: DamagedFileError, category: type[Warning] = DamagedEntryWarning,
                 stacklevel: int = 3) -> None:
    """The one warning line a cache gives for a damaged entry before rebuilding it."""
    warnings.warn(f"{what} cache entry {error.where} is damaged: {error.problem}; rebuilding it", category,
                  stacklevel=stacklevel)
