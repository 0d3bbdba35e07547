"""The lean forward pass: a pyrender Renderer that binds the program, camera and lights once per frame.

Why: the stock pass re-binds the program, camera matrices and every light uniform for every
primitive, each uniform through a `glGetUniformLocation` lookup and PyOpenGL's argument
wrapping; with 28 teeth that is ~600 wrapped GL calls and most of the frame time on this
machine. Here a frame costs a fixed ~20 calls plus 4 per visible node (model matrix, colour
factor, vertex array, draw). Uniform locations are cached per program. Only what our scenes
use is supported: opaque triangle primitives without textures, directional lights, our shaders.

Imported only by `orthosim_render.renderer.Renderer`, after `orthosim_render.pyrender_setup.load_pyrender` has chosen
the GL platform (PyOpenGL fixes it at its first import).
"""

from __future__ import annotations

import numpy as np

from orthosim_render.pyrender_setup import load_pyrender

pyrender = load_pyrender()
from OpenGL import GL  # noqa: E402 (after load_pyrender: it chooses the platform PyOpenGL loads)
from pyrender.constants import BufFlags  # noqa: E402


class LeanRenderer(pyrender.Renderer):
    def __init__(self, *args, lighting: str = "vertex", **kwargs):
        super().__init__(*args, **kwargs)
        self._locations: dict[tuple[int, str], int] = {}
        self._fbos: dict = {}
        self._cache_keys: dict = {}  # view -> key of the static image held in its cache
        self._previous_keys: dict = {}  # view -> static key of the previous frame
        self.static_nodes = None  # set per frame by Renderer.render
        self.static_key = None
        self.cache_name = None
        self.cache_hits = self.cache_builds = 0
        self.read_channels = 3  # 4 for RGBA output, set by Renderer
        self.label_ids = None  # node -> label id while a frame is drawn with its label target
        self._shader_files = ("gouraud.vert", "gouraud.frag") if lighting == "vertex" else ("mesh.vert", "mesh.frag")

    def _program_for(self, primitive, n_lights: int):
        # Attribute locations follow pyrender's Primitive._add_to_context buffer layout.
        defines = {}
        loc = 1
        bf = primitive.buf_flags
        for flag, name in ((BufFlags.NORMAL, "NORMAL_LOC"), (BufFlags.TANGENT, "TANGENT_LOC"),
                           (BufFlags.TEXCOORD_0, "TEXCOORD_0_LOC"), (BufFlags.TEXCOORD_1, "TEXCOORD_1_LOC"),
                           (BufFlags.COLOR_0, "COLOR_0_LOC")):
            if bf & flag:
                defines[name] = loc
                loc += 1
        defines["INST_M_LOC"] = loc
        defines["MAX_DIRECTIONAL_LIGHTS"] = max(n_lights, 1)
        if self.label_ids is not None:
            defines["LABEL_TARGET"] = 1
        program = self._program_cache.get_program(*self._shader_files, defines=defines)
        if not program._in_context():
            program._add_to_context()
        return program

    def _loc(self, program, name: str) -> int:
        key = (program._program_id, name)
        loc = self._locations.get(key)
        if loc is None:
            loc = GL.glGetUniformLocation(program._program_id, name)
            self._locations[key] = loc
        return loc

    def _draw_sprites(self, sprites, VP) -> None:
        defines = {"TEXCOORD_0_LOC": 1, "INST_M_LOC": 2}
        if self.label_ids is not None:
            defines["LABEL_TARGET"] = 1
        program = self._program_cache.get_program("marker.vert", "marker.frag", defines=defines)
        if not program._in_context():
            program._add_to_context()
        program._bind()
        GL.glEnable(GL.GL_PROGRAM_POINT_SIZE)
        GL.glUniformMatrix4fv(self._loc(program, "V"), 1, GL.GL_FALSE, VP[0])
        GL.glUniformMatrix4fv(self._loc(program, "P"), 1, GL.GL_FALSE, VP[1])
        GL.glUniform1f(self._loc(program, "viewport_height"), float(self.viewport_height))
        for primitive, M in sprites:
            material = primitive.material
            GL.glUniformMatrix4fv(self._loc(program, "M"), 1, GL.GL_FALSE, M)
            GL.glUniform4fv(self._loc(program, "marker_color"), 1, np.asarray(material.baseColorFactor, np.float32))
            GL.glUniform3fv(self._loc(program, "marker_emissive"), 1, np.asarray(material.emissiveFactor, np.float32))
            GL.glBindVertexArray(primitive._vertex_array_id)
            GL.glDrawArraysInstanced(GL.GL_POINTS, 0, len(primitive.positions), 1)
        GL.glDisable(GL.GL_PROGRAM_POINT_SIZE)

    # ---- frame buffers we own: colour RGBA8 + depth 24, identical formats so blits are exact
    def _fbo(self, name):
        fbo = self._fbos.get(name)
        if fbo is None:
            w, h = self.viewport_width, self.viewport_height
            cb, db = GL.glGenRenderbuffers(2)
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, cb)
            GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_RGBA8, w, h)
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, db)
            GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_DEPTH_COMPONENT24, w, h)
            fb = GL.glGenFramebuffers(1)
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fb)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, cb)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_DEPTH_ATTACHMENT, GL.GL_RENDERBUFFER, db)
            fbo = self._fbos[name] = (fb, cb, db)
        return fbo

    def drop_caches(self, keep_scene) -> None:
        for name in [n for n in self._fbos if n not in ("work", "labels", "labels_target") and n[1][0] != keep_scene]:
            fb, cb, db = self._fbos.pop(name)
            GL.glDeleteFramebuffers(1, [fb])
            GL.glDeleteRenderbuffers(2, [cb, db])
            self._cache_keys.pop(name[1], None)
            self._previous_keys.pop(name[1], None)

    def delete_fbos(self):
        for fb, cb, db in self._fbos.values():
            if fb:
                GL.glDeleteFramebuffers(1, [fb])
            buffers = [b for b in (cb, db) if b]  # the label target is a colour buffer alone
            GL.glDeleteRenderbuffers(len(buffers), buffers)
        self._fbos.clear()
        self._cache_keys.clear()

    def _begin(self, fb, clear_color=None):
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fb)
        GL.glViewport(0, 0, self.viewport_width, self.viewport_height)
        GL.glFrontFace(GL.GL_CW)  # the projection is mirrored vertically, see _frame_constants
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glDepthFunc(GL.GL_LESS)
        GL.glDisable(GL.GL_BLEND)  # opaque surfaces; _draw blends the translucent gum on its own
        GL.glPolygonMode(GL.GL_FRONT_AND_BACK, GL.GL_FILL)
        if clear_color is not None:
            GL.glClearColor(*clear_color)
            GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)

    def _frame_constants(self, scene):
        V, P = self._get_camera_matrices(scene)
        # Draw upside down: GL stores the bottom row first, so the mirrored image reads back
        # top row first and goes to the encoders without a flipping copy. Mirroring reverses
        # the winding of every triangle, hence glFrontFace(GL_CW) in _begin.
        P = np.diag([1.0, -1.0, 1.0, 1.0]) @ P
        cam_pos = scene.get_pose(scene.main_camera_node)[:3, 3].astype(np.float32)
        VP = np.ascontiguousarray(V.T, dtype=np.float32), np.ascontiguousarray(P.T, dtype=np.float32)
        lights = []
        # pyrender keeps nodes in sets, whose order changes from one scene to the next; a fixed
        # order keeps the floating-point sum of the lights, hence every pixel, reproducible.
        for ln in sorted(scene.directional_light_nodes, key=lambda n: n.name or ""):
            pose = scene.get_pose(ln)
            lights.append((-pose[:3, 2], ln.light.color, float(ln.light.intensity)))
        return VP, cam_pos, lights

    def _draw(self, scene, nodes, VP, cam_pos, lights) -> None:
        """Draw `nodes` ((node, pose) pairs, already in draw order): opaque surfaces, then the
        translucent ones (the gum: blended, not writing depth), then marker sprites."""
        bound = {"program": None, "cull": None}
        sprites, translucent = [], []
        for node, pose in nodes:
            M = np.ascontiguousarray(pose.T, dtype=np.float32)
            for primitive in node.mesh.primitives:
                if primitive.mode == pyrender.GLTF.POINTS:
                    sprites.append((primitive, M))  # after the opaque surfaces they sit on
                elif primitive.material.alphaMode == "BLEND":
                    translucent.append((node, primitive, M))  # over everything opaque, seen through
                else:
                    self._draw_primitive(scene, node, primitive, M, VP, cam_pos, lights, bound)
        if translucent:
            GL.glEnable(GL.GL_BLEND)
            GL.glBlendFunc(GL.GL_SRC_ALPHA, GL.GL_ONE_MINUS_SRC_ALPHA)
            GL.glDepthMask(GL.GL_FALSE)
            for node, primitive, M in translucent:
                self._draw_primitive(scene, node, primitive, M, VP, cam_pos, lights, bound)
            GL.glDepthMask(GL.GL_TRUE)
            GL.glDisable(GL.GL_BLEND)
        if sprites:
            self._draw_sprites(sprites, VP)
        GL.glBindVertexArray(0)
        GL.glUseProgram(0)

    def _draw_primitive(self, scene, node, primitive, M, VP, cam_pos, lights, bound: dict) -> None:
        """One surface primitive of `node` at model matrix `M`; `bound` keeps the bound program and culling
        across calls."""
        program = self._program_for(primitive, len(lights))
        if program is not bound["program"]:
            program._bind()
            bound["program"] = program
            GL.glUniformMatrix4fv(self._loc(program, "V"), 1, GL.GL_FALSE, VP[0])
            GL.glUniformMatrix4fv(self._loc(program, "P"), 1, GL.GL_FALSE, VP[1])
            GL.glUniform3fv(self._loc(program, "cam_pos"), 1, cam_pos)
            GL.glUniform3fv(self._loc(program, "ambient_light"), 1,
                            np.asarray(scene.ambient_light, np.float32))
            GL.glUniform1i(self._loc(program, "n_directional_lights"), len(lights))
            for i, (direction, colour, intensity) in enumerate(lights):
                b = f"directional_lights[{i}]."
                GL.glUniform3fv(self._loc(program, b + "direction"), 1, direction.astype(np.float32))
                GL.glUniform3fv(self._loc(program, b + "color"), 1, np.asarray(colour, np.float32))
                GL.glUniform1f(self._loc(program, b + "intensity"), intensity)
        material = primitive.material
        GL.glUniformMatrix4fv(self._loc(program, "M"), 1, GL.GL_FALSE, M)
        GL.glUniform4fv(self._loc(program, "material.base_color_factor"), 1,
                        np.asarray(material.baseColorFactor, np.float32))
        GL.glUniform3fv(self._loc(program, "material.emissive_factor"), 1,
                        np.asarray(material.emissiveFactor, np.float32))
        GL.glUniform1f(self._loc(program, "material.roughness_factor"), float(material.roughnessFactor))
        if self.label_ids is not None:
            label = self.label_ids.get(node, 0)
            GL.glUniform2f(self._loc(program, "label_rg"), (label % 256) / 255.0, (label // 256) / 255.0)
        want_cull = not material.doubleSided
        if want_cull != bound["cull"]:
            (GL.glEnable if want_cull else GL.glDisable)(GL.GL_CULL_FACE)
            GL.glCullFace(GL.GL_BACK)
            bound["cull"] = want_cull
        GL.glBindVertexArray(primitive._vertex_array_id)
        n_instances = 1 if primitive.poses is None else len(primitive.poses)
        GL.glDrawElementsInstanced(primitive.mode, primitive.indices.size, GL.GL_UNSIGNED_INT,
                                   None, n_instances)

    def _forward_pass(self, scene, flags, seg_node_map=None):
        VP, cam_pos, lights = self._frame_constants(scene)
        # Nearest first: the depth test then rejects hidden fragments before they are shaded.
        # Static teeth (see Renderer.render) always before the others, in the cached and the
        # uncached path alike, so that both produce the same pixels.
        static = self.static_nodes or frozenset()
        order = []
        for node in scene.mesh_nodes:
            if node.mesh.is_visible:
                pose = scene.get_pose(node)
                d2 = float(np.sum((pose[:3, 3] - cam_pos) ** 2))
                order.append((node not in static, d2, node.name or "", node, pose))
        order.sort(key=lambda item: item[:3])
        nodes = [(item[3], item[4]) for item in order]
        n_static = sum(1 for item in order if not item[0])

        if flags & pyrender.RenderFlags.OFFSCREEN:  # multisampled path through pyrender's buffers
            self._configure_forward_pass_viewport(flags)
            self._begin(self._main_fb_ms, scene.bg_color)
            GL.glEnable(GL.GL_MULTISAMPLE)
            self._draw(scene, nodes, VP, cam_pos, lights)
            GL.glFlush()
            return self._read_main_framebuffer(scene, flags)

        if self.label_ids is not None:
            return self._labelled_pass(scene, nodes, VP, cam_pos, lights)
        work = self._fbo("work")[0]
        key = self.static_key
        view = self.cache_name
        stable = key is not None and n_static > 0 and (
            self._cache_keys.get(view) == key or self._previous_keys.get(view) == key)
        self._previous_keys[view] = key
        if stable:
            # Static teeth drawn once into a cached colour+depth image; each frame starts from
            # a copy of it and draws only what moved.
            cache = self._fbo(("cache", view))[0]
            if self._cache_keys.get(view) != key:
                self._begin(cache, scene.bg_color)
                self._draw(scene, nodes[:n_static], VP, cam_pos, lights)
                self._cache_keys[view] = key
                self.cache_builds += 1
            GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, cache)
            GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, work)
            w, h = self.viewport_width, self.viewport_height
            GL.glBlitFramebuffer(0, 0, w, h, 0, 0, w, h, GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT,
                                 GL.GL_NEAREST)
            self._begin(work)
            self._draw(scene, nodes[n_static:], VP, cam_pos, lights)
            self.cache_hits += 1
        else:
            self._begin(work, scene.bg_color)
            self._draw(scene, nodes, VP, cam_pos, lights)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, work)
        w, h = self.viewport_width, self.viewport_height
        # a new array per frame: the encoders still hold the previous ones
        image = np.empty((h, w, self.read_channels), np.uint8)
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        GL.glReadPixels(0, 0, w, h, GL.GL_RGBA if self.read_channels == 4 else GL.GL_RGB, GL.GL_UNSIGNED_BYTE,
                        image)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        return image

    def _labelled_pass(self, scene, nodes, VP, cam_pos, lights):
        """One full draw into colour + label targets; (colour, labels (h, w) uint16, depth (h, w) float32)."""
        fb = self._fbo("labels")[0]
        if self._fbos.get("labels_target") is None:
            w, h = self.viewport_width, self.viewport_height
            rb = GL.glGenRenderbuffers(1)
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
            GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_RGBA8, w, h)
            GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fb)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT1, GL.GL_RENDERBUFFER, rb)
            self._fbos["labels_target"] = (0, rb, 0)
        self._begin(fb)
        GL.glDrawBuffers(2, [GL.GL_COLOR_ATTACHMENT0, GL.GL_COLOR_ATTACHMENT1])
        GL.glClearBufferfv(GL.GL_COLOR, 0, np.asarray(scene.bg_color, np.float32))
        GL.glClearBufferfv(GL.GL_COLOR, 1, np.zeros(4, np.float32))
        GL.glClearBufferfv(GL.GL_DEPTH, 0, np.ones(1, np.float32))
        self._draw(scene, nodes, VP, cam_pos, lights)
        w, h = self.viewport_width, self.viewport_height
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fb)
        GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
        image = np.empty((h, w, self.read_channels), np.uint8)
        GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
        GL.glReadPixels(0, 0, w, h, GL.GL_RGBA if self.read_channels == 4 else GL.GL_RGB, GL.GL_UNSIGNED_BYTE, image)
        rg = np.empty((h, w, 4), np.uint8)
        GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT1)
        GL.glReadPixels(0, 0, w, h, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE, rg)
        depth = np.empty((h, w), np.float32)
        GL.glReadPixels(0, 0, w, h, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT, depth)
        GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
        GL.glDrawBuffers(1, [GL.GL_COLOR_ATTACHMENT0])
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        return image, rg[:, :, 0].astype(np.uint16) | (rg[:, :, 1].astype(np.uint16) << 8), depth
