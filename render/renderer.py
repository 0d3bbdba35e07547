"""The renderer: owns the offscreen OpenGL context (EGL or OSMesa, `orthosim_render.offscreen_backend`) and turns a `DentitionScene` into pixels.

Drawing goes through a subclass of pyrender's `Renderer` (pyrender still owns meshes, buffers and
the shader cache); each change below is measured by `orthosim bench` (bench/render.py,
`render_variants`):
  - our shaders (render/shaders/) instead of pyrender's physically based ones, with lighting
    evaluated per vertex;
  - a lean forward pass that binds the program, camera and lights once per frame, not once per
    primitive, with cached uniform locations;
  - contact markers as point sprites, one draw call for thousands;
  - teeth that did not move drawn once into a cached colour+depth image per view; a frame copies
    it and draws only what moved (bit-identical to a full redraw, see `_mark_static`);
  - colour-only read-back of our own framebuffer (pyrender also reads and linearises depth).
Anti-aliasing (4x multisampling through pyrender's framebuffer path) is optional and slower.

Before each draw the renderer uploads the buffers the scene changed (`DentitionScene.buffer_versions`):
contact markers go into a preallocated buffer with `glBufferSubData`, grown by doubling, so a
2,000-frame run allocates a handful of GL buffers, not 2,000. One scene's GPU buffers live in one
context: a scene is drawn by one renderer (switching a renderer between scenes re-uploads).
"""

from __future__ import annotations

import weakref

import numpy as np

from orthosim_render.pyrender_setup import load_pyrender, offscreen_platform, shader_dir




