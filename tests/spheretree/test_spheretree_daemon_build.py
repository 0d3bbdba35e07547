"""Trees built inside a daemonic process (the simulation child of a drawn run) are the trees built anywhere else.

A daemonic process may not start worker processes, so `cached_sphere_trees` builds there on threads;
a user relies on the same mesh giving the same tree, bit for bit, whichever process built it.
"""

from __future__ import annotations

import multiprocessing

import numpy as np
import trimesh

from orthosim.spheretree import cached_sphere_trees


def _meshes() -> list[trimesh.Trimesh]:
    return [trimesh.creation.capsule(height=8.0, radius=2.5, count=[16, 16]),
            trimesh.creation.capsule(height=5.0, radius=3.0, count=[12, 12]),
            trimesh.creation.icosphere(subdivisions=2, radius=4.0)]


def _arrays(trees) -> list[list[np.ndarray]]:
    return [[*t.centers, *t.radii, *t.parents, t.leaf_of_face] for t in trees]


def _build_in_daemon(cache_dir: str, out) -> None:
    assert multiprocessing.current_process().daemon
    out.put(_arrays(cached_sphere_trees(_meshes(), depth=3, cache_dir=cache_dir, workers=2, shipped=False)))


def test_a_daemonic_process_builds_the_same_trees_on_several_workers(tmp_path):
    context = multiprocessing.get_context("fork")
    out = context.Queue()
    child = context.Process(target=_build_in_daemon, args=(str(tmp_path / "daemon"), out), daemon=True)
    child.start()
    in_daemon = out.get()
    child.join()
    assert child.exitcode == 0
    serial = _arrays(cached_sphere_trees(_meshes(), depth=3, cache_dir=tmp_path / "serial", workers=1, shipped=False))
    assert len(in_daemon) == len(serial) == 3
    for a, b in zip(in_daemon, serial):
        assert len(a) == len(b)
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    assert len(list((tmp_path / "daemon").glob("*.npz"))) == 3  # each built once and stored
