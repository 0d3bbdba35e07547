"""The numpy tally: what earlier runs spent on numpy forms of the compiled kernels, kept in the cache folder.

A run answers its depth and signed-distance queries in numpy until compiling numba's kernels pays
(`orthosim.geometry.signeddistance.compiled_pays`), so that a short run never waits for the
compiler. Counted in one process only, a user who makes nothing but short runs would never
compile, and every run would pay numpy's price again. So each process adds the seconds it spent
to this tally, and a run compiles once what earlier runs spent and what it spends itself pass the
threshold together: the demo spends about 1.5 s there on the quiet two-core machine (3-4 s before
the numpy forms replayed the kernel's descent in Python floats, 2026-11-29), more under load, so
about its 8th to 20th run compiles, once, for every later run. (The detectors' descent keeps its own per-process rule:
loading its kernels costs more than a short run's numpy descents.)

The tally belongs to one compile: its key is the kernels' source files with their modification
times (the stamp numba's own cache checks) and numba's cache folder (`NUMBA_CACHE_DIR`, or beside
the sources). A new install, an edited kernel or another numba cache starts from nothing, as
numba's cache does. It is a checksummed cache entry (`orthosim.storage.cacheentry`)
at `$ORTHOSIM_CACHE/firstrun/numpy-tally.json` (`~/.cache/orthosim/...` without the variable); a
damaged one is one warning and counts as nothing. Two processes that add at once are serialised by
a lock on the file beside it; where the folder cannot be written, the tally is simply not kept
(it is a saving, never a reason for a run to fail).
"""

from __future__ import annotations

import atexit
import hashlib
import os
import threading
from pathlib import Path

from orthosim.errors import DamagedFileError
from orthosim.storage.cacheentry import damaged, read_json, warn_damaged, write_json

KIND = "numpy-tally"
_FILE = Path("firstrun") / "numpy-tally.json"
_lock = threading.Lock()
_spent: dict[str, float] = {}  # this process's spending, by counter
_kept: dict[str, float] = {}  # what of it is in the tally already
_carried: dict[str, float] = {}  # the tally as this process first read it, by counter
_sources: dict[str, tuple[str, ...]] = {}  # counter -> the kernels' source files it belongs to
_at_exit: list[bool] = []


def tally_path() -> Path:
    env = os.environ.get("ORTHOSIM_CACHE")
    return (Path(env) if env else Path.home() / ".cache" / "orthosim") / _FILE


def _key(counter: str) -> str:
    # runs that share one compile share a tally: the same kernels' sources and numba's cache folder
    h = hashlib.sha256(f"{counter}\0{os.environ.get('NUMBA_CACHE_DIR', '')}".encode())
    for source in _sources.get(counter, ()):
        try:
            stat = os.stat(source)
            h.update(f"\0{os.path.realpath(source)}\0{stat.st_mtime_ns}\0{stat.st_size}".encode())
        except OSError:
            h.update(f"\0{source}\0missing".encode())
    return h.hexdigest()[:32]


def _read() -> dict:
    """{key: amount} as on disk; nothing where there is no tally or a damaged one (warned)."""
    path = tally_path()
    if not path.is_file():  # none yet, or a cache folder that cannot hold one: nothing carried
        return {}
    try:
        payload = read_json(path, KIND, "tally")
    except FileNotFoundError:  # removed meanwhile (read_json turns any other failure into damage)
        return {}
    except DamagedFileError as error:
        warn_damaged("numpy tally", error)
        return {}
    if not isinstance(payload, dict) or not all(
            isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) and 0 <= v < float("inf")
            for k, v in payload.items()):
        warn_damaged("numpy tally", damaged(path, "its counts are not non-negative numbers"))
        return {}
    return payload


def carried(counter: str, *sources: str) -> float:
    """What earlier runs of this install spent on `counter` (read once a process). `sources`: the
    files of the kernels the counter stands for (their stamps key the tally)."""
    with _lock:
        if sources:
            _sources[counter] = tuple(sources)
        if counter not in _carried:
            _carried[counter] = float(_read().get(_key(counter), 0.0))
        return _carried[counter]


def spend(counter: str, amount: float, *sources: str) -> None:
    """This process spent `amount` more on `counter`; added to the tally by `keep`, at the latest
    when the process exits normally."""
    with _lock:
        if sources:
            _sources[counter] = tuple(sources)
        _spent[counter] = _spent.get(counter, 0.0) + amount
        if not _at_exit:
            _at_exit.append(True)
            atexit.register(keep)


def keep() -> None:
    """Add what this process spent since its last `keep` to the tally on disk. A forked child that
    ends with os._exit (multiprocessing's) runs no atexit: the run's own end calls this."""
    with _lock:
        owed = {c: s - _kept.get(c, 0.0) for c, s in _spent.items() if s > _kept.get(c, 0.0)}
        if not owed:
            return
        path = tally_path()
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with open(path.with_suffix(".lock"), "a") as lock:
                try:
                    import fcntl

                    fcntl.flock(lock, fcntl.LOCK_EX)
                except (ImportError, OSError):  # no flock here: a lost addition only delays a compile
                    pass
                tally = _read()
                for counter, amount in owed.items():
                    key = _key(counter)
                    tally[key] = float(tally.get(key, 0.0)) + amount
                write_json(path, KIND, "tally", tally)
        except OSError:
            return
        _kept.update({c: _kept.get(c, 0.0) + a for c, a in owed.items()})


def forget_this_process() -> None:
    """Start this process's counts afresh (tests; a worker reused for another install's runs)."""
    with _lock:
        _spent.clear()
        _kept.clear()
        _carried.clear()
        _sources.clear()
