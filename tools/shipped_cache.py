"""Write the cache entries shipped inside the package (`orthosim/storage/shipped/`): the teeth and
sphere trees of the demo's model (the parametric model of the paper's cases), built from nothing
exactly as a run builds them, so that a fresh install's first `orthosim demo` loads them.

Run after changing a builder (the model's or the sphere trees'; `tests/storage/test_shipped_entries.py`
says when):   .venv/bin/python tools/shipped_cache.py
The old entries are removed first; the new ones are the files a run writes into an empty cache.
"""

from __future__ import annotations

import os
import shutil
import sys
import tempfile
from pathlib import Path


def main() -> None:
    from orthosim.storage.shipped import SHIPPED_DIR

    for kind in ("dentitions", "spheretrees"):
        shutil.rmtree(SHIPPED_DIR / kind, ignore_errors=True)  # else the build would load the old ones
    with tempfile.TemporaryDirectory(prefix="orthosim-shipped-") as tmp:
        os.environ["ORTHOSIM_CACHE"] = tmp
        from orthosim.collision import CollisionModel
        from orthosim.exchange.case import DEFAULT_CASE, load_case

        CollisionModel.from_dentition(load_case(DEFAULT_CASE).build_dentition())
        for kind, found in (("dentitions", Path(tmp, "dentitions").glob("*.npz")), ("spheretrees", Path(tmp).glob("*.npz"))):
            (SHIPPED_DIR / kind).mkdir(parents=True, exist_ok=True)
            for entry in sorted(found):
                shutil.copyfile(entry, SHIPPED_DIR / kind / entry.name)
                print(f"{kind}/{entry.name}: {entry.stat().st_size} bytes", file=sys.stderr)


if __name__ == "__main__":
    main()
