"""`orthosim check`: validate case files without running them."""

from __future__ import annotations

from pathlib import Path

import click


@click.command()
@click.argument("cases", nargs=-1, required=True, type=click.Path(path_type=Path))
def check(cases: tuple[Path, ...]) -> None:
    """Validate case files without running them."""
    from orthosim.exchange.case import load_case

    for path in cases:
        case = load_case(path)
        click.echo(f"{path}: ok ({case.name}; {len(case.loads)} loads, {len(case.extractions)} extractions, {case.steps} steps)")
