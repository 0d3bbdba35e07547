"""orthosim draws through EGL or OSMesa: `--gl auto|egl|osmesa`, a machine without libOSMesa (Mesa
25.1 and later) renders through EGL, a backend that cannot start is one line before any work, the
three paper cases look the same through every backend here, and goldens key on the backend.

A missing system library is made faithfully: a `sitecustomize` in the child process makes ctypes
refuse to open it, as the dynamic loader does on a machine without the package (PyOpenGL and
orthosim's probe both open libOSMesa and libEGL through ctypes). Every drawing runs in a child
process, because PyOpenGL fixes its platform once per process.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from orthosim_render.imgdiff import GoldenSidecar, Tolerance, choose_mode, compare_images

ROOT = Path(__file__).resolve().parents[2]
CASES = ROOT / "cases"
PAPER_CASES = {  # as tests/render/test_golden_images.py shows them
    "case1_first_premolar_extraction": "right_buccal",
    "case2_second_premolar_extraction": "right_buccal",
    "case3_incisor_space_closure": "frontal",
}
_HIDE = textwrap.dedent("""
    import ctypes, os
    _hidden = tuple(n for n in os.environ.get("ORTHOSIM_TEST_HIDE_LIBS", "").split(",") if n)
    _open = ctypes.CDLL.__init__

    def _refuse(self, name, *args, **kwargs):
        if name and any(os.path.basename(str(name)).startswith(f"lib{h}.so") for h in _hidden):
            raise OSError(f"{name}: cannot open shared object file: No such file or directory")
        _open(self, name, *args, **kwargs)

    ctypes.CDLL.__init__ = _refuse
