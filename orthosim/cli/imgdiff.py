"""`orthosim imgdiff`: a render compared with its golden PNG (exit 0 match, 1 differ, 2 unusable input)."""

from __future__ import annotations

import sys
from pathlib import Path

import click


@click.command()
@click.argument("golden", type=click.Path(path_type=Path))
@click.argument("candidate", type=click.Path(path_type=Path))
@click.option("--diff", "diff_path", type=click.Path(path_type=Path), default=None,
              help="Write the diff image here (default: CANDIDATE.diff.png, only when they differ).")
@click.option("--max-level", default=3, show_default=True, type=int,
              help="Tolerance mode: levels (0-255) a channel may be off before its pixel counts as different.")
@click.option("--max-fraction", default=0.001, show_default=True, type=float,
              help="Tolerance mode: fraction of pixels allowed to differ (0.001 = 0.1 %).")
@click.option("--update", is_flag=True, help="Make the candidate the golden: rewrite GOLDEN.png and GOLDEN.json.")
@click.option("--ignore", multiple=True, metavar="LABEL",
              help="Leave out the pixels of a kind (gingiva, contact, marker, background), a tooth (13) or a contact "
                   "(\"contact 13-14\"); repeatable; needs labels on both sides.")
@click.option("--max-shift-px", default=0.0, show_default=True, type=float,
              help="Tolerate a tooth or contact that only moved this many pixels (needs labels on both sides).")
def imgdiff(golden: Path, candidate: Path, diff_path: Path | None, max_level: int, max_fraction: float,
            update: bool, ignore: tuple[str, ...], max_shift_px: float) -> None:
    """Compare a render with its golden PNG; exit 0 match, 1 differ, 2 unusable input.

    Exact when the candidate was drawn by the GL renderer and Mesa version the golden's sidecar
    (GOLDEN.json) names, else within tolerance (SSIM reported). When both carry labels
    (GOLDEN.labels.npz/.json) a second line says what changed, tooth by tooth. See render/imgdiff.py.
    """
    from orthosim_render.imgdiff import Tolerance, imgdiff as compare
    from orthosim_render.regression import this_machine_gl

    outcome = compare(golden, candidate, diff_path=diff_path, tolerance=Tolerance(max_level, max_fraction),
                      update=update, this_machine=this_machine_gl, max_shift_px=max_shift_px,
                      ignore=tuple(int(item) if item.isdigit() else item for item in ignore))
    for line in outcome.lines:
        click.echo(line)
    if outcome.exit_code:
        sys.exit(outcome.exit_code)
