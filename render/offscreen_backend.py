"""Which offscreen OpenGL backend draws this process's frames: EGL (a GPU, or Mesa's software device)
or OSMesa, decided once, in this one place, before PyOpenGL is first imported.

PyOpenGL fixes its platform (`PYOPENGL_PLATFORM`) at its own first import, so the choice cannot be
made by trying a backend through PyOpenGL and falling back: this module probes the system libraries
directly through ctypes (never importing PyOpenGL), then sets `PYOPENGL_PLATFORM` for the rest of
the process. The request comes from `--gl` / `ORTHOSIM_GL` (`auto`, `egl`, `osmesa`); without one,
a `PYOPENGL_PLATFORM` of `egl` or `osmesa` set by the user is honoured, else `auto`:
  - `auto`: an EGL device that is a GPU (EGL_EXT_device_enumeration lists it without
    EGL_MESA_device_software), else EGL on Mesa's software device (llvmpipe, surfaceless), else
    OSMesa (Mesa removed it in 25.1, so newer distributions lack libOSMesa);
  - `egl`: the same EGL order, never OSMesa; `osmesa`: OSMesa only.
An EGL device counts only if a context of the kind pyrender's EGL platform asks for (OpenGL 4.1 core,
RGB8 with a 24-bit depth buffer) can be created on it, and OSMesa only if its library exports
`OSMesaCreateContextAttribs`; a backend that cannot start is a `RenderSetupError` naming the fix
(exit 2 from the CLI), raised before any work.
"""

from __future__ import annotations

import ctypes
import os
import sys
from dataclasses import dataclass

from orthosim.errors import OrthosimError

ENV = "ORTHOSIM_GL"
CHOICES = ("auto", "egl", "osmesa")
# finer requests (ORTHOSIM_GL only; the bench measures each device kind in its own process)
DEVICE_CHOICES = ("egl/gpu", "egl/software", "egl/default")

# EGL enums (Khronos EGL 1.5 and the EXT/MESA device extensions)
_EGL_EXTENSIONS = 0x3055
_EGL_PLATFORM_DEVICE_EXT = 0x313F
_EGL_DRM_DEVICE_FILE_EXT = 0x3233
_EGL_DRM_RENDER_NODE_FILE_EXT = 0x3377
_EGL_OPENGL_API = 0x30A2
_CONFIG = (0x3033, 0x0001,  # SURFACE_TYPE: PBUFFER_BIT
           0x3022, 8, 0x3024, 8, 0x3023, 8, 0x3025, 24,  # BLUE, RED, GREEN 8 bits; DEPTH 24
           0x303F, 0x308E,  # COLOR_BUFFER_TYPE: RGB_BUFFER
           0x3040, 0x0008, 0x3042, 0x0008,  # RENDERABLE_TYPE, CONFORMANT: OPENGL_BIT
           0x3038)  # NONE
_CONTEXT = (0x3098, 4, 0x30FB, 1, 0x30FD, 0x1, 0x3038)  # OpenGL 4.1 core profile, as pyrender's EGL platform


class RenderSetupError(OrthosimError):
    """Offscreen OpenGL cannot start on this machine (a missing system library, usually)."""


@dataclass(frozen=True)
class GLBackend:
    """The backend that draws: `name` is PyOpenGL's platform ("egl" or "osmesa"); `device` is "gpu",
    "software" (Mesa's software device), "default" (EGL's default display, no device enumeration)
    or "osmesa"; `device_index` is the device's place in eglQueryDevicesEXT's list (None otherwise);
    `device_file` the DRM node EGL names for it, when it names one."""

    name: str
    device: str
    device_index: int | None = None
    device_file: str | None = None

    @property
    def label(self) -> str:
        """"egl/gpu", "egl/software", "egl/default" or "osmesa": what run.json, sidecars and the bench record."""
        return self.name if self.name == "osmesa" else f"{self.name}/{self.device}"


def _load(names: tuple[str, ...]):
    """The first of `names` that the dynamic loader opens (as PyOpenGL's loader tries them), or None."""
    for name in names:
        try:
            return ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
        except OSError:
            continue
    return None


def _so_names(base: str) -> tuple[str, ...]:
    return (f"lib{base}.so", *(f"lib{base}.so.{i}" for i in range(9, -1, -1)))


