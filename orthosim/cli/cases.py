"""`orthosim cases`: the shipped case files listed, or one copied to start from."""

from __future__ import annotations

from pathlib import Path

import click

from orthosim.exchange.shippedcases import copy_shipped_case, find_shipped_case, shipped_cases


@click.command("cases")
@click.option("--copy", "copy", nargs=2, default=None, metavar="NAME DEST",
              help="Copy shipped case NAME into folder DEST (or to DEST when it ends in .toml) to start from.")
def cases(copy: tuple[str, str] | None) -> None:
    """List the case files shipped with orthosim, or copy one to start from."""
    if copy:
        name, dest = copy
        target = copy_shipped_case(name, Path(dest))
        note = (" (its teeth are read from mesh folders named relative to the file: edit [model] folder)"
                if find_shipped_case(name).needs_data else "")
        click.echo(f"copied {name} -> {target}{note}; run it with: orthosim run {target}")
        return
    rows = shipped_cases()
    width = max((len(c.name) for c in rows), default=0)
    for c in rows:
        data = " [needs the Open-Full-Jaw data]" if c.needs_data else ""
        span = f" ({c.duration_days:g} days)" if c.duration_days else ""  # staging cases: a set-up, no treatment time
        click.echo(f"{c.name:<{width}}  {c.title}{span}{data}")
    from orthosim.exchange.case import CASES_DIR

    click.echo(f"{len(rows)} cases in {CASES_DIR}; copy one with: orthosim cases --copy NAME DIR")