class Renderer:
    """Offscreen renderer of fixed image size; use as a context manager or call `close()`."""

    def __init__(self, size: tuple[int, int] = (640, 480), *, alpha: bool = False, msaa: bool = False,
                 shading: str = "lambert", lean: bool = True, lighting: str = "vertex", static_cache: bool = True):
        """`shading` "pbr" (pyrender's own shaders) and `lean=False` (pyrender's stock forward pass)
        exist only so that the bench can measure what each optimisation buys."""
        pyrender = load_pyrender()
        from OpenGL import GL

        self._GL = GL
        self._pyrender = pyrender
        self.size = (int(size[0]), int(size[1]))
        self.alpha = alpha
        self.msaa = msaa
        w, h = self.size
        self._platform = None
        self._platform = offscreen_platform(w, h)
        self.backend = self._platform.orthosim_backend  # glbackend.GLBackend: what draws
        if lean and shading != "lambert":
            raise ValueError("the lean forward pass drives orthosim's Lambert shaders only")
        if lean:
            from orthosim_render.lean_renderer import LeanRenderer  # after the platform above is chosen

            self._inner = LeanRenderer(w, h, lighting=lighting)
        else:
            self._inner = pyrender.Renderer(w, h)
        if shading == "lambert":
            # Our shaders replace pyrender's; the cache is created by pyrender.Renderer.__init__.
            self._inner._program_cache = pyrender.shader_program.ShaderProgramCache(shader_dir=shader_dir())
        self.shading = shading
        self.lean = lean
        self.lighting = lighting if lean else "pixel"
        self.static_cache = static_cache and lean and not msaa
        if lean:
            self._inner.read_channels = 4 if alpha else 3
        # weak keys: a renderer that outlives many scenes must not keep their meshes alive
        self._seen_versions = weakref.WeakKeyDictionary()
        self._instance_capacity = weakref.WeakKeyDictionary()
        self._flags = pyrender.RenderFlags.NONE
        # EGL has no window framebuffer to read back: pyrender's stock pass draws into its own there
        if msaa or (not lean and self.backend.name != "osmesa"):
            self._flags |= pyrender.RenderFlags.OFFSCREEN | pyrender.RenderFlags.RGBA
            # pyrender would read and linearise depth too: read colour only
            self._inner._read_main_framebuffer = self._read_msaa_colour
        self.frames = 0

    # --------------------------------------------------------------------------------- info
    @property
    def gl_renderer(self) -> str:
        """The GL renderer string (e.g. 'llvmpipe (LLVM 15.0.6, 256 bits)'), for the bench record."""
        self._platform.make_current()
        return self._GL.glGetString(self._GL.GL_RENDERER).decode(errors="replace")

    @property
    def gl_version(self) -> str:
        self._platform.make_current()
        return self._GL.glGetString(self._GL.GL_VERSION).decode(errors="replace")

    # ------------------------------------------------------------------------------ drawing
    def render(self, scene, view: str | None = None) -> np.ndarray:
        """Draw `scene` from preset `view` (the scene's current one if None).

        Returns (h, w, 3) uint8 RGB, or (h, w, 4) RGBA with a transparent background when the
        renderer was made with alpha=True. Reads the scene, never changes it, except for selecting
        `view` on it.
        """
        if view is not None and (scene.current_view is None or scene.current_view.name != view):
            scene.set_view(view)
        self._platform.make_current()
        self._sync_buffers(scene)
        if self.lean:
            self._mark_static(scene)
        out = self._inner.render(scene.scene, self._flags)
        if self._flags & self._pyrender.RenderFlags.OFFSCREEN:
            rgba = out
        elif self.lean:
            return out  # already top row first, with the channels asked for (see _forward_pass)
        else:
            self._GL.glFinish()
            buf = np.asarray(self._platform._buffer)  # (h, w, 4) uint8, OSMesa's own colour buffer
            rgba = buf[::-1]  # OSMesa stores the bottom row first
        self.frames += 1
        if self.alpha:
            return np.ascontiguousarray(rgba)
        return np.ascontiguousarray(rgba[:, :, :3])

    def render_labelled(self, scene, node_labels: dict, view: str | None = None):
        """Draw `scene` as `render` does and, in the same pass, what each pixel shows (semantic goldens,
        `orthosim_render.semantic_labels`): returns (image as `render` returns it, labels (h, w) uint16, depth
        (h, w) float32 window depth in [0, 1], 1.0 where nothing is drawn), top row first.

        `node_labels`: pyrender node -> label id (1-65535); contact sprites carry their own ids in
        their texture coordinate's second component. The colour image is the one `render` draws (the
        label target is a second output of the same shaders). Lean renderers without multisampling only.
        """
        if not self.lean or self.msaa or self.lighting != "vertex":
            raise ValueError("the label target needs the lean forward pass, vertex lighting and no multisampling")
        if view is not None and (scene.current_view is None or scene.current_view.name != view):
            scene.set_view(view)
        self._platform.make_current()
        self._sync_buffers(scene)
        self._mark_static(scene)
        self._inner.label_ids = node_labels
        try:
            image, labels, depth = self._inner.render(scene.scene, self._flags)
        finally:
            self._inner.label_ids = None
        self.frames += 1
        return image, labels, depth

    def _mark_static(self, scene) -> None:
        """Tell the forward pass which teeth can come from its cached image, and under what key.

        Static: visible, not moving in the current state, vertex colours not painted by contacts.
        The key holds everything that changes how those teeth look (scene, view, their poses, tint
        and buffer versions): the cache is redrawn whenever any of it changes, so the cache can
        make a frame faster but never different.
        """
        inner = self._inner
        if not self.static_cache or scene.state is None:
            inner.static_nodes = inner.static_key = None
            return
        moving = scene.state.moving
        static = [d for fdi, d in scene.teeth.items() if d.mesh.is_visible and fdi not in moving and not d.painted]
        view = scene.current_view.name
        versions = scene.buffer_versions
        key = (scene.uid, view, tuple(d.fdi for d in static), tuple(d.tinted for d in static),
               tuple(versions.get(d.primitive, 0) for d in static),
               b"".join(np.asarray(d.node._matrix, np.float64).tobytes() for d in static))
        inner.static_nodes = frozenset(d.node for d in static)
        inner.static_key = key
        inner.cache_name = (scene.uid, view)
        inner.drop_caches(keep_scene=scene.uid)  # cached images of other scenes are dead weight

    def _read_msaa_colour(self, scene, flags):
        GL = self._GL
        inner = self._inner
        w, h = inner._main_fb_dims
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb_ms)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, inner._main_fb)
        GL.glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL.GL_COLOR_BUFFER_BIT, GL.GL_LINEAR)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, inner._main_fb)
        data = GL.glReadPixels(0, 0, w, h, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE)
        rows = np.frombuffer(data, dtype=np.uint8).reshape(h, w, 4)
        return rows if self.lean else rows[::-1]  # the lean pass draws mirrored (top row first)

    def _sync_buffers(self, scene) -> None:
        """Upload the primitives the scene changed since the last draw (see DentitionScene.buffer_versions)."""
        for prim, version in scene.buffer_versions.items():
            if self._seen_versions.get(prim) == version:
                continue
            self._seen_versions[prim] = version
            if not prim._in_context():
                # first draw, or back after another scene: pyrender uploads the arrays as they are
                self._instance_capacity.pop(prim, None)
                continue
            if prim is scene.markers:
                self._upload_markers(prim)
            else:
                # vertex colours changed (contact faces): rebuild this primitive's buffers
                prim.delete()
                prim._add_to_context()

    def _upload_markers(self, prim) -> None:
        """Copy the marker arrays into the GL buffer, growing it (by doubling) only when too small."""
        GL = self._GL
        sprite = prim.mode == self._pyrender.GLTF.POINTS
        if sprite:
            live = (prim._positions, prim._texcoord_0)
            n = len(live[0])
            data = np.hstack(live).astype(np.float32, copy=False)  # pyrender's interleaved layout
            buffer = prim._buffers[0]
        else:
            live = prim._poses
            n = len(live)
            data = live.transpose(0, 2, 1)  # GL wants column-major matrices
            buffer = prim._buffers[1]
        capacity = self._instance_capacity.get(prim, 1)
        if n > capacity:
            capacity = max(n, 2 * capacity, 256)
            prim.delete()
            # allocate at full capacity once, but draw only the live markers
            if sprite:
                prim._positions = np.zeros((capacity, 3), np.float32)
                prim._texcoord_0 = np.zeros((capacity, 2), np.float32)
                prim._positions[:n], prim._texcoord_0[:n] = live
                prim._add_to_context()
                prim._positions, prim._texcoord_0 = live
            else:
                padded = np.zeros((capacity, 4, 4), np.float32)
                padded[:n] = live
                prim._poses = padded
                prim._add_to_context()
                prim._poses = live
            self._instance_capacity[prim] = capacity
            return
        data = np.ascontiguousarray(data, dtype=np.float32)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, buffer)
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, data.nbytes, data)
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, 0)

    # ------------------------------------------------------------------------------ cleanup
    def close(self) -> None:
        if self._platform is None:
            return
        self._platform.make_current()
        if self.lean:
            self._inner.delete_fbos()
        self._inner.delete()
        self._platform.delete_context()
        self._platform = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass
