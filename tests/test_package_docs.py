"""A newcomer finds a concept by its name: every package's opening text names each of its modules
and subpackages, and names none that is gone."""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = sorted(p.parent for folder in ("orthosim", "render", "bench") for p in (ROOT / folder).rglob("__init__.py")
                  if "__pycache__" not in p.parts)


def _parts(package: Path) -> set[str]:
    modules = {p.stem for p in package.glob("*.py") if p.stem != "__init__"}
    subpackages = {p.name for p in package.iterdir() if (p / "__init__.py").exists()}
    return modules | subpackages


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_a_package_text_names_every_module_it_holds(package):
    text = ast.get_docstring(ast.parse((package / "__init__.py").read_text())) or ""
    named = set(re.findall(r"`([a-z_]+)/?`", text))
    missing = sorted(_parts(package) - named)
    assert not missing, f"{package.relative_to(ROOT)}/__init__.py does not name: {missing}"
