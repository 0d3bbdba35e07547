"""Built dentitions come back from the disk cache unchanged; a damaged entry is rebuilt with a warning;
two processes filling the same entry at once both get whole teeth."""

import multiprocessing
import warnings

import numpy as np
import pytest
import trimesh

from model_helpers import small_dentition

from orthosim.model.dentition_cache import DentitionCacheWarning, cached_dentition, entry_path, is_cached

PARAMS = {"kind": "test", "size_mm": 8.0}


def build_counting(counter: list):
    def build():
        counter.append(1)
        warnings.warn("tooth 11: repaired mesh: filled 1 hole", UserWarning)
        return small_dentition()
    return build


def test_a_cached_dentition_is_the_built_one_and_is_not_built_again(tmp_path):
    built: list = []
    with pytest.warns(UserWarning, match="repaired mesh"):
        first = cached_dentition(PARAMS, build_counting(built), cache_dir=tmp_path)
    assert is_cached(PARAMS, cache_dir=tmp_path)
    with pytest.warns(UserWarning, match="repaired mesh"):  # the build's warnings come with every load
        again = cached_dentition(PARAMS, build_counting(built), cache_dir=tmp_path)
    assert len(built) == 1
    assert again.description == first.description and again.info == first.info
    for n, t in first.teeth.items():
        u = again.teeth[n]
        assert np.array_equal(u.mesh.vertices, t.mesh.vertices) and np.array_equal(u.mesh.faces, t.mesh.faces)
        assert np.array_equal(u.rest_pose, t.rest_pose) and np.array_equal(u.face_part, t.face_part)
        assert np.array_equal(u.landmarks["incisal_edge"], t.landmarks["incisal_edge"]) and u.source == t.source


def test_other_parameters_or_input_bytes_are_another_entry(tmp_path):
    mesh = tmp_path / "tooth_11.stl"
    mesh.write_bytes(b"solid a")
    key = entry_path(PARAMS, [mesh], tmp_path)
    assert entry_path({**PARAMS, "size_mm": 9.0}, [mesh], tmp_path) != key
    mesh.write_bytes(b"solid b")
    assert entry_path(PARAMS, [mesh], tmp_path) != key


def test_a_damaged_entry_is_rebuilt_with_a_one_line_warning(tmp_path):
    built: list = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cached_dentition(PARAMS, build_counting(built), cache_dir=tmp_path)
    path = entry_path(PARAMS, cache_dir=tmp_path)
    path.write_bytes(path.read_bytes()[:1000])  # cut short, as by a full disk
    with pytest.warns(DentitionCacheWarning, match="unreadable") as caught:
        dent = cached_dentition(PARAMS, build_counting(built), cache_dir=tmp_path)
    assert len(built) == 2 and set(dent.teeth) == {11, 21}
    assert all("\n" not in str(w.message) for w in caught)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        cached_dentition(PARAMS, build_counting(built), cache_dir=tmp_path)  # whole again: loaded
    assert len(built) == 2


def _fill(cache_dir, queue):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        dent = cached_dentition(PARAMS, small_dentition, cache_dir=cache_dir)
    queue.put(len(dent.teeth))


def test_two_processes_filling_one_entry_at_once_both_get_whole_teeth(tmp_path):
    ctx = multiprocessing.get_context("fork")
    queue = ctx.Queue()
    procs = [ctx.Process(target=_fill, args=(tmp_path, queue)) for _ in range(2)]
    for p in procs:
        p.start()
    for p in procs:
        p.join(60)
    assert [p.exitcode for p in procs] == [0, 0]
    assert sorted(queue.get(timeout=5) for _ in procs) == [2, 2]
    assert not list(tmp_path.glob(".*"))  # no temporary file left
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the entry loads without a damage warning
        assert len(cached_dentition(PARAMS, lambda: pytest.fail("rebuilt"), cache_dir=tmp_path).teeth) == 2


def test_a_cases_diastema_is_part_of_its_cached_model_not_served_from_the_same_teeth_without_it(tmp_path, monkeypatch):
    from orthosim import load_case

    monkeypatch.setenv("ORTHOSIM_CACHE", str(tmp_path / "cache"))
    teeth = tmp_path / "teeth"
    teeth.mkdir()
    for fdi, x in ((11, -3.5), (21, 3.5)):
        m = trimesh.creation.capsule(height=14.0, radius=3.0, count=[16, 16])
        m.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
        m.apply_translation([x, -8.0, 20.0])
        m.export(teeth / f"tooth_{fdi}.stl")
    text = ('[model]\nkind = "meshes"\nfolder = "teeth"\n{extra}[model.files]\n"tooth_11.stl" = 11\n"tooth_21.stl" = 21\n'
            '[treatment]\nduration_days = 10\nstep_days = 10\n')
    gaps = {}
    for name, extra in (("closed", ""), ("opened", "diastema_mm = 2.0\n")):
        (tmp_path / f"{name}.toml").write_text(text.format(extra=extra))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            dent = load_case(tmp_path / f"{name}.toml").build_dentition()
        gaps[name] = dent.teeth[21].rest_pose[0, 3] - dent.teeth[11].rest_pose[0, 3]
    assert gaps["opened"] == pytest.approx(gaps["closed"] + 2.0)


def test_every_module_the_builders_import_is_part_of_the_cache_key():
    """A dentition built by code the key does not cover would be served stale after that code changes:
    every orthosim module a builder module imports (at any depth in the file) is a builder module
    too, but for those that hold no geometry (errors, storage, the cache itself, the first-run line
    of system/firstrun) and the collision package, whose broad phase only lists candidate pairs."""
    import ast

    from pathlib import Path

    from orthosim.model import dentition_cache

    package = Path(dentition_cache.__file__).resolve().parents[1]  # orthosim/
    keyed = set(dentition_cache._BUILDER_MODULES)
    exempt = ("errors", "collision", "storage", "model/dentition_cache", "system/firstrun")

    def module_path(dotted: str) -> str | None:
        """orthosim.a.b -> "a/b" when that is a module file of the package (a package: None)."""
        rel = dotted.split(".")[1:]
        return "/".join(rel) if rel and (package / Path(*rel)).with_suffix(".py").is_file() else None

    missing, seen = set(), 0
    for name in keyed:
        tree = ast.parse((package / f"{name}.py").read_text())
        for node in ast.walk(tree):
            if not (isinstance(node, ast.ImportFrom) and node.level == 0 and (node.module or "").startswith("orthosim")):
                continue
            mods = [module_path(f"{node.module}.{a.name}") or module_path(node.module) for a in node.names]
            for m in filter(None, mods):
                seen += 1
                if m not in keyed and not any(m == e or m.startswith(e + "/") for e in exempt):
                    missing.add(f"{name} imports {m}")
    assert seen > 20  # the builders do import one another: the walk found them
    assert not missing, sorted(missing)