""")


def _env(tmp_path: Path, gl: str | None = None, hide: tuple[str, ...] = ()) -> dict:
    """The environment of a child: ORTHOSIM_GL as given (none: auto), `hide` libraries unloadable."""
    env = {k: v for k, v in os.environ.items() if k not in ("ORTHOSIM_GL", "PYOPENGL_PLATFORM", "PYTEST_ADDOPTS")}
    if gl:
        env["ORTHOSIM_GL"] = gl
    if hide:
        site = tmp_path / "hide-libs"
        site.mkdir(exist_ok=True)
        (site / "sitecustomize.py").write_text(_HIDE)
        env["PYTHONPATH"] = os.pathsep.join([str(site), *filter(None, [env.get("PYTHONPATH")])])
        env["ORTHOSIM_TEST_HIDE_LIBS"] = ",".join(hide)
    return env


def _orthosim(tmp_path, *args, gl=None, hide=()) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from orthosim.cli import entry; entry()", *map(str, args)],
                          cwd=ROOT, capture_output=True, text=True, env=_env(tmp_path, gl, hide), timeout=600)


def _python(tmp_path, code: str, gl=None, hide=()) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                          env=_env(tmp_path, gl, hide), timeout=600)


def _backends_here(tmp_path) -> list[str]:
    """Labels of the backends that start on this machine (probed in a child: the probe terminates EGL displays)."""
    done = _python(tmp_path, "from orthosim_render.offscreen_backend import available_backends as a; "
                             "print(','.join(dict.fromkeys(b.label for b in a())))")
    assert done.returncode == 0, done.stderr
    return [label for label in done.stdout.strip().split(",") if label]


def _has_egl(tmp_path) -> bool:
    return any(label.startswith("egl/") for label in _backends_here(tmp_path))


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_with_osmesa_hidden_a_case_renders_through_egl(tmp_path):
    if not _has_egl(tmp_path):
        pytest.skip("no EGL device can create a context on this machine")
    out = tmp_path / "run"
    done = _orthosim(tmp_path, "run", CASES / "case3_incisor_space_closure.toml", "--out", out, "--size", "160x120",
                     "--frames-per-step", "1", "-q", hide=("OSMesa",))
    assert done.returncode == 0, done.stderr
    render = json.loads((out / "run.json").read_text())["render"]
    assert render["gl_backend"].startswith("egl/") and render["frames"] > 1
    frames = sorted((out / "frames").glob("*.png"))
    assert len(frames) == render["frames"]
    # and OSMesa really is out of reach in that environment: asking for it is one line, exit 2, no folder
    refused = _orthosim(tmp_path, "run", CASES / "case3_incisor_space_closure.toml", "--out", tmp_path / "osmesa",
                        "--gl", "osmesa", hide=("OSMesa",))
    assert refused.returncode == 2 and "libosmesa6" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1 and "Traceback" not in refused.stderr
    assert not (tmp_path / "osmesa").exists()


def test_gl_egl_without_an_egl_library_is_one_line_naming_the_fix_before_any_work(tmp_path):
    out = tmp_path / "run"
    done = _orthosim(tmp_path, "run", CASES / "case3_incisor_space_closure.toml", "--out", out, "--gl", "egl",
                     hide=("EGL",))
    assert done.returncode == 2
    (line,) = done.stderr.strip().splitlines()
    assert line.startswith("orthosim: error: --gl egl") and "libegl" in line.lower() and "--no-render" in line
    assert not out.exists() and done.stdout == ""


def test_with_neither_library_drawing_is_refused_but_a_simulation_alone_runs(tmp_path):
    refused = _orthosim(tmp_path, "demo", "--out", tmp_path / "demo", hide=("EGL", "OSMesa"))
    assert refused.returncode == 2 and "neither EGL nor OSMesa" in refused.stderr
    assert not (tmp_path / "demo").exists()
    alone = _orthosim(tmp_path, "run", CASES / "case3_incisor_space_closure.toml", "--out", tmp_path / "alone",
                      "--no-render", "-q", hide=("EGL", "OSMesa"))
    assert alone.returncode == 0, alone.stderr
    assert json.loads((tmp_path / "alone" / "run.json").read_text())["render"] is None


def test_an_unknown_orthosim_gl_is_one_line_naming_the_choices(tmp_path):
    done = _orthosim(tmp_path, "demo", "--out", tmp_path / "demo", gl="vulkan")
    assert done.returncode == 2 and "ORTHOSIM_GL: vulkan: is not an OpenGL backend" in done.stderr
    assert "auto, egl, osmesa" in done.stderr and not (tmp_path / "demo").exists()


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_auto_prefers_egl_and_each_backend_is_what_draws(tmp_path):
    labels = _backends_here(tmp_path)
    if not labels:
        pytest.skip("no offscreen OpenGL on this machine")
    code = ("from orthosim_render.renderer import Renderer; r = Renderer((64, 48)); "
            "print(r.backend.label, '|', r.gl_renderer)")
    auto = _python(tmp_path, code)
    assert auto.returncode == 0, auto.stderr
    assert auto.stdout.split(" | ")[0] == labels[0]  # GPUs first, then Mesa's software device, then OSMesa
    if any(label.startswith("egl/") for label in labels):
        assert labels[0].startswith("egl/")
    for gl in ("egl", "osmesa"):
        if any(label.split("/")[0] == gl for label in labels):
            drawn = _python(tmp_path, code, gl=gl)
            assert drawn.returncode == 0, drawn.stderr
            assert drawn.stdout.split(" | ")[0].split("/")[0] == gl


_PAPER_FRAMES = textwrap.dedent("""
    import dataclasses, json, sys
    import numpy as np
    from orthosim_render.regression import render_case_frame
    cases = json.loads(sys.argv[1])
    frames = {name: render_case_frame(f"cases/{name}.toml", step=-1, view=view, size=(320, 240))
              for name, view in cases.items()}
    np.savez(sys.argv[2], **{name: f.image for name, f in frames.items()})
    print(json.dumps({name: f.sidecar.to_json() for name, f in frames.items()}))