class _EGL:
    """The few EGL entry points the probe needs, bound through ctypes from libEGL."""

    def __init__(self, lib):
        vp, i32, ui = ctypes.c_void_p, ctypes.c_int32, ctypes.c_uint
        self.lib = lib
        lib.eglGetProcAddress.restype, lib.eglGetProcAddress.argtypes = vp, [ctypes.c_char_p]
        lib.eglQueryString.restype, lib.eglQueryString.argtypes = ctypes.c_char_p, [vp, i32]
        lib.eglInitialize.restype, lib.eglInitialize.argtypes = ui, [vp, ctypes.POINTER(i32), ctypes.POINTER(i32)]
        lib.eglTerminate.restype, lib.eglTerminate.argtypes = ui, [vp]
        lib.eglBindAPI.restype, lib.eglBindAPI.argtypes = ui, [ui]
        lib.eglChooseConfig.restype = ui
        lib.eglChooseConfig.argtypes = [vp, ctypes.POINTER(i32), ctypes.POINTER(vp), i32, ctypes.POINTER(i32)]
        lib.eglCreateContext.restype, lib.eglCreateContext.argtypes = vp, [vp, vp, vp, ctypes.POINTER(i32)]
        lib.eglDestroyContext.restype, lib.eglDestroyContext.argtypes = ui, [vp, vp]
        lib.eglGetDisplay.restype, lib.eglGetDisplay.argtypes = vp, [vp]
        self.query_devices = self._ext("eglQueryDevicesEXT", ui, i32, ctypes.POINTER(vp), ctypes.POINTER(i32))
        self.query_device_string = self._ext("eglQueryDeviceStringEXT", ctypes.c_char_p, vp, i32)
        self.platform_display = self._ext("eglGetPlatformDisplayEXT", vp, ui, vp, ctypes.POINTER(i32))

    def _ext(self, name: str, restype, *argtypes):
        address = self.lib.eglGetProcAddress(name.encode())
        return ctypes.CFUNCTYPE(restype, *argtypes)(address) if address else None

    def devices(self) -> list[tuple[int, object, str, str | None]]:
        """(index, handle, extensions, DRM file) of every EGL device; [] without device enumeration."""
        if self.query_devices is None or self.query_device_string is None or self.platform_display is None:
            return []
        count = ctypes.c_int32(0)
        if not self.query_devices(0, None, ctypes.byref(count)) or count.value < 1:
            return []
        handles = (ctypes.c_void_p * count.value)()
        if not self.query_devices(count.value, handles, ctypes.byref(count)):
            return []
        found = []
        for i in range(count.value):
            extensions = (self.query_device_string(handles[i], _EGL_EXTENSIONS) or b"").decode(errors="replace")
            drm = None
            for key, ext in ((_EGL_DRM_DEVICE_FILE_EXT, "EGL_EXT_device_drm "),
                             (_EGL_DRM_RENDER_NODE_FILE_EXT, "EGL_EXT_device_drm_render_node ")):
                if drm is None and ext in extensions + " ":
                    value = self.query_device_string(handles[i], key)
                    drm = value.decode(errors="replace") if value else None
            found.append((i, handles[i], extensions, drm))
        return found

    def can_create_context(self, display) -> bool:
        """Whether `display` initialises and creates a context like pyrender's EGL platform's (then dropped)."""
        lib = self.lib
        if not display or not lib.eglInitialize(display, None, None):
            return False
        try:
            config, n = ctypes.c_void_p(), ctypes.c_int32(0)
            attrs = (ctypes.c_int32 * len(_CONFIG))(*_CONFIG)
            if not lib.eglChooseConfig(display, attrs, ctypes.byref(config), 1, ctypes.byref(n)) or n.value < 1:
                return False
            if not lib.eglBindAPI(_EGL_OPENGL_API):
                return False
            context = lib.eglCreateContext(display, config, None, (ctypes.c_int32 * len(_CONTEXT))(*_CONTEXT))
            if not context:
                return False
            lib.eglDestroyContext(display, context)
            return True
        finally:
            lib.eglTerminate(display)


def probe_egl() -> list[GLBackend]:
    """Every EGL backend that can create a context here, GPUs first, then Mesa's software device
    (or EGL's default display when the library cannot enumerate devices); [] without libEGL."""
    lib = _load(("libEGL.so.1", "libEGL.so"))
    if lib is None:
        return []
    try:
        egl = _EGL(lib)
    except AttributeError:  # not an EGL library after all
        return []
    devices = egl.devices()
    if not devices:
        display = lib.eglGetDisplay(None)
        return [GLBackend("egl", "default")] if egl.can_create_context(display) else []
    found = []
    for index, handle, extensions, drm in devices:
        kind = "software" if "EGL_MESA_device_software" in extensions.split() else "gpu"
        if egl.can_create_context(egl.platform_display(_EGL_PLATFORM_DEVICE_EXT, handle, None)):
            found.append(GLBackend("egl", kind, index, drm))
    return sorted(found, key=lambda b: (b.device != "gpu", b.device_index))


