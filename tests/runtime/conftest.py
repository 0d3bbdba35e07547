"""Fixtures of the runtime tests: small file systems mounted for a test (read-only, or nearly full),
skipped where mounting is not allowed (not root, a container without mount rights)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import uuid
from pathlib import Path

import pytest


def _mount(*args) -> Path | None:
    """A fresh mount point with `mount args`, or None where mounting is not allowed (not root, container)."""
    if sys.platform != "linux" or os.geteuid() != 0 or shutil.which("mount") is None:
        return None
    point = Path(tempfile.gettempdir()) / f"orthosim-test-{uuid.uuid4().hex}"
    point.mkdir()
    r = subprocess.run(["mount", *args, str(point)], capture_output=True)
    if r.returncode != 0:
        point.rmdir()
        return None
    return point


def _unmount(point: Path) -> None:
    subprocess.run(["umount", "-l", str(point)], capture_output=True)
    point.rmdir()


@pytest.fixture
def read_only_folder():
    point = _mount("-t", "tmpfs", "-o", "size=1m,ro", "tmpfs")
    if point is None:
        pytest.skip("mounting a read-only tmpfs needs root on Linux")
    yield point
    _unmount(point)


@pytest.fixture
def tiny_disk():
    point = _mount("-t", "tmpfs", "-o", "size=256k", "tmpfs")
    if point is None:
        pytest.skip("mounting a small tmpfs needs root on Linux")
    yield point
    _unmount(point)
