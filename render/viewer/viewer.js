// orthosim's treatment viewer: plays the animated glTF scene (animation.glb) embedded in the page,
// with WebGL2 and nothing else (no library, no request: the page works from a file:// URL).
//
// What it does, in order: decode the GLB from the page (base64), read its nodes, meshes, materials
// and the one animation; frame the five camera presets as render/cameras.py does (from the hull of
// the rest-pose vertices each view frames, scene extras); draw with tooth.vert/tooth.frag (the
// frames' lighting in GLSL ES 3.00); answer the controls: orbit (drag), zoom (wheel), pan (right
// or shift drag), view buttons, the day/stage slider and play, toggles for roots, gum, contacts
// and the opposing arch, the FDI number of the tooth under the pointer (an id pass read back).
// Test mode (URL hash `#test&step=K&view=NAME&w=320&h=240`): draws the id pass at that size and
// writes each id's pixel count and centroid to <html data-viewer-test>, for tests/render/test_viewer_browser.py.
"use strict";

(function () {
  const errors = [];
  function report(message) {
    errors.push(String(message));
    const box = document.getElementById("errors");
    if (box) { box.textContent = errors.join("\n"); box.hidden = false; }
    document.documentElement.dataset.errors = JSON.stringify(errors);
  }
  window.addEventListener("error", (e) => report(e.message || e));

  const CONFIG = JSON.parse(document.getElementById("orthosim-config").textContent);
  const SHADERS = JSON.parse(document.getElementById("orthosim-shaders").textContent);

  // ------------------------------------------------------------------------------ GLB
  const COMPONENT = { 5126: Float32Array, 5125: Uint32Array, 5123: Uint16Array, 5122: Int16Array,
                      5121: Uint8Array, 5120: Int8Array };
  const WIDTH = { SCALAR: 1, VEC2: 2, VEC3: 3, VEC4: 4, MAT4: 16 };

  function decodeBase64(text) {
    const binary = atob(text);
    const out = new Uint8Array(binary.length);
    for (let i = 0; i < binary.length; i++) out[i] = binary.charCodeAt(i);
    return out;
  }

  function parseGlb(bytes) {
    const view = new DataView(bytes.buffer, bytes.byteOffset, bytes.byteLength);
    if (view.getUint32(0, true) !== 0x46546c67 || view.getUint32(4, true) !== 2) throw new Error("the embedded scene is not a glTF 2.0 binary");
    const jsonLength = view.getUint32(12, true);
    const json = JSON.parse(new TextDecoder().decode(bytes.subarray(20, 20 + jsonLength)));
    const start = 20 + jsonLength;
    const binLength = view.getUint32(start, true);
    return { json, bin: bytes.subarray(start + 8, start + 8 + binLength) };
  }

  function accessor(glb, index) {
    const a = glb.json.accessors[index];
    const v = glb.json.bufferViews[a.bufferView];
    const Type = COMPONENT[a.componentType];
    const offset = glb.bin.byteOffset + (v.byteOffset || 0) + (a.byteOffset || 0);
    const width = WIDTH[a.type];
    return { array: new Type(glb.bin.buffer, offset, a.count * width), width, count: a.count,
             componentType: a.componentType, normalized: !!a.normalized };
  }

  // ------------------------------------------------------------------------------ small matrix algebra (column-major 4x4)
  function identity() { const m = new Float32Array(16); m[0] = m[5] = m[10] = m[15] = 1; return m; }
  function multiply(a, b) {
    const out = new Float32Array(16);
    for (let c = 0; c < 4; c++) for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      out[c * 4 + r] = s;
    }
    return out;
  }
  function fromTRS(t, q, s) {
    const [x, y, z, w] = q;
    const m = new Float32Array(16);
    m[0] = (1 - 2 * (y * y + z * z)) * s[0]; m[1] = 2 * (x * y + z * w) * s[0]; m[2] = 2 * (x * z - y * w) * s[0];
    m[4] = 2 * (x * y - z * w) * s[1]; m[5] = (1 - 2 * (x * x + z * z)) * s[1]; m[6] = 2 * (y * z + x * w) * s[1];
    m[8] = 2 * (x * z + y * w) * s[2]; m[9] = 2 * (y * z - x * w) * s[2]; m[10] = (1 - 2 * (x * x + y * y)) * s[2];
    m[12] = t[0]; m[13] = t[1]; m[14] = t[2]; m[15] = 1;
    return m;
  }
  function perspective(yfov, aspect, near, far) {
    const f = 1 / Math.tan(yfov / 2), m = new Float32Array(16);
    m[0] = f / aspect; m[5] = f; m[10] = (far + near) / (near - far); m[11] = -1; m[14] = 2 * far * near / (near - far);
    return m;
  }
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, k) => [a[0] * k, a[1] * k, a[2] * k];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const normalize = (a) => scale(a, 1 / Math.hypot(a[0], a[1], a[2]));
  function rotate(v, axis, angle) {  // Rodrigues
    const c = Math.cos(angle), s = Math.sin(angle);
    return add(add(scale(v, c), scale(cross(axis, v), s)), scale(axis, dot(axis, v) * (1 - c)));
  }
  function slerp(a, b, t) {
    let d = a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3];
    if (d < 0) { b = b.map((v) => -v); d = -d; }
    if (d > 0.9995) {
      const q = a.map((v, i) => v + t * (b[i] - v));
      const n = Math.hypot(...q);
      return q.map((v) => v / n);
    }
    const th = Math.acos(d), s = Math.sin(th);
    const wa = Math.sin((1 - t) * th) / s, wb = Math.sin(t * th) / s;
    return a.map((v, i) => wa * v + wb * b[i]);
  }
  const toSrgb = (c) => (c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055);

  // ------------------------------------------------------------------------------ the scene
  const glb = parseGlb(decodeBase64(document.getElementById("orthosim-scene").textContent.trim()));
  const doc = glb.json;
  const extras = doc.scenes[0].extras.orthosim;
  const steps = extras.steps, days = extras.days;

  // camera presets exactly as render/cameras.py frames them (frame_view), at any aspect
  function frameView(name, aspect) {
    const v = extras.views[name];
    const z = scale(v.forward, -1), y = v.up, x = cross(y, z);
    const hull = v.hull, n = hull.length / 3;
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < n; i++) for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], hull[3 * i + k]); hi[k] = Math.max(hi[k], hull[3 * i + k]);
    }
    const center = scale(add(lo, hi), 0.5);
    const tanY = Math.tan(extras.yfov / 2), tanX = tanY * aspect;
    const rel = [];
    let d = -Infinity;
    for (let i = 0; i < n; i++) {
      const p = sub([hull[3 * i], hull[3 * i + 1], hull[3 * i + 2]], center);
      const r = [dot(p, x), dot(p, y), dot(p, z)];
      rel.push(r);
      d = Math.max(d, Math.max(Math.abs(r[0]) * extras.margin / tanX, Math.abs(r[1]) * extras.margin / tanY) + r[2]);
    }
    let dmin = Infinity, dmax = -Infinity;
    for (const r of rel) { dmin = Math.min(dmin, d - r[2]); dmax = Math.max(dmax, d - r[2]); }
    const near = Math.max(0.001, dmin * 0.5), far = dmax * 1.5 + 0.010;  // metres (cameras.py: 1 mm, 10 mm)
    return { name, x, y, z, target: center, distance: d, near, far, arches: v.arches };
  }

  const canvas = document.getElementById("view");
  const gl = canvas.getContext("webgl2", { antialias: !/(^#test|[#&]aa=0)/.test(location.hash), preserveDrawingBuffer: true });
  if (!gl) throw new Error("this browser has no WebGL2");

  function compile(vertexSource, fragmentSource) {
    const program = gl.createProgram();
    for (const [type, source] of [[gl.VERTEX_SHADER, vertexSource], [gl.FRAGMENT_SHADER, fragmentSource]]) {
      const shader = gl.createShader(type);
      gl.shaderSource(shader, source);
      gl.compileShader(shader);
      if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(shader));
      gl.attachShader(program, shader);
    }
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(program));
    const uniforms = {};
    const count = gl.getProgramParameter(program, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < count; i++) {
      const name = gl.getActiveUniform(program, i).name;
      uniforms[name.replace("[0]", "")] = gl.getUniformLocation(program, name);
    }
    return { program, uniforms };
  }
  const shaded = compile(SHADERS["tooth.vert"], SHADERS["tooth.frag"]);
  const flat = compile(SHADERS["id.vert"], SHADERS["id.frag"]);

  const buffers = new Map();  // accessor -> GL buffer
  function glBuffer(index, target) {
    if (!buffers.has(index)) {
      const b = gl.createBuffer();
      gl.bindBuffer(target, b);
      gl.bufferData(target, accessor(glb, index).array, gl.STATIC_DRAW);
      buffers.set(index, b);
    }
    return buffers.get(index);
  }
  const GL_TYPE = { 5126: gl.FLOAT, 5125: gl.UNSIGNED_INT, 5123: gl.UNSIGNED_SHORT, 5122: gl.SHORT,
                    5121: gl.UNSIGNED_BYTE, 5120: gl.BYTE };

  function material(index) {
    const m = doc.materials[index], pbr = m.pbrMetallicRoughness || {};
    const f = pbr.baseColorFactor || [1, 1, 1, 1], e = m.emissiveFactor || [0, 0, 0];
    return { color: [toSrgb(f[0]), toSrgb(f[1]), toSrgb(f[2]), f[3]], emissive: e.map(toSrgb),
             blend: m.alphaMode === "BLEND", shininess: m.name.startsWith("crown") || m.name.includes("root") ? 24 : 0 };
  }

  const meshes = doc.meshes.map((mesh) => mesh.primitives.map((p) => {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    for (const [location, name] of [[0, "POSITION"], [1, "NORMAL"]]) {
      const a = doc.accessors[p.attributes[name]];
      gl.bindBuffer(gl.ARRAY_BUFFER, glBuffer(p.attributes[name], gl.ARRAY_BUFFER));
      gl.enableVertexAttribArray(location);
      gl.vertexAttribPointer(location, 3, GL_TYPE[a.componentType], !!a.normalized, 0, 0);
    }
    const idx = doc.accessors[p.indices];
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, glBuffer(p.indices, gl.ELEMENT_ARRAY_BUFFER));
    gl.bindVertexArray(null);
    return { vao, count: idx.count, type: GL_TYPE[idx.componentType], material: material(p.material),
             part: (p.extras || {}).part || "" };
  }));

  // the animation: node -> path -> sampler values, over keyframes at k * step_seconds
  const channels = [];
  for (const anim of doc.animations || []) {
    for (const c of anim.channels) {
      const s = anim.samplers[c.sampler];
      channels.push({ node: c.target.node, path: c.target.path, step: s.interpolation === "STEP",
                      values: accessor(glb, s.output) });
    }
  }
  const nodes = doc.nodes.map((n) => ({ ...n, t: n.translation || [0, 0, 0], r: n.rotation || [0, 0, 0, 1],
                                         s: n.scale || [1, 1, 1], role: (n.extras || {}).role || (n.extras && n.extras.fdi ? "tooth" : "") }));
  const parent = new Map();
  nodes.forEach((n, i) => (n.children || []).forEach((c) => parent.set(c, i)));

  function pose(position) {  // every node's TRS at a keyframe position (0 .. K-1, fractional between)
    const k = Math.min(Math.floor(position), steps.length - 1), f = position - k, k1 = Math.min(k + 1, steps.length - 1);
    for (const c of channels) {
      const v = c.values.array, w = c.values.width;
      const a = Array.from(v.subarray(k * w, k * w + w));
      let out = a;
      if (!c.step && f > 0 && k1 !== k) {
        const b = Array.from(v.subarray(k1 * w, k1 * w + w));
        out = c.path === "rotation" ? slerp(a, b, f) : a.map((x, i) => x + f * (b[i] - x));
      }
      const node = nodes[c.node];
      if (c.path === "translation") node.t = out; else if (c.path === "rotation") node.r = out; else node.s = out;
    }
    const world = new Array(nodes.length);
    const resolve = (i) => {
      if (!world[i]) {
        const local = fromTRS(nodes[i].t, nodes[i].r, nodes[i].s);
        world[i] = parent.has(i) ? multiply(resolve(parent.get(i)), local) : local;
      }
      return world[i];
    };
    nodes.forEach((_, i) => resolve(i));
    return world;
  }
  const rootOf = (i) => (parent.has(i) ? rootOf(parent.get(i)) : i);

  // ------------------------------------------------------------------------------ state and drawing
  const state = { position: 0, camera: null, named: "frontal", roots: true, gum: true, contacts: true,
                  opposing: true, playing: false };
  const hasGum = nodes.some((n) => n.role === "gingiva");

  function setView(name, aspect) {
    state.named = name;
    state.camera = frameView(name, aspect);
    state.opposing = state.camera.arches.length === 2;
    const box = document.getElementById("toggle-opposing");
    if (box) box.checked = state.opposing;
  }

  function archShown(arch) {
    const arches = state.camera.arches;
    if (state.opposing) return true;
    return arches.length === 1 ? arches[0] === arch : arch === "upper";
  }

  function visible(i) {
    const root = nodes[rootOf(i)], ex = root.extras || {};
    if (root.role === "contact") return state.contacts;
    if (root.role === "gingiva") return state.gum && archShown(ex.arch);
    if (ex.fdi) return archShown(ex.arch);
    return true;
  }

  // as render/scene.py does in an occlusal view of one arch: a contact between teeth of the hidden
  // arch would float over the shown one; keep the markers on the shown arch's side of the occlusal
  // plane (y = 0), with the frames' margin for the contacts between the arches
  function markerOnShownSide(y) {
    const arches = state.camera.arches;
    if (state.opposing || arches.length !== 1) return true;
    return arches[0] === "upper" ? y > -CONFIG.occlusal_margin : y < CONFIG.occlusal_margin;
  }

  function cameraMatrices(camera, aspect) {
    const eye = add(camera.target, scale(camera.z, camera.distance));
    const { x, y, z } = camera;
    const V = new Float32Array([x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
                                -dot(x, eye), -dot(y, eye), -dot(z, eye), 1]);
    return { V, P: perspective(extras.yfov, aspect, camera.near, camera.far), eye };
  }

  function drawList(world) {
    const opaque = [], blended = [];
    nodes.forEach((n, i) => {
      if (n.mesh === undefined || !visible(i)) return;
      const m = world[i];
      if (m[0] === 0 && m[1] === 0 && m[2] === 0) return;  // scaled out: not there at this keyframe
      if (n.role === "contact" && !markerOnShownSide(m[13])) return;
      for (const p of meshes[n.mesh]) {
        if (p.part === "root" && !state.roots) continue;
        (p.material.blend ? blended : opaque).push({ node: i, p, m });
      }
    });
    return { opaque, blended };
  }

  function draw(target) {  // target: {framebuffer, width, height, ids}
    const { width, height } = target;
    const aspect = width / height;
    const { V, P, eye } = cameraMatrices(state.camera, aspect);
    const world = pose(state.position);
    const list = drawList(world);
    gl.bindFramebuffer(gl.FRAMEBUFFER, target.framebuffer);
    gl.viewport(0, 0, width, height);
    const bg = target.ids ? [0, 0, 0] : CONFIG.background;
    gl.clearColor(bg[0], bg[1], bg[2], 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.disable(gl.CULL_FACE);
    const prog = target.ids ? flat : shaded;
    gl.useProgram(prog.program);
    const u = prog.uniforms;
    gl.uniformMatrix4fv(u.V, false, V);
    gl.uniformMatrix4fv(u.P, false, P);
    if (!target.ids) {
      const { x, y, z } = state.camera;
      const dirs = [], cols = [];
      for (const [d, c, k] of CONFIG.light_rig) {  // camera-frame directions carried into the world
        dirs.push(...add(add(scale(x, d[0]), scale(y, d[1])), scale(z, d[2])));
        cols.push(c[0] * k, c[1] * k, c[2] * k);
      }
      gl.uniform3fv(u.light_direction, dirs);
      gl.uniform3fv(u.light_color, cols);
      gl.uniform3fv(u.ambient_light, CONFIG.ambient);
      gl.uniform3fv(u.cam_pos, eye);
    }
    const one = (item) => {
      gl.uniformMatrix4fv(u.M, false, item.m);
      if (target.ids) {
        const ex = nodes[rootOf(item.node)].extras || {};
        gl.uniform4f(u.id_color, ex.fdi ? ex.fdi / 255 : 0, 0, ex.fdi ? 1 / 255 : 2 / 255, 1);
      } else {
        gl.uniform4fv(u.base_color, item.p.material.color);
        gl.uniform3fv(u.emissive, item.p.material.emissive);
        gl.uniform1f(u.shininess, item.p.material.shininess);
      }
      gl.bindVertexArray(item.p.vao);
      gl.drawElements(gl.TRIANGLES, item.p.count, item.p.type, 0);
    };
    gl.disable(gl.BLEND);
    list.opaque.forEach(one);
    if (!target.ids) {  // translucent gum last, over the teeth, not writing depth
      gl.enable(gl.BLEND);
      gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
      gl.depthMask(false);
      list.blended.forEach(one);
      gl.depthMask(true);
      gl.disable(gl.BLEND);
    }
    gl.bindVertexArray(null);
  }

  function idTarget(width, height) {
    const framebuffer = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, framebuffer);
    const color = gl.createRenderbuffer();
    gl.bindRenderbuffer(gl.RENDERBUFFER, color);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA8, width, height);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, color);
    const depth = gl.createRenderbuffer();
    gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, width, height);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    return { framebuffer, width, height, ids: true };
  }

  function readIds(target) {  // (counts, centroids) per tooth id, rows counted from the image top
    const pixels = new Uint8Array(target.width * target.height * 4);
    gl.bindFramebuffer(gl.FRAMEBUFFER, target.framebuffer);
    gl.readPixels(0, 0, target.width, target.height, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    const sums = {};
    for (let row = 0; row < target.height; row++) for (let col = 0; col < target.width; col++) {
      const o = ((target.height - 1 - row) * target.width + col) * 4;
      if (pixels[o + 2] !== 1) continue;  // not a tooth
      const s = sums[pixels[o]] || (sums[pixels[o]] = [0, 0, 0]);
      s[0] += 1; s[1] += col; s[2] += row;
    }
    const out = {};
    for (const [id, s] of Object.entries(sums)) out[id] = { pixels: s[0], centroid: [s[1] / s[0], s[2] / s[0]] };
    return out;
  }

  // ------------------------------------------------------------------------------ the page
  const params = new URLSearchParams(location.hash.slice(1).replace(/&/g, "&"));
  function fit() {
    const r = window.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(canvas.clientWidth * r));
    canvas.height = Math.max(1, Math.round(canvas.clientHeight * r));
  }
  let pending = false;
  function redraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; paint(); });
  }
  function paint() {
    draw({ framebuffer: null, width: canvas.width, height: canvas.height, ids: false });
    const k = Math.round(state.position);
    const label = document.getElementById("day");
    if (label) label.textContent = extras.labels ? extras.labels[k]
      : extras.timeline === "stage" ? `stage ${steps[k]} of ${steps[steps.length - 1]}`
      : `day ${Math.round(days[k])} of ${Math.round(days[days.length - 1])} (step ${steps[k]})`;
  }

  function setPosition(position) {
    state.position = Math.max(0, Math.min(steps.length - 1, position));
    const slider = document.getElementById("slider");
    if (slider && Math.abs(slider.value - state.position) >= 0.5) slider.value = Math.round(state.position);
    redraw();
  }

  function wireControls() {
    for (const b of document.querySelectorAll("button[data-view]")) {
      const name = b.dataset.view;
      if (!extras.views[name]) { b.hidden = true; continue; }  // an arch the model lacks
      b.addEventListener("click", () => { setView(name, canvas.width / canvas.height); redraw(); });
    }
    const slider = document.getElementById("slider");
    slider.max = steps.length - 1;
    slider.addEventListener("input", () => { state.playing = false; setPosition(Number(slider.value)); });
    const play = document.getElementById("play");
    let last = 0;
    const tick = (now) => {
      if (!state.playing) { play.textContent = "Play"; return; }
      const dt = last ? (now - last) / 1000 : 0;
      last = now;
      const rate = Math.max(1, (steps.length - 1) / 8);  // the whole treatment in about 8 seconds
      if (state.position >= steps.length - 1) { state.playing = false; play.textContent = "Play"; return; }
      setPosition(state.position + dt * rate);
      requestAnimationFrame(tick);
    };
    play.addEventListener("click", () => {
      state.playing = !state.playing;
      play.textContent = state.playing ? "Pause" : "Play";
      if (state.playing) {
        if (state.position >= steps.length - 1) setPosition(0);
        last = 0;
        requestAnimationFrame(tick);
      }
    });
    for (const key of ["roots", "gum", "contacts", "opposing"]) {
      const box = document.getElementById(`toggle-${key}`);
      if (!box) continue;
      box.checked = state[key];
      box.addEventListener("change", () => { state[key] = box.checked; redraw(); });
    }
    if (!hasGum) document.getElementById("toggle-gum").parentElement.hidden = true;
    wirePointer();
    window.addEventListener("resize", () => { fit(); state.camera = { ...frameView(state.named, canvas.width / canvas.height), ...orbitOf(state.camera) }; redraw(); });
  }

  function orbitOf(camera) { return { x: camera.x, y: camera.y, z: camera.z, target: camera.target, distance: camera.distance }; }

  function wirePointer() {
    let drag = null, picker = null;
    const tip = document.getElementById("tooltip");
    canvas.addEventListener("contextmenu", (e) => e.preventDefault());
    canvas.addEventListener("pointerdown", (e) => {
      drag = { x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey };
      canvas.setPointerCapture(e.pointerId);
    });
    canvas.addEventListener("pointerup", () => { drag = null; });
    canvas.addEventListener("pointermove", (e) => {
      const c = state.camera;
      if (drag) {
        const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
        drag.x = e.clientX; drag.y = e.clientY;
        if (drag.pan) {
          const k = 2 * c.distance * Math.tan(extras.yfov / 2) / canvas.clientHeight;
          c.target = add(c.target, add(scale(c.x, -dx * k), scale(c.y, dy * k)));
        } else {
          const a = -dx * 0.008, b = -dy * 0.008;
          const up = [0, 1, 0];
          c.x = normalize(rotate(c.x, up, a)); c.y = normalize(rotate(c.y, up, a)); c.z = normalize(rotate(c.z, up, a));
          c.y = normalize(rotate(c.y, c.x, b)); c.z = normalize(rotate(c.z, c.x, b));
        }
        redraw();
        tip.hidden = true;
        return;
      }
      const rect = canvas.getBoundingClientRect();
      const w = Math.max(1, Math.round(rect.width)), h = Math.max(1, Math.round(rect.height));
      if (!picker || picker.width !== w || picker.height !== h) picker = idTarget(w, h);
      draw(picker);
      const px = new Uint8Array(4);
      gl.bindFramebuffer(gl.FRAMEBUFFER, picker.framebuffer);
      gl.readPixels(Math.floor(e.clientX - rect.left), h - 1 - Math.floor(e.clientY - rect.top), 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      if (px[2] === 1 && CONFIG.names[px[0]]) {
        tip.textContent = `${px[0]}: ${CONFIG.names[px[0]]}`;
        tip.style.left = `${e.clientX + 14}px`; tip.style.top = `${e.clientY + 10}px`;
        tip.hidden = false;
      } else tip.hidden = true;
    });
    canvas.addEventListener("wheel", (e) => {
      e.preventDefault();
      const c = state.camera, k = Math.exp(e.deltaY * 0.001);
      c.distance *= k; c.near *= k; c.far *= k;
      redraw();
    }, { passive: false });
  }

  function start() {
    fit();
    const named = params.get("view") || (extras.views.frontal ? "frontal" : Object.keys(extras.views)[0]);
    if (!extras.views[named]) throw new Error(`unknown view ${named}`);
    if (params.has("test")) {
      const w = Number(params.get("w") || 320), h = Number(params.get("h") || 240);
      setView(named, w / h);
      state.position = Number(params.get("step") || 0);
      for (const key of ["roots", "gum", "contacts"]) if (params.has(key)) state[key] = params.get(key) === "1";
      const target = idTarget(w, h);
      draw(target);
      document.documentElement.dataset.viewerTest = JSON.stringify({ size: [w, h], step: steps[state.position],
                                                                      teeth: readIds(target) });
    }
    setView(named, canvas.width / canvas.height);
    if (params.has("step")) state.position = Number(params.get("step"));
    if (params.get("bare") === "1") document.body.classList.add("bare");
    fit();
    state.camera = frameView(named, canvas.width / canvas.height);
    wireControls();
    document.getElementById("slider").value = state.position;
    paint();
    document.documentElement.dataset.drawn = String(performance.now());
    // for the bench: milliseconds to draw one whole frame (the GPU's work included), over n frames
    window.orthosimViewer = { frameMs(n) {
      const pixel = new Uint8Array(4), started = performance.now();
      for (let i = 0; i < n; i++) {
        state.position = i % steps.length;
        paint();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, pixel);  // waits for the frame to finish
      }
      return (performance.now() - started) / n;
    } };
    document.title = document.title.replace(/ \(loading\)$/, "");
  }

  try { start(); } catch (e) { report(e && e.message ? e.message : e); throw e; }
})();
