"""Test helpers for case files: a small valid case to edit, written to a folder, and a refusal read back."""

from __future__ import annotations

import pytest

from orthosim.errors import CaseError
from orthosim import load_case

BASE = """
[model]
kind = "parametric"
[treatment]
extractions = [14]
duration_days = 10
step_days = 1
[wire]
type = "rectangular"
[[loads]]
teeth = [16]
force_cN = 150
direction = "mesial"
"""


def write(tmp_path, text):
    """`text` written as tmp_path/case.toml; its path."""
    p = tmp_path / "case.toml"
    p.write_text(text)
    return p


def refused(tmp_path, text) -> str:
    """The one-line CaseError that loading `text` raises (asserted one line, naming the file and a fix)."""
    with pytest.raises(CaseError) as err:
        load_case(write(tmp_path, text))
    msg = str(err.value)
    assert "\n" not in msg and str(tmp_path / "case.toml") in msg and "fix:" in msg
    return msg
