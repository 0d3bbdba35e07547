"""A damaged sphere-tree cache entry never reaches a run: it is named in one warning and rebuilt;
and two processes writing and reading one entry at once never see a partial file."""

from __future__ import annotations

import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from cli_helpers import said_lines
import trimesh

from orthosim.spheretree import build_sphere_tree, cached_sphere_tree
from orthosim.spheretree.cache import DamagedCacheWarning, save_tree

ROOT = Path(__file__).resolve().parents[2]


def _mesh() -> trimesh.Trimesh:
    return trimesh.creation.capsule(height=8.0, radius=2.5, count=[16, 16])


def _entry(folder: Path) -> Path:
    (path,) = folder.glob("*.npz")
    return path


def _rewrite(path: Path, change) -> None:
    with np.load(path) as z:
        arrays = {k: z[k].copy() for k in z.files}
    change(arrays)
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)


def _shrink_leaves(a):
    a["r3"] *= 0.5


def _nan_centre(a):
    a["c2"][0, 1] = np.nan


def _infinite_radius(a):
    a["r1"][0] = np.inf


DAMAGE = {
    "empty": lambda p: p.write_bytes(b""),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
    "garbage": lambda p: p.write_bytes(b"\x00\xffnot a sphere tree" * 50),
    "non-finite centre": lambda p: _rewrite(p, _nan_centre),
    "infinite radius": lambda p: _rewrite(p, _infinite_radius),
    "spheres that do not bound the mesh": lambda p: _rewrite(p, _shrink_leaves),
    "a level missing": lambda p: _rewrite(p, lambda a: [a.pop(k) for k in ("c3", "r3", "p3")]),
}


@pytest.mark.parametrize("kind", DAMAGE)
def test_a_damaged_entry_is_reported_in_one_warning_and_rebuilt(tmp_path, kind):
    mesh = _mesh()
    fresh = cached_sphere_tree(mesh, cache_dir=tmp_path)
    entry = _entry(tmp_path)
    DAMAGE[kind](entry)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tree = cached_sphere_tree(mesh, cache_dir=tmp_path)
    damaged = [w for w in caught if issubclass(w.category, DamagedCacheWarning)]
    assert len(damaged) == 1, [str(w.message) for w in caught]
    message = str(damaged[0].message)
    assert "\n" not in message and entry.name in message and "rebuilding" in message
    tree.validate(mesh.vertices, mesh.faces)  # the tree used is whole and bounds the mesh
    for k in range(fresh.depth):
        np.testing.assert_array_equal(tree.centers[k], fresh.centers[k])
        np.testing.assert_array_equal(tree.radii[k], fresh.radii[k])
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the entry was written again: the next load is silent
        cached_sphere_tree(mesh, cache_dir=tmp_path)


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_a_run_with_a_damaged_cache_warns_once_and_matches_a_clean_run(tmp_path, monkeypatch):
    """Through `orthosim run`: an empty entry is no abort, a non-finite one no silent wrong answer."""
    from cli_helpers import orthosim as run, quick_case

    case = quick_case(tmp_path, steps=1)
    env_cache = tmp_path / "cache"
    monkeypatch.setenv("ORTHOSIM_CACHE", str(env_cache))
    clean = run("run", case, "--out", tmp_path / "clean", "--no-render")
    assert clean.returncode == 0, clean.stderr
    entries = sorted(env_cache.glob("*.npz"))
    entries[0].write_bytes(b"")
    _rewrite(entries[1], _nan_centre)
    damaged = run("run", case, "--out", tmp_path / "damaged", "--no-render")
    assert damaged.returncode == 0, damaged.stderr
    lines = said_lines(damaged.stderr)
    assert len(lines) == 2 and all(l.startswith("orthosim: warning: sphere-tree cache entry ") for l in lines), lines
    assert damaged.stdout.split(" -> ")[0] == clean.stdout.split(" -> ")[0]  # same collisions, same penetration


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_two_processes_writing_and_reading_one_entry_never_see_a_partial_file(tmp_path):
    mesh = _mesh()
    tree = build_sphere_tree(mesh)
    target = tmp_path / "entry.npz"
    save_tree(tree, target)
    writer = subprocess.Popen([sys.executable, "-c", textwrap.dedent(f"""
        import sys
        from orthosim.spheretree.cache import load_tree, save_tree
        tree = load_tree({str(target)!r})
        print("ready", flush=True)
        for _ in range(300):
            save_tree(tree, {str(target)!r})
        """)], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    from orthosim.spheretree.cache import damage, load_tree

    reads = 0
    try:
        assert writer.stdout.readline().strip() == "ready"
        while writer.poll() is None:
            seen = load_tree(target)  # raises on a partial file
            assert damage(seen, mesh.vertices, mesh.faces, tree.branching, tree.depth) is None
            reads += 1
    finally:
        writer.wait(timeout=60)
    assert writer.returncode == 0 and reads > 10
    assert sorted(p.name for p in tmp_path.iterdir()) == ["entry.npz"]  # no temporary file left
