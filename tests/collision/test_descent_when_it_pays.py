"""The detectors stay off numba's compiler until compiling their descent pays: with the kernels not
in numba's cache, the numpy descent (the same results) for the first PAYS_AFTER_DESCENTS descents of
a process, then the compiled walk (`orthosim.collision.descent.compiled_descent`)."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

pytest.importorskip("numba")

_PROBE = """
import json
from orthosim.collision import descent, descent_compiled
descent.PAYS_AFTER_DESCENTS = 3
walks = [descent.compiled_descent(None) is not None for _ in range(5)]
print(json.dumps({"ready": descent_compiled.kernels_ready(), "walks": walks,
                  "asked": descent.compiled_descent(True) is not None, "refused": descent.compiled_descent(False) is None}))
"""


@pytest.mark.slow  # a fresh interpreter importing numba
def test_a_fresh_machine_descends_with_numpy_until_compiling_pays(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "empty-numba-cache")}
    done = subprocess.run([sys.executable, "-c", _PROBE], env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    seen = json.loads(done.stdout)
    assert seen["ready"] is False  # nothing compiled for this source in that cache
    assert seen["walks"] == [False, False, False, True, True]  # numpy for 3 descents, then the compiled walk
    assert seen["asked"] and seen["refused"]  # compiled=True and False still mean what they say
    assert "preparing" not in done.stderr  # nothing was compiled: the probe never called a kernel
