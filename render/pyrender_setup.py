"""The one place that imports pyrender and OpenGL, with the fixes they need to run headless here.

Every module of `render/` that needs pyrender gets it through `load_pyrender()`, so the order of
the steps below is guaranteed whichever module is imported first:
  1. the offscreen backend (EGL or OSMesa, `orthosim_render.offscreen_backend`) chosen, and PYOPENGL_PLATFORM
     set to it, before OpenGL loads, so tests and the CLI render without a display and without the
     user setting anything;
  2. PyOpenGL's per-call `glGetError` check switched off (`OPENGL_ERROR_CHECKING=1` in the
     environment turns it back on for debugging): it doubles the cost of every GL call and the
     renderer makes a few hundred per frame;
  3. `np.infty` restored for numpy 2 (pyrender's mesh bounds still use the removed alias);
  4. `pyrender.viewer` replaced by an empty module, because importing it pulls in pyglet and the
     on-screen libGL that a headless machine may not have;
  5. pyrender's shader cache keyed on the integer value of the current context: under OSMesa
     `OpenGL.contextdata.getContext()` returns a fresh ctypes pointer object on every call, so
     the stock cache never hits, recompiles every shader on every draw (~4 fps) and leaks the
     programs (gigabytes over a long run).
"""

from __future__ import annotations

import ctypes
import os
import sys
import types

from orthosim_render.offscreen_backend import RenderSetupError, select

_loaded = None

__all__ = ["RenderSetupError", "load_pyrender", "offscreen_platform", "shader_dir"]


def _egl_platform(backend, width: int, height: int):
    from pyrender.platforms import egl

    if backend.device_index is None:
        device = egl.EGLDevice(None)  # EGL's default display
    else:
        devices = egl.query_devices()
        if backend.device_index >= len(devices):
            raise RuntimeError(f"EGL lists {len(devices)} devices now, not device {backend.device_index}")
        device = devices[backend.device_index]
    platform = _shared_display_platform(egl)(width, height, device=device)
    platform.init_context()
    if not platform._egl_context:
        raise RuntimeError("eglCreateContext returned no context")
    return platform


def _shared_display_platform(egl):
    """pyrender's EGLPlatform, except that closing it destroys its context only, never the display.

    EGL has one display per device and process, shared by every context on it: pyrender's
    `delete_context` terminates it, which kills every other renderer of the process (the bench's
    renderers, a test's cached one) at their next `eglMakeCurrent`. The display stays initialised
    until the process ends; a later context re-initialises it (a no-op) and uses it.
    """
    class SharedDisplayEGLPlatform(egl.EGLPlatform):
        def delete_context(self):
            from OpenGL.EGL import EGL_NO_CONTEXT, EGL_NO_SURFACE, eglDestroyContext, eglMakeCurrent

            if self._egl_display is not None and self._egl_context is not None:
                eglMakeCurrent(self._egl_display, EGL_NO_SURFACE, EGL_NO_SURFACE, EGL_NO_CONTEXT)
                eglDestroyContext(self._egl_display, self._egl_context)
            self._egl_context = None
            self._egl_display = None

    return SharedDisplayEGLPlatform


def _osmesa_platform(width: int, height: int):
    from pyrender.platforms.osmesa import OSMesaPlatform

    platform = OSMesaPlatform(width, height)
    platform.init_context()
    if not platform._context:
        raise RuntimeError("OSMesaCreateContextAttribs returned no context")
    return platform


def offscreen_platform(width: int, height: int):
    """A current offscreen GL context (pyrender's platform object) of `width` x `height` px, through
    the backend this process chose (`glbackend.select`), or a one-line RenderSetupError."""
    load_pyrender()
    backend = select()
    try:
        platform = (_egl_platform(backend, width, height) if backend.name == "egl"
                    else _osmesa_platform(width, height))
        platform.make_current()
    except (ImportError, OSError, AttributeError, RuntimeError, AssertionError, ValueError) as exc:
        raise RenderSetupError("--gl", backend.label,
                               f"cannot create an offscreen context ({type(exc).__name__}: {exc})",
                               "choose another backend with --gl (or ORTHOSIM_GL), or run with --no-render") from exc
    platform.orthosim_backend = backend
    return platform


def _context_key(cid) -> int:
    """The current GL context as a stable integer, whatever type PyOpenGL's platform returns."""
    if cid is None:
        return 0
    if isinstance(cid, int):
        return cid
    value = getattr(cid, "value", None)  # c_void_p and friends
    if isinstance(value, int):
        return value
    try:
        return ctypes.cast(cid, ctypes.c_void_p).value or 0
    except (TypeError, ctypes.ArgumentError):
        return id(cid)


def _patch_shader_cache(pyrender_shader_program) -> None:
    import OpenGL.contextdata

    cache_cls = pyrender_shader_program.ShaderProgramCache
    if getattr(cache_cls, "_orthosim_patched", False):
        return
    ShaderProgram = pyrender_shader_program.ShaderProgram

    def get_program(self, vertex_shader, fragment_shader, geometry_shader=None, defines=None):
        defines = defines or {}
        names = [os.path.basename(fn) for fn in (vertex_shader, fragment_shader, geometry_shader) if fn is not None]
        key = (_context_key(OpenGL.contextdata.getContext()),) + tuple(
            sorted([(s, 1) for s in names] + [(d, defines[d]) for d in defines])
        )
        program = self._program_cache.get(key)
        if program is None:
            paths = [os.path.join(self.shader_dir, fn) if fn is not None else None
                     for fn in (vertex_shader, fragment_shader, geometry_shader)]
            program = ShaderProgram(vertex_shader=paths[0], fragment_shader=paths[1],
                                    geometry_shader=paths[2], defines=defines)
            self._program_cache[key] = program
        return program

    cache_cls.get_program = get_program
    cache_cls._orthosim_patched = True


def load_pyrender():
    """Import pyrender with the headless fixes applied (idempotent); returns the module."""
    global _loaded
    if _loaded is not None:
        return _loaded
    backend = select()  # sets PYOPENGL_PLATFORM: PyOpenGL reads it once, at its first import
    import OpenGL

    if "OpenGL.GL" not in sys.modules:
        OpenGL.ERROR_CHECKING = os.environ.get("OPENGL_ERROR_CHECKING", "") == "1"
    if backend.name == "egl":
        import OpenGL.raw.EGL._errors as egl_errors

        # PyOpenGL 3.1.10 defines the EGL error checker only when checking is on (its else branch
        # sets another name), so OpenGL.EGL cannot import with checking off: no checker is meant
        if not hasattr(egl_errors, "_error_checker"):
            egl_errors._error_checker = None
    import numpy as np

    if not hasattr(np, "infty"):
        np.infty = np.inf
    if "pyrender.viewer" not in sys.modules:
        stub = types.ModuleType("pyrender.viewer")
        stub.__doc__ = "orthosim stub: the interactive pyglet viewer is never used headless."

        class Viewer:  # noqa: D401 - placeholder with the name pyrender exports
            def __init__(self, *args, **kwargs):
                raise RuntimeError("pyrender's on-screen Viewer is disabled in orthosim (headless)")

        stub.Viewer = Viewer
        sys.modules["pyrender.viewer"] = stub
    import pyrender
    import pyrender.shader_program

    _patch_shader_cache(pyrender.shader_program)
    _loaded = pyrender
    return pyrender


def shader_dir() -> str:
    """Folder of orthosim's own GLSL shaders (Lambert shading; see render/shaders/)."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "shaders")
