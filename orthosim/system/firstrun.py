"""The one line a long first step prints: what it prepares, and that it happens once.

A fresh install has empty caches: the first run builds the teeth, fits their sphere trees and has
numba compile its kernels for this machine, seconds of work that later runs load from the caches
in a fraction of a second. So that a new user never watches a silent terminal (or log) for more
than two seconds, each such step runs inside `preparing(what)`: when it is still running after
`NOTICE_AFTER_S`, one line goes to stderr, whether or not stderr is a terminal,

    orthosim: preparing the sphere trees of 28 teeth (once: kept in the cache for later runs)

once per process for each `what`; a step that ends sooner (a warm cache, a small model) says
nothing. `announce_compiles()` does the same for numba's compiler: numba emits its
"numba:compile" event only when a kernel is not in its cache, so the line appears exactly when
this machine compiles.
"""

from __future__ import annotations

import sys
import threading
import time
from contextlib import contextmanager
from typing import Iterator

NOTICE_AFTER_S = 1.0  # a step still running after this long says what it prepares (the budget is 2 s of silence)
_COMPILING = "the compiled kernels for this machine"
_said: set[str] = set()
_lock = threading.Lock()
_hushed: list[bool] = []
_one_thread: list[bool] = []


def _say(what: str) -> None:
    with _lock:
        if what in _said or _hushed:
            return
        _said.add(what)
    print(f"orthosim: preparing {what} (once: kept in the cache for later runs)", file=sys.stderr, flush=True)


def keep_to_one_thread() -> None:
    """This process starts no thread to say its line (an `orthosim batch` worker keeping to one
    core): a step says what it prepared when it ends, if it took longer than the notice's delay."""
    _one_thread.append(True)


def hush() -> None:
    """This process says nothing of what it prepares: a helper whose parent speaks for it (the
    workers that build sphere trees for `cached_sphere_trees`, which says the one line)."""
    _hushed.append(True)


@contextmanager
def preparing(what: str, after_s: float | None = None) -> Iterator[None]:
    """Say "orthosim: preparing WHAT ..." on stderr if the block still runs after `after_s` seconds
    (default `NOTICE_AFTER_S`; 0: at once), once per process per `what`. `what` names the thing
    prepared in a user's words."""
    after_s = NOTICE_AFTER_S if after_s is None else after_s
    if what in _said or _hushed:
        yield
        return
    if after_s <= 0:
        _say(what)
        yield
        return
    if _one_thread:
        started = time.monotonic()
        try:
            yield
        finally:
            if time.monotonic() - started > after_s:
                _say(what)
        return
    timer = threading.Timer(after_s, _say, (what,))
    timer.daemon = True
    timer.start()
    try:
        yield
    finally:
        timer.cancel()


class _CompileNotice:
    """numba's compile events (START and END, nested when a kernel compiles the kernels it calls):
    the outermost compile runs inside `preparing`."""

    def __init__(self):
        self.depth = 0
        self.block = None

    def on_start(self, event) -> None:
        self.depth += 1
        if self.depth == 1:
            self.block = preparing(_COMPILING)
            self.block.__enter__()

    def on_end(self, event) -> None:
        self.depth -= 1
        if self.depth == 0 and self.block is not None:
            block, self.block = self.block, None
            block.__exit__(None, None, None)


_listening: list[_CompileNotice] = []


def announce_compiles() -> None:
    """Have numba's compiles of kernels (cache misses only) say so, as `preparing` does; called by
    each module that defines kernels, after importing numba. Idempotent; a numba without the event
    API (before 0.55) stays silent."""
    if _listening:
        return
    try:
        from numba.core import event
    except ImportError:  # pragma: no cover - numba is optional, or too old for events
        return
    class Notice(_CompileNotice, event.Listener):  # numba's listeners are its Listener's subclasses
        pass

    notice = Notice()
    _listening.append(notice)
    event.register("numba:compile", notice)


_cached: dict[int, bool] = {}  # id of a kernel -> whether numba's cache held it when first asked


def in_numba_cache(*kernels) -> bool:
    """Whether each of the numba `kernels` runs without compiling: compiled in this process already,
    or in numba's cache for its source (numba's own index check: source stamp and entries; asked
    once a process). Any doubt reads as False, and a kernel not in the cache stays so for this
    process (a kernel compiled meanwhile by another process is found by the next)."""
    for kernel in kernels:
        if kernel.signatures:
            continue
        if id(kernel) not in _cached:
            try:
                _cached[id(kernel)] = bool(kernel._cache._cache_file._load_index())
            except Exception:  # noqa: BLE001: a numba without this layout, or no cache: not cached
                _cached[id(kernel)] = False
        if not _cached[id(kernel)]:
            return False
    return True
