"""Which folders hold one Open-Full-Jaw scan: light enough for a case file's validation (no mesh
library imported), used by `orthosim.exchange.openfulljaw` to load them."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Sequence

from orthosim.errors import MeshError

_TOOTH_FILE = re.compile(r"^tooth_(\d+)\.stl$", re.IGNORECASE)
ARCH_FOLDERS = ("maxilla", "mandible")  # the dataset's names for a patient's two arch folders


def scan_folders(folder: str | Path | Sequence[str | Path]) -> list[Path]:
    """The folders of one scan: `folder` itself, each of a list, or a patient folder's `maxilla/` and `mandible/`."""
    if isinstance(folder, (str, Path)):
        folder = Path(folder)
        if folder.is_dir() and not any(_TOOTH_FILE.match(p.name) for p in folder.iterdir()):
            arches = [folder / a for a in ARCH_FOLDERS if (folder / a).is_dir()]
            if arches:
                return arches
        return [folder]
    folders = [Path(f) for f in folder]
    if not folders:
        raise MeshError("open-full-jaw", "folders", "is empty", "list the scan's maxilla and/or mandible folders")
    return folders
