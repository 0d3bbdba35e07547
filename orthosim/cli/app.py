"""The `orthosim` group and its console entry: commands registered (the heavier ones imported only
when they run), user errors turned into one line and an exit code."""

from __future__ import annotations

import importlib
import sys

import click

from orthosim import __version__
from orthosim.errors import OrthosimError


class _LazyGroup(click.Group):
    """A command group whose commands are imported only when they run.

    Importing a command's module can pull trimesh, scipy and FCL (seconds on a loaded machine);
    `orthosim --help` and `orthosim check` should not pay for that.
    """

    lazy = {  # name -> (module, attribute, one-line help shown by --help)
        "run": ("orthosim.cli.run", "run", "Run one case: simulate, detect, write frames and metrics."),
        "demo": ("orthosim.cli.run", "demo", "Run the paper's case 1 (cases/case1_...) into out/demo/."),
        "check": ("orthosim.cli.check", "check", "Validate case files without running them."),
        "occlusion": ("orthosim.cli.occlusion", "occlusion",
                      "Occlusal measures and contacts per pair of a case's model at rest; contact areas drawn (Figure 7)."),
        "bench": ("orthosim.cli.bench", "bench", "Measure throughput against the 40 fps target; write JSON."),
        "stage": ("orthosim.cli.stage", "stage", "Aligner staging: plan a case's set-up, or re-check a written staging."),
        "imgdiff": ("orthosim.cli.imgdiff", "imgdiff", "Compare a render with its golden PNG; exit 0 match, 1 differ, 2 unusable input."),
        "report": ("orthosim.cli.report", "report", "Contact-area report: index.html, report.json (and report.pdf) for cases or finished runs."),
        "spheretree": ("orthosim.cli.spheretree", "spheretree", "Build, export and evaluate sphere trees."),
        "collide": ("orthosim.cli.collide", "collide", "Collision accuracy studies, timings and single queries."),
        "batch": ("orthosim.cli.batch", "batch", "Many runs and parameter sweeps, on every core or a Dask cluster."),
        "evidence": ("orthosim.cli.evidence", "evidence", "Run the clinical evidence table; write a page."),
        "cases": ("orthosim.cli.cases", "cases", "List the shipped case files, or copy one to start from."),
    }

    def list_commands(self, ctx):
        return sorted([*super().list_commands(ctx), *self.lazy])

    def get_command(self, ctx, name):
        if name in self.lazy:
            module, attr, _ = self.lazy[name]
            return getattr(importlib.import_module(module), attr)
        return super().get_command(ctx, name)

    def format_commands(self, ctx, formatter):
        rows = [(name, self.lazy[name][2]) for name in self.list_commands(ctx) if name in self.lazy]
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, prog_name="orthosim")
def main() -> None:
    """Headless orthodontic treatment simulator: tooth movement, collision detection, offscreen rendering."""


def _one_line_warning(message, category, filename, lineno, file=None, line=None) -> None:
    """Repairs and other warnings reach the user as `orthosim: warning: ...`, one line each."""
    text = " ".join(str(message).split())
    click.echo(f"orthosim: warning: {text}", err=True)


def click_error_line(err: click.ClickException) -> str:
    """A click error on one line, in the form of every other error: `--gl: 'vulkan' is not one of
    auto, egl, osmesa` for a value a parameter refuses; click's own message, whitespace folded,
    for the rest (an unknown option or command, a missing argument)."""
    if isinstance(err, click.BadParameter) and not isinstance(err, click.MissingParameter) and err.param is not None:
        param = err.param
        name = param.opts[-1] if isinstance(param, click.Option) else param.human_readable_name
        message = err.message
        if isinstance(param.type, click.Choice):  # click quotes each choice: listed plain, as the help lists them
            value = message.split(" is not one of ", 1)[0]
            message = f"{value} is not one of {', '.join(map(str, param.type.choices))}"
        return f"{name}: {' '.join(message.split()).rstrip('.')}"
    return " ".join(err.format_message().split()).rstrip(".")


def entry() -> None:
    """Console-script entry: run the CLI, turning user errors into one line and an exit code."""
    import warnings

    from orthosim.system.lifeline import sigterm_as_interrupt, terminated

    warnings.showwarning = _one_line_warning
    sigterm_as_interrupt()
    try:
        try:
            main.main(standalone_mode=False)
        except Exception as err:  # whatever a SIGTERM interrupted ends as the stop it was
            if terminated() and not isinstance(err, OrthosimError):
                raise KeyboardInterrupt from None
            raise
    except OrthosimError as err:
        click.echo(f"orthosim: error: {err}", err=True)
        sys.exit(err.exit_code)
    except click.exceptions.Abort:
        click.echo("orthosim: terminated" if terminated() else "orthosim: aborted", err=True)
        sys.exit(143 if terminated() else 130)
    except click.exceptions.NoArgsIsHelpError as err:  # `orthosim`, `orthosim stage` alone: the help, as click shows it
        err.show()
        sys.exit(err.exit_code)
    except click.ClickException as err:  # usage errors (a bad option or value, a missing argument) and file errors
        click.echo(f"orthosim: error: {click_error_line(err)}", err=True)
        sys.exit(err.exit_code)
    except KeyboardInterrupt:
        click.echo("orthosim: terminated" if terminated() else "orthosim: interrupted", err=True)
        sys.exit(143 if terminated() else 130)
    except BrokenPipeError:
        sys.exit(1)
    except SystemExit:
        raise
