"""A run folder: what `orthosim run` leaves in `--out`, and how readers tell a finished run.

`run.json` is written last, after every other output of the run. It names the orthosim version
that wrote the folder, the case file (and its SHA-256), the detector, `complete: true`, and the
SHA-256 of every file the run left at the top of the folder (`output_sha256`). A folder without it, or
whose `run.json` says otherwise, holds no finished run; reports, batches and regression tools read
a run only through `read_finished_run`, which refuses such folders, folders written by another
orthosim version, and folders whose recorded files are missing or changed since (a damaged disk, a
copy cut short, a hand edit), with one line that names the fix. A batch runs such a folder again.
"""

from __future__ import annotations

import json
from pathlib import Path

from orthosim import __version__
from orthosim.storage.atomic import write_json
from orthosim.storage.checksums import file_sha256
from orthosim.errors import OrthosimError

RUN_FILE = "run.json"


class RunFolderError(OrthosimError):
    """A run folder is missing, unfinished, unreadable or from another orthosim version."""


def output_digests(out_dir: str | Path) -> dict[str, str]:
    """File name -> hex SHA-256 of every file at the top of a run folder but run.json and hidden
    temporaries (subfolders, such as drawn frames, are not read back and not recorded)."""
    folder = Path(out_dir)
    return {p.name: file_sha256(p) for p in sorted(folder.iterdir() if folder.is_dir() else ())
            if p.is_file() and p.name != RUN_FILE and not p.name.startswith(".")}


def write_run_record(out_dir: str | Path, case_file: str | Path, detector: str, extra: dict | None = None) -> dict:
    """Mark `out_dir` as a finished run: write run.json (atomically) as the run's last output."""
    record = {
        "orthosim_version": __version__,
        "complete": True,
        "case_file": str(case_file),
        "case_sha256": file_sha256(case_file),
        "detector": detector,
        **(extra or {}),
        "output_sha256": output_digests(out_dir),
    }
    write_json(Path(out_dir) / RUN_FILE, record)
    return record


def read_finished_run(run_dir: str | Path) -> dict:
    """The run.json of a finished run written by this orthosim version; RunFolderError otherwise."""
    run_dir = Path(run_dir)
    path = run_dir / RUN_FILE
    rerun = f"run it again: orthosim run CASE --out {run_dir}"
    if not run_dir.is_dir():
        raise RunFolderError(run_dir, None, "is not a run folder (no such folder)", "give a folder that `orthosim run` wrote")
    if not path.is_file():
        raise RunFolderError(run_dir, RUN_FILE, "is missing: the run did not finish (or the folder is not a run)", rerun)
    try:
        record = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise RunFolderError(path, None, f"is unreadable ({err.__class__.__name__})", rerun) from None
    if not isinstance(record, dict) or record.get("complete") is not True:
        raise RunFolderError(path, "complete", "does not mark a finished run", rerun)
    version = record.get("orthosim_version")
    if version != __version__:
        raise RunFolderError(path, "orthosim_version", f"the run was written by orthosim {version}, this is {__version__}",
                             rerun)
    _check_outputs(run_dir, record.get("output_sha256"), rerun)
    return record


def _check_outputs(run_dir: Path, outputs, rerun: str) -> None:
    """Refuse a run whose recorded files are missing or no longer the bytes the run wrote."""
    path = run_dir / RUN_FILE
    if not isinstance(outputs, dict) or not all(isinstance(v, str) for v in outputs.values()):
        raise RunFolderError(path, "output_sha256", "holds no checksums of the run's files", rerun)
    for name, digest in outputs.items():
        file = run_dir / name
        if Path(name).name != name or not file.is_file():
            raise RunFolderError(file, None, "is missing from the run folder", rerun)
        try:
            same = file_sha256(file) == digest
        except OSError as err:
            raise RunFolderError(file, None, f"is unreadable ({err.__class__.__name__})", rerun) from None
        if not same:
            raise RunFolderError(file, None, "is damaged: its checksum differs from the one run.json recorded", rerun)
