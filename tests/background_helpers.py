"""Sequences that `tests/runtime/test_background.py` has a child process produce: module-level, so that they
pickle by name, in a module that imports little, so that the child starts quickly."""

from __future__ import annotations

import numpy as np

from orthosim.errors import CaseError


def numbers(n: int):
    yield from range(n)


def fails_after_two():
    yield "first"
    yield "second"
    raise CaseError("case.toml", "loads[0].teeth", "tooth 99 does not exist", "use an FDI number")


def endless():
    i = 0
    while True:
        yield np.full(1000, i)
        i += 1


def unpicklable_item():
    yield lambda: None


def squares_from_worker_processes(n: int):
    """Squares computed by a pool of two worker processes started inside the producing child."""
    import multiprocessing

    with multiprocessing.get_context("fork").Pool(2) as pool:
        yield from pool.map(_square, range(n))


def _square(x: int) -> int:
    return x * x
