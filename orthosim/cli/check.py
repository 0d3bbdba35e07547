"""`orthosim check`: case files checked like a linter, without running them.

Every problem of every file given, one line each (`FILE: [section] field: problem; fix`, on
stderr, where errors go), each good file as `FILE: ok (...)`, then a count (on stdout, with the
good files); exit status 2 when any
file has a problem. The problems come from `orthosim.exchange.case.read_case`: every unknown
key, and per section the first value that cannot be read; a file that is not valid TOML is one line.
"""

from __future__ import annotations

import sys
from pathlib import Path

import click

from orthosim.errors import OrthosimError


def problem_line(path: Path, error: OrthosimError) -> str:
    """`FILE: [section] field: problem; fix`, one line (the section left out for a problem of the whole file)."""
    where = error.where or str(path)
    head = f"{where}:"
    if error.field:
        section, _, field = error.field.partition(".")  # "loads[0].teeth[1]": section loads[0]; a top-level key alone
        head += f" [{section}]" + (f" {field}:" if field else ":")
    text = f"{head} {error.problem}" + (f"; {error.fix}" if error.fix else "")
    return " ".join(text.split())


@click.command()
@click.argument("cases", nargs=-1, required=True, type=click.Path(path_type=Path))
def check(cases: tuple[Path, ...]) -> None:
    """Check case files without running them: every problem, one line each, then a count."""
    from orthosim.exchange.case import read_case

    problems = bad_files = 0
    for path in cases:
        case, found = read_case(path)
        for error in found:
            click.echo(problem_line(path, error), err=True)
        if found:
            problems, bad_files = problems + len(found), bad_files + 1
            continue
        click.echo(f"{path}: ok ({case.name}; {len(case.loads)} loads, {len(case.extractions)} extractions, {case.steps} steps)")
    files = f"{len(cases)} file{'s' if len(cases) != 1 else ''}"
    if problems:
        click.echo(f"{problems} problem{'s' if problems != 1 else ''} in {bad_files} of {files}")
        sys.exit(2)
    click.echo(f"{files} checked, no problems")
