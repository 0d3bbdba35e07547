"""Errors a user can cause, each carrying a one-line message that names the file, the field and the fix.

The CLI catches `OrthosimError` and prints `str(error)` as a single line with a non-zero exit code;
anything else escaping is a bug in orthosim, not in the user's input.
"""

from __future__ import annotations

from pathlib import Path


class OrthosimError(Exception):
    """Base class of every error caused by user input (case files, meshes, command-line values)."""

    exit_code = 2

    def __init__(self, where: str | Path | None, field: str | None, problem: str, fix: str | None = None):
        self.where = str(where) if where is not None else None
        self.field = field
        self.problem = problem
        self.fix = fix
        super().__init__(self._format())

    def __reduce__(self):
        # rebuilt from its parts, so that an error raised in a child process (`orthosim.runtime.background`)
        # reaches the CLI as the same type with the same one-line message
        return (type(self), (self.where, self.field, self.problem, self.fix))

    def _format(self) -> str:
        parts = []
        if self.where:
            parts.append(self.where)
        if self.field:
            parts.append(self.field)
        head = ": ".join(parts)
        text = f"{head}: {self.problem}" if head else self.problem
        if self.fix:
            text += f" (fix: {self.fix})"
        return " ".join(text.split())  # always one line


class CaseError(OrthosimError):
    """A case file is missing, malformed, or asks for something the model cannot do."""


class MeshError(OrthosimError):
    """A tooth mesh cannot be read, or is broken beyond a safe repair."""


class SphereTreeError(OrthosimError):
    """A sphere-tree file or build request is invalid."""


class DamagedFileError(OrthosimError):
    """A file orthosim wrote earlier (a cache entry, a run folder, a batch table, a staging file) is
    damaged or not what it should be: caches rebuild it with a warning, other readers refuse it."""