""")


@pytest.mark.slow
def test_the_paper_cases_look_the_same_through_every_backend(tmp_path):
    """Each paper case's last step (320x240, as the goldens) through EGL and OSMesa: within imgdiff's tolerance."""
    labels = _backends_here(tmp_path)
    if len(labels) < 2:
        pytest.skip(f"fewer than two offscreen backends here ({labels})")
    drawn = {}
    for label in labels:
        npz = tmp_path / f"{label.replace('/', '_')}.npz"
        done = subprocess.run([sys.executable, "-c", _PAPER_FRAMES, json.dumps(PAPER_CASES), str(npz)], cwd=ROOT,
                              capture_output=True, text=True, env=_env(tmp_path, gl=label), timeout=600)
        assert done.returncode == 0, done.stderr
        sidecars = {k: GoldenSidecar.from_json({**v, "size": v["size"]}, label)
                    for k, v in json.loads(done.stdout.strip().splitlines()[-1]).items()}
        assert {s.gl_backend for s in sidecars.values()} == {label}
        drawn[label] = (np.load(npz), sidecars)
    reference, *others = labels
    for other in others:
        for case in PAPER_CASES:
            a, b = drawn[reference][0][case], drawn[other][0][case]
            comparison = compare_images(a, b, drawn[reference][1][case], drawn[other][1][case], Tolerance(),
                                        names=(f"{case} via {reference}", f"{case} via {other}"))
            assert comparison.mode == "tolerance"  # another backend: never held to the exact rule
            assert comparison.matched, comparison.summary()


def test_a_golden_is_exact_only_against_its_own_backend():
    golden = GoldenSidecar(gl_renderer="llvmpipe (LLVM 15.0.6, 256 bits)", mesa_version="22.3.6", gl_backend="egl/software")
    same = GoldenSidecar(gl_renderer=golden.gl_renderer, mesa_version="22.3.6", gl_backend="egl/software")
    other = GoldenSidecar(gl_renderer=golden.gl_renderer, mesa_version="22.3.6", gl_backend="osmesa")
    assert choose_mode(golden, same)[0] == "exact"
    mode, why = choose_mode(golden, other)
    assert mode == "tolerance" and "backend egl/software vs osmesa" in why


def test_a_sidecar_from_before_egl_names_no_backend_and_was_drawn_through_osmesa():
    # a sidecar as written before the EGL backend: a golden's own, without the field it since gained
    written = json.loads((ROOT / "tests" / "golden" / "normal_occlusion_frontal.json").read_text())
    written.pop("gl_backend", None)
    legacy = GoldenSidecar.from_json(written, "normal_occlusion_frontal.json")
    assert legacy.gl_backend is None
    osmesa = GoldenSidecar(gl_renderer=legacy.gl_renderer, mesa_version=legacy.mesa_version, gl_backend="osmesa")
    egl = GoldenSidecar(gl_renderer=legacy.gl_renderer, mesa_version=legacy.mesa_version, gl_backend="egl/software")
    assert choose_mode(legacy, osmesa)[0] == "exact"
    assert choose_mode(legacy, egl)[0] == "tolerance"


def test_a_pytest_session_that_never_asks_for_the_fixture_is_left_as_it_was(tmp_path):
    """The plugin loads in every pytest run where orthosim is installed: it must set no GL platform, import no OpenGL."""
    (tmp_path / "test_plain.py").write_text(textwrap.dedent("""
        import os, sys

        def test_nothing_of_orthosim_here(request):
            assert request.config.pluginmanager.has_plugin("orthosim")
            assert "PYOPENGL_PLATFORM" not in os.environ and "ORTHOSIM_GL" not in os.environ
            assert not [m for m in ("OpenGL", "pyrender", "orthosim_render.pyrender_setup") if m in sys.modules]
    """))
    env = _env(tmp_path)
    done = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "--rootdir", str(tmp_path),
                           "-c", os.devnull, str(tmp_path / "test_plain.py")], cwd=tmp_path, capture_output=True,
                          text=True, env=env, timeout=300)
    assert done.returncode == 0, done.stdout + done.stderr
    assert "1 passed" in done.stdout


_TWO_RENDERERS = textwrap.dedent("""
    import numpy as np
    from orthosim import load_case
    from orthosim_render.frame_state import FrameState
    from orthosim_render.renderer import Renderer
    from orthosim_render.scene import DentitionScene
    dent = load_case("cases/normal_occlusion.toml").build_dentition()
    state = FrameState(poses=dent.rest_poses(), extracted=frozenset())
    kept = Renderer((160, 120)); scene = DentitionScene(dent, (160, 120)); scene.update(state)
    before = kept.render(scene, "frontal")
    for _ in range(2):
        other = Renderer((160, 120)); s = DentitionScene(dent, (160, 120)); s.update(state)
        other.render(s, "frontal"); other.close()
    print(kept.backend.label, np.array_equal(before, kept.render(scene, "frontal")))
""")


@pytest.mark.slow  # over the fast tier's 2 s budget (tests/conftest.py)
def test_closing_one_renderer_leaves_the_others_of_the_process_drawing(tmp_path):
    """EGL has one display per device and process: closing a renderer must not terminate it under the others."""
    labels = _backends_here(tmp_path)
    if not labels:
        pytest.skip("no offscreen OpenGL on this machine")
    for gl in dict.fromkeys(label.split("/")[0] for label in labels):
        done = _python(tmp_path, _TWO_RENDERERS, gl=gl)
        assert done.returncode == 0, done.stderr
        label, same = done.stdout.split()
        assert label.split("/")[0] == gl and same == "True"
