"""The sub-runs of `orthosim bench` and how each one's failure is kept: loudly, never as a figure.

A bench run is made of sub-runs: child processes (`orthosim run` launched for the start-up and the
memory figures, the report's runs, `stage verify`, the batch's workers, one renderer per GL
backend) and studies run in the bench's own process (trees, the labelled scan, staging). A sub-run
that fails or is refused (a non-zero exit status, an exception) leaves its figure null and adds a
`Failure` to the record's `failures`, naming the figure and why in one line; `orthosim bench`
prints each one and exits 1. A figure is thus never read off a run that did not finish, and a
ratio or a target whose baseline did not run is null, never met.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Callable, TypeVar

T = TypeVar("T")


@dataclass(frozen=True)
class Failure:
    """One sub-run that failed or was refused: `figure` is the record's key it leaves null."""

    figure: str  # e.g. "startup", "memory.run_10k_steps_no_render_mb", "render_backends"
    why: str  # one line: the exit status or exception, and the child's last line of stderr where known

    def line(self) -> str:
        return f"bench: failed: {self.figure}: {self.why}"


class SubRunFailed(RuntimeError):
    """A sub-run of the bench failed or was refused; its figure stays null (see the module doc)."""

    def __init__(self, figure: str, why: str):
        super().__init__(f"{figure}: {why}")
        self.failure = Failure(figure, why)


def last_line(text: str | bytes | None) -> str:
    """The last non-empty line of a child's output (its error, usually), or '' when it printed nothing."""
    if isinstance(text, bytes):
        text = text.decode(errors="replace")
    lines = [line.strip() for line in (text or "").splitlines() if line.strip()]
    return lines[-1][:300] if lines else ""


def exit_failure(figure: str, command: str, exit_code: int | None, stderr: str | bytes | None = None) -> Failure:
    """The failure of a child process that exited with `exit_code` (a negative code: killed by that signal)."""
    how = f"killed by signal {-exit_code}" if exit_code is not None and exit_code < 0 else f"exited with {exit_code}"
    said = last_line(stderr)
    return Failure(figure, f"{command} {how}" + (f": {said}" if said else ""))


def guarded(figure: str, failures: list[Failure], call: Callable[[], T]) -> T | None:
    """`call()`, or None with a `Failure` for `figure` added to `failures` when it raises.

    A `SubRunFailed` names its own figure; any other exception is the sub-run's failure too (the
    bench goes on with the other figures). KeyboardInterrupt and SystemExit pass through."""
    try:
        return call()
    except SubRunFailed as err:
        failures.append(err.failure)
    except Exception as err:  # noqa: BLE001: a study that breaks is that figure's failure, said in one line
        said = last_line(str(err)) or "(no message)"
        failures.append(Failure(figure, f"{type(err).__name__}: {said}"))
    return None


def gather(record: dict | None, figure: str, failures: list[Failure]) -> None:
    """Move the failures a study kept in its own record (`record["failures"]`, `Failure` dicts whose
    figures are relative to the study) into `failures`, named under `figure`."""
    for found in (record or {}).get("failures", ()):
        failures.append(Failure(f"{figure}.{found['figure']}", found["why"]))


def as_records(failures: list[Failure]) -> list[dict]:
    """`failures` as the JSON record's list."""
    return [asdict(f) for f in failures]
