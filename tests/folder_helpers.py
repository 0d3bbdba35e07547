"""Test helpers for output folders: an earlier run's files laid down, and a folder's files read back."""

from __future__ import annotations

from pathlib import Path


def earlier_run(folder: Path, frames: int) -> None:
    """What an earlier finished run left in `folder`: `frames` PNG files, metrics.json and run.json."""
    (folder / "frames").mkdir(parents=True)
    for i in range(frames):
        (folder / "frames" / f"{i:05d}.png").write_bytes(b"old")
    (folder / "metrics.json").write_text('{"old": true}')
    (folder / "run.json").write_text('{"complete": true}')


def listing(folder: Path) -> dict:
    """Every file under `folder`, by its relative path, with its bytes."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}