def probe_osmesa() -> list[GLBackend]:
    """[the OSMesa backend] when libOSMesa loads (as PyOpenGL loads it) with OSMesaCreateContextAttribs; else []."""
    lib = _load(_so_names("OSMesa"))
    return [GLBackend("osmesa", "osmesa")] if lib is not None and hasattr(lib, "OSMesaCreateContextAttribs") else []


def available_backends() -> list[GLBackend]:
    """Every backend that can start here, in `auto`'s order of preference (probes; imports no PyOpenGL)."""
    return probe_egl() + probe_osmesa()


def requested() -> str:
    """The backend asked for: ORTHOSIM_GL, else a PYOPENGL_PLATFORM of egl/osmesa, else "auto"."""
    request = os.environ.get(ENV, "").strip().lower()
    if request:
        if request not in CHOICES + DEVICE_CHOICES:
            raise RenderSetupError(ENV, request, "is not an OpenGL backend", f"use one of {', '.join(CHOICES)}")
        return request
    platform = os.environ.get("PYOPENGL_PLATFORM", "").strip().lower()
    return platform if platform in ("egl", "osmesa") else "auto"


_FIXES = {
    "egl": "install Mesa's EGL (Debian: apt-get install libegl1 libegl-mesa0) or a GPU driver with EGL, "
           "or use --gl osmesa",
    "osmesa": "install OSMesa (Debian 12/13: apt-get install libosmesa6; gone from Mesa 25.1), or use --gl egl",
    "auto": "install Mesa's EGL (Debian: apt-get install libegl1 libegl-mesa0) or OSMesa (libosmesa6)",
}


def choose(request: str) -> GLBackend:
    """The backend `request` ("auto", "egl", "osmesa", or an EGL device kind such as "egl/software")
    gets here, or RenderSetupError naming the fix."""
    if request not in CHOICES + DEVICE_CHOICES:
        raise RenderSetupError("--gl", request, "is not an OpenGL backend", f"use one of {', '.join(CHOICES)}")
    if request == "osmesa":
        candidates = probe_osmesa()
    else:
        candidates = probe_egl()
        if request in DEVICE_CHOICES:
            candidates = [b for b in candidates if b.label == request]
            request = "egl"
        elif request == "auto" and not candidates:  # OSMesa only where no EGL device starts
            candidates = probe_osmesa()
    if not candidates:
        what = {"auto": "neither EGL nor OSMesa", "egl": "no EGL device", "osmesa": "OSMesa"}[request]
        raise RenderSetupError(f"--gl {request}", None, f"cannot start offscreen OpenGL: {what} can create a "
                               "context on this machine", _FIXES[request] + ", or run with --no-render")
    return candidates[0]


_chosen: GLBackend | None = None


def _pyopengl_platform() -> str | None:
    """PyOpenGL's platform if it is already imported in this process ("egl", "osmesa", other), else None."""
    module = sys.modules.get("OpenGL.platform")
    platform = getattr(module, "PLATFORM", None) if module is not None else None
    if platform is None:
        return None
    name = type(platform).__name__.lower()
    return "egl" if "egl" in name else "osmesa" if "osmesa" in name else name


def select(request: str | None = None) -> GLBackend:
    """Decide this process's backend (once; later calls return it) and set PYOPENGL_PLATFORM to match.

    `request` None reads ORTHOSIM_GL (see `requested`). A second call asking for another backend, or
    PyOpenGL already imported with another platform, is a RenderSetupError: the platform is per process.
    """
    global _chosen
    request = requested() if request is None else request
    if _chosen is not None:
        if request not in ("auto", _chosen.name, _chosen.label):
            raise RenderSetupError("--gl", request, f"this process already draws through {_chosen.label}",
                                   "choose the backend once, before anything is drawn (a new process for another)")
        return _chosen
    loaded = _pyopengl_platform()
    if loaded in ("egl", "osmesa") and request == "auto":
        request = loaded  # PyOpenGL's platform is fixed already: auto can only mean that one
    backend = choose(request)
    if loaded is not None and loaded != backend.name:
        raise RenderSetupError("PYOPENGL_PLATFORM", loaded, f"PyOpenGL was imported before orthosim chose {backend.label}",
                               f"set {ENV}={loaded} (or import orthosim_render before OpenGL)")
    os.environ["PYOPENGL_PLATFORM"] = backend.name
    _chosen = backend
    return backend


