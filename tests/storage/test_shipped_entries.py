"""The teeth and sphere trees of the demo's model ship inside the package: a fresh install's first
`orthosim demo` loads them, checked as every cache entry is, and builds nothing
(`orthosim.storage.shipped`, written by `tools/shipped_cache.py`)."""

from __future__ import annotations

import shutil
import warnings

import pytest

from orthosim.exchange.case import DEFAULT_CASE, load_case
from orthosim.model import dentition_cache
from orthosim.model.parametric import build_parametric_dentition
from orthosim.spheretree.cache import cached_sphere_trees
from orthosim.storage.shipped import SHIPPED_DIR

REGENERATE = "a builder changed: write them again with `python tools/shipped_cache.py` and commit them"


def _demo_parameters():
    model = load_case(DEFAULT_CASE).model
    return dentition_cache.parametric_parameters(model.resolution, model.third_molars, model.diastema_mm)


def test_the_demo_model_and_its_trees_load_from_the_shipped_entries_with_an_empty_cache(tmp_path):
    empty = tmp_path / "cache"
    dent = dentition_cache.cached_dentition(_demo_parameters(), lambda: pytest.fail(f"the teeth were built: {REGENERATE}"),
                                            cache_dir=empty)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a damaged shipped entry warns: here that is a failure
        trees = cached_sphere_trees([dent.teeth[n].mesh for n in dent.fdis], cache_dir=empty, workers=1)
    assert not empty.exists(), f"trees were built into the user's cache: {REGENERATE}"
    assert len(trees) == len(dent.fdis) == 28


def test_a_damaged_shipped_entry_is_rebuilt_to_the_clean_result_with_a_warning(tmp_path, monkeypatch):
    shipped = tmp_path / "shipped"
    shutil.copytree(SHIPPED_DIR, shipped)
    (entry,) = (shipped / "dentitions").glob("*.npz")
    data = bytearray(entry.read_bytes())
    data[len(data) // 2] ^= 0xFF  # one byte of the arrays flipped: its checksum fails
    entry.write_bytes(data)
    params = _demo_parameters()
    with monkeypatch.context() as patch, pytest.warns(dentition_cache.DentitionCacheWarning, match="damaged"):
        patch.setattr("orthosim.storage.shipped.SHIPPED_DIR", shipped)
        dent = dentition_cache.cached_dentition(params, lambda: build_parametric_dentition(
            params["resolution"], params["third_molars"], params["diastema_mm"]), cache_dir=tmp_path / "cache")
    clean = dentition_cache.cached_dentition(params, lambda: pytest.fail("the clean shipped entry was not read"),
                                             cache_dir=tmp_path / "elsewhere")
    for n in clean.fdis:
        assert (dent.teeth[n].mesh.vertices == clean.teeth[n].mesh.vertices).all()
        assert (dent.teeth[n].mesh.faces == clean.teeth[n].mesh.faces).all()
