// fmrh's viewer: flies a camera over terrain that `fmrh serve` serves, asks the server for
// the scene whenever the camera settles, and draws it with WebGL 2. Plain JavaScript, no
// library: the server does the work (scheduling, loading, crack-free meshing) and the page
// only parses the glTF binary it gets and draws one mesh per block.
//
// Frames. The server's world frame is fmrh's: x east, y south, z up, metres from the
// north-west sample. The glTF is X east, Y up, Z south, relative to the scene's origin
// (`scenes[0].extras.fmrh.origin.world_m`). The page keeps its camera in fmrh's frame and
// draws in a right-handed east-north-up frame centred on the eye (y negated), so the image
// is not mirrored and f32 positions stay small near the eye.
//
// For tests, `window.fmrhViewer` says where the page is: `state` ('loading', 'ready',
// 'error'), `scenes` (scenes drawn so far), `busy` (a scene is asked for or due), `query`
// (the last scene's query string, which `/api/scene?` + query answers again), `stats` (the
// scene JSON it shows), `triangles`, `renderer` (the WebGL renderer), `eye` and `error`.
'use strict';

const viewer = { state: 'loading', scenes: 0, query: null, stats: null, error: null };
window.fmrhViewer = viewer;

const FOV_DEG = 60;
const $ = (id) => document.getElementById(id);
const canvas = $('view');
const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });

function fail(message) {
  viewer.state = 'error';
  viewer.error = String(message);
  const s = $('status');
  s.textContent = viewer.error;
  s.className = 'error';
}

// ---- the camera, in fmrh's frame -------------------------------------------------------

const camera = { eye: [0, 0, 0], heading: 0, pitch: -0.3 }; // radians; heading 0 = north
let items = [];
let item = null;
let levelColours = [];

// The unit vector the camera looks along, in fmrh's frame (y south).
function forward() {
  const c = Math.cos(camera.pitch);
  return [Math.sin(camera.heading) * c, -Math.cos(camera.heading) * c, Math.sin(camera.pitch)];
}

function target() {
  const f = forward();
  const d = 1000;
  return [camera.eye[0] + f[0] * d, camera.eye[1] + f[1] * d, camera.eye[2] + f[2] * d];
}

function lookAt(eye, at) {
  const d = [at[0] - eye[0], at[1] - eye[1], at[2] - eye[2]];
  const horizontal = Math.hypot(d[0], d[1]);
  camera.eye = eye.slice();
  camera.heading = Math.atan2(d[0], -d[1]);
  camera.pitch = Math.atan2(d[2], horizontal);
}

// A first view of the item: from beyond its south edge, looking north across it.
function defaultView(it) {
  const [dx, dy] = it.spacing_m || [1, 1];
  const w = it.width * dx;
  const h = it.height * dy;
  const [lo, hi] = it.height_range || [0, 0];
  const size = Math.max(w, h);
  lookAt([w * 0.5, h * 1.1, hi + size * 0.25], [w * 0.5, h * 0.45, (lo + hi) / 2]);
}

// ---- matrices (column-major, as WebGL takes them) --------------------------------------

function perspective(fovY, aspect, near, far) {
  const f = 1 / Math.tan(fovY / 2);
  const nf = 1 / (near - far);
  return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
}

// A view matrix for an eye at the origin looking along `dir` (east-north-up), z up.
function viewMatrix(dir) {
  const norm = (v) => { const l = Math.hypot(v[0], v[1], v[2]); return [v[0] / l, v[1] / l, v[2] / l]; };
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const z = norm([-dir[0], -dir[1], -dir[2]]);
  const x = norm(cross([0, 0, 1], z));
  const y = cross(z, x);
  return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0, 0, 0, 0, 1];
}

function multiply(a, b) {
  const out = new Array(16).fill(0);
  for (let c = 0; c < 4; c++) {
    for (let r = 0; r < 4; r++) {
      let s = 0;
      for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
      out[c * 4 + r] = s;
    }
  }
  return out;
}

// ---- WebGL -------------------------------------------------------------------------------

const VERTEX = `#version 300 es
in vec3 a_position;   // glTF: X east, Y up (height), Z south, X and Z from the origin
in vec3 a_normal;
uniform vec3 u_offset; // origin minus eye in fmrh's frame (x east, y south, z up)
uniform mat4 u_view_projection;
out vec3 v_normal;
out float v_height;
void main() {
  vec3 w = vec3(a_position.x + u_offset.x, a_position.z + u_offset.y, a_position.y + u_offset.z);
  gl_Position = u_view_projection * vec4(w.x, -w.y, w.z, 1.0);
  v_normal = vec3(a_normal.x, -a_normal.z, a_normal.y);
  v_height = a_position.y;
}`;

const FRAGMENT = `#version 300 es
precision highp float;
in vec3 v_normal;
in float v_height;
uniform vec3 u_colour;
uniform int u_mode;       // 0: by level, 1: shaded by height
uniform vec2 u_heights;   // the item's height range
out vec4 colour;
void main() {
  vec3 sun = normalize(vec3(-1.0, 1.0, 1.4)); // from the north-west, as hillshades are lit
  float light = 0.35 + 0.65 * max(dot(normalize(v_normal), sun), 0.0);
  vec3 base = u_colour;
  if (u_mode == 1) {
    float t = clamp((v_height - u_heights.x) / max(u_heights.y - u_heights.x, 1e-3), 0.0, 1.0);
    base = t < 0.5 ? mix(vec3(0.30, 0.55, 0.25), vec3(0.60, 0.50, 0.35), t * 2.0)
                   : mix(vec3(0.60, 0.50, 0.35), vec3(0.95, 0.95, 0.95), t * 2.0 - 1.0);
  }
  colour = vec4(base * light, 1.0);
}`;

let program = null;
let where = {};

function compile() {
  const shader = (type, text) => {
    const s = gl.createShader(type);
    gl.shaderSource(s, text);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  };
  program = gl.createProgram();
  gl.attachShader(program, shader(gl.VERTEX_SHADER, VERTEX));
  gl.attachShader(program, shader(gl.FRAGMENT_SHADER, FRAGMENT));
  gl.bindAttribLocation(program, 0, 'a_position');
  gl.bindAttribLocation(program, 1, 'a_normal');
  gl.linkProgram(program);
  if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
  for (const u of ['u_offset', 'u_view_projection', 'u_colour', 'u_mode', 'u_heights']) {
    where[u] = gl.getUniformLocation(program, u);
  }
}

// The scene on the GPU: one entry per block, and the origin of its positions.
let drawn = { blocks: [], origin: [0, 0] };

// Parses a glTF binary as `fmrh mesh` writes it: a node per block, each with one
// triangle primitive (POSITION, NORMAL, indices) and its facts in `extras.fmrh`.
function parseGlb(buffer) {
  const dv = new DataView(buffer);
  if (buffer.byteLength < 12 || dv.getUint32(0, true) !== 0x46546c67) throw new Error('the mesh is not a glTF binary');
  let json = null;
  let bin = -1;
  for (let at = 12; at + 8 <= buffer.byteLength;) {
    const length = dv.getUint32(at, true);
    const type = dv.getUint32(at + 4, true);
    if (type === 0x4e4f534a) json = JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, at + 8, length)));
    if (type === 0x004e4942) bin = at + 8;
    at += 8 + length;
  }
  if (!json || bin < 0) throw new Error('the glTF binary has no JSON or no BIN chunk');
  const array = (index, Type, components) => {
    const a = json.accessors[index];
    const v = json.bufferViews[a.bufferView];
    return new Type(buffer, bin + (v.byteOffset || 0) + (a.byteOffset || 0), a.count * components);
  };
  const blocks = [];
  for (const node of json.nodes) {
    if (node.mesh === undefined) continue;
    const p = json.meshes[node.mesh].primitives[0];
    const wide = json.accessors[p.indices].componentType === 5125;
    const facts = (node.extras && node.extras.fmrh) || {};
    blocks.push({
      positions: array(p.attributes.POSITION, Float32Array, 3),
      normals: array(p.attributes.NORMAL, Float32Array, 3),
      indices: array(p.indices, wide ? Uint32Array : Uint16Array, 1),
      wide,
      level: facts.level || 0,
      synthetic: !!facts.synthetic,
    });
  }
  const extras = (json.scenes[0].extras || {}).fmrh || {};
  return { blocks, origin: (extras.origin && extras.origin.world_m) || [0, 0] };
}

function upload(scene) {
  for (const b of drawn.blocks) {
    gl.deleteVertexArray(b.vao);
    for (const buf of b.buffers) gl.deleteBuffer(buf);
  }
  const blocks = scene.blocks.map((b) => {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const attribute = (location, data) => {
      const buf = gl.createBuffer();
      gl.bindBuffer(gl.ARRAY_BUFFER, buf);
      gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
      gl.enableVertexAttribArray(location);
      gl.vertexAttribPointer(location, 3, gl.FLOAT, false, 0, 0);
      return buf;
    };
    const positions = attribute(0, b.positions);
    const normals = attribute(1, b.normals);
    const indices = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indices);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, b.indices, gl.STATIC_DRAW);
    gl.bindVertexArray(null);
    return {
      vao, buffers: [positions, normals, indices], count: b.indices.length,
      type: b.wide ? gl.UNSIGNED_INT : gl.UNSIGNED_SHORT, level: b.level, synthetic: b.synthetic,
    };
  });
  drawn = { blocks, origin: scene.origin };
}

// The camera's view-projection matrix for a canvas `width` × `height`: in the frame the
// shader draws in (east-north-up, centred on the eye), so that it is right-handed and the
// screen's right is forward × up.
function viewProjection(width, height) {
  const f = forward();
  const [dx, dy] = item.spacing_m || [1, 1];
  const size = Math.max(item.width * dx, item.height * dy);
  const hi = (item.height_range || [0, 0])[1];
  const above = Math.max(camera.eye[2] - hi, 1);
  const near = Math.min(Math.max(above * 0.05, 1), 1000);
  const far = size * 4 + Math.abs(camera.eye[2]) * 4;
  return multiply(perspective((FOV_DEG * Math.PI) / 180, width / height, near, far), viewMatrix([f[0], -f[1], f[2]]));
}

// Where the point `p` of fmrh's frame lands on the canvas, in CSS pixels from its top-left,
// by the shader's own transformation (for tests: the same side as `fmrh render`'s).
viewer.project = (p) => {
  const vp = viewProjection(canvas.width, canvas.height);
  const w = [p[0] - camera.eye[0], -(p[1] - camera.eye[1]), p[2] - camera.eye[2], 1];
  const clip = [0, 1, 2, 3].map((r) => vp[r] * w[0] + vp[4 + r] * w[1] + vp[8 + r] * w[2] + vp[12 + r] * w[3]);
  const [cw, ch] = [canvas.clientWidth, canvas.clientHeight];
  return [((clip[0] / clip[3] + 1) / 2) * cw, ((1 - clip[1] / clip[3]) / 2) * ch];
};

function draw() {
  const width = canvas.width;
  const height = canvas.height;
  gl.viewport(0, 0, width, height);
  gl.clearColor(0.62, 0.75, 0.88, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!program || !item) return;
  gl.enable(gl.DEPTH_TEST);
  gl.useProgram(program);
  const [lo, hi] = item.height_range || [0, 0];
  const vp = viewProjection(width, height);
  gl.uniformMatrix4fv(where.u_view_projection, false, new Float32Array(vp));
  gl.uniform3f(where.u_offset, drawn.origin[0] - camera.eye[0], drawn.origin[1] - camera.eye[1], -camera.eye[2]);
  gl.uniform1i(where.u_mode, $('colour').value === 'shaded' ? 1 : 0);
  gl.uniform2f(where.u_heights, lo, hi);
  for (const b of drawn.blocks) {
    const c = levelColours[b.level % levelColours.length] || [128, 128, 128];
    // Synthetic nodes (refined past the data) are drawn paler.
    const k = b.synthetic ? 0.6 : 1;
    gl.uniform3f(where.u_colour, (c[0] / 255) * k + (1 - k), (c[1] / 255) * k + (1 - k), (c[2] / 255) * k + (1 - k));
    gl.bindVertexArray(b.vao);
    gl.drawElements(gl.TRIANGLES, b.count, b.type, 0);
  }
  gl.bindVertexArray(null);
}

// ---- asking for scenes -------------------------------------------------------------------

let dirty = true;
let inFlight = false;
let lastAsked = 0;
// Whether a scene is being asked for or will be (the camera moved since the last).
Object.defineProperty(viewer, 'busy', { get: () => inFlight || dirty });
// Where the eye is now, in fmrh's frame.
Object.defineProperty(viewer, 'eye', { get: () => camera.eye.slice() });

function query() {
  const t = target();
  const fmt = (v) => v.map((x) => x.toFixed(3)).join(',');
  const q = new URLSearchParams({
    item: item.name,
    eye: fmt(camera.eye),
    target: fmt(t),
    tau: $('tau').value,
    fov: String(FOV_DEG),
    viewport: `${canvas.width}x${canvas.height}`,
  });
  // A TIN's cracks close with skirts; the grid's as the Cracks control says.
  if ($('tin').value) q.set('max_error', $('tin').value);
  else q.set('cracks', $('cracks').value);
  return q.toString();
}

async function answer(url, kind) {
  const r = await fetch(url);
  if (!r.ok) {
    let message = `HTTP ${r.status}`;
    try { message = (await r.json()).error || message; } catch (e) { /* not JSON */ }
    throw new Error(message);
  }
  return kind === 'json' ? r.json() : r.arrayBuffer();
}

function show(stats, triangles, meshBytes) {
  const cell = (name, text) => { document.querySelector(`[data-stat="${name}"]`).textContent = text; };
  cell('blocks', String(stats.blocks));
  cell('levels', Object.entries(stats.levels).map(([l, n]) => `${l}:${n}`).join(' '));
  cell('triangles', triangles.toLocaleString('en'));
  cell('payload_bytes', stats.payload_bytes.toLocaleString('en'));
  cell('schedule_us', `${stats.schedule_us.toFixed(1)} µs`);
  cell('max_screen_error_px', `${stats.max_screen_error_px.toFixed(3)} px`);
  cell('max_error_m', `${stats.max_error_m.toFixed(3)} m`);
  cell('mesh_bytes', `${(meshBytes / 1e6).toFixed(2)} MB`);
  const legend = $('legend');
  legend.textContent = '';
  for (const l of Object.keys(stats.levels)) {
    const span = document.createElement('span');
    const c = levelColours[Number(l) % levelColours.length];
    span.style.background = `rgb(${c[0]},${c[1]},${c[2]})`;
    span.textContent = `level ${l}`;
    legend.appendChild(span);
  }
}

// One scene: its JSON (the stats), then its mesh; both answer the same query, so they
// describe the same blocks. Only one is asked at a time; a camera that moved meanwhile
// is asked for next.
async function ask() {
  if (inFlight || !item || !program) return;
  inFlight = true;
  dirty = false;
  lastAsked = performance.now();
  const q = query();
  $('status').className = '';
  $('status').textContent = 'asking for a scene…';
  try {
    const stats = await answer(`/api/scene?${q}`, 'json');
    const glb = await answer(`/api/mesh?${q}`, 'bytes');
    const scene = parseGlb(glb);
    upload(scene);
    const triangles = scene.blocks.reduce((n, b) => n + b.indices.length / 3, 0);
    show(stats, triangles, glb.byteLength);
    viewer.query = q;
    viewer.stats = stats;
    viewer.triangles = triangles;
    viewer.scenes += 1;
    viewer.state = 'ready';
    viewer.error = null;
    $('status').textContent = `scene ${viewer.scenes}: ${stats.server_ms.toFixed(1)} ms on the server`;
  } catch (e) {
    fail(e.message || e);
  } finally {
    inFlight = false;
  }
}

// ---- flying ------------------------------------------------------------------------------

const held = new Set();
let dragging = null;

function moved() { dirty = true; }

canvas.addEventListener('mousedown', (e) => { dragging = [e.clientX, e.clientY]; canvas.style.cursor = 'grabbing'; });
window.addEventListener('mouseup', () => { dragging = null; canvas.style.cursor = 'grab'; });
window.addEventListener('mousemove', (e) => {
  if (!dragging) return;
  camera.heading += (e.clientX - dragging[0]) * 0.004;
  camera.pitch = Math.max(-1.55, Math.min(1.55, camera.pitch - (e.clientY - dragging[1]) * 0.004));
  dragging = [e.clientX, e.clientY];
  moved();
});
window.addEventListener('keydown', (e) => {
  if (e.target instanceof HTMLInputElement || e.target instanceof HTMLSelectElement) return;
  held.add(e.key.toLowerCase());
});
window.addEventListener('keyup', (e) => held.delete(e.key.toLowerCase()));
window.addEventListener('blur', () => held.clear());
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const f = forward();
  const step = speed() * 0.15 * -Math.sign(e.deltaY);
  for (let i = 0; i < 3; i++) camera.eye[i] += f[i] * step;
  moved();
}, { passive: false });

// Metres a second: faster the higher the camera flies.
function speed() {
  const hi = (item && item.height_range) ? item.height_range[1] : 0;
  return Math.max(camera.eye[2] - hi, 50) * 0.8;
}

function fly(seconds) {
  const k = (held.has('shift') ? 4 : 1) * speed() * seconds;
  const h = camera.heading;
  const ahead = [Math.sin(h), -Math.cos(h)];
  const right = [Math.cos(h), Math.sin(h)];
  let [f, s, u] = [0, 0, 0];
  if (held.has('w') || held.has('arrowup')) f += 1;
  if (held.has('s') || held.has('arrowdown')) f -= 1;
  if (held.has('d') || held.has('arrowright')) s += 1;
  if (held.has('a') || held.has('arrowleft')) s -= 1;
  if (held.has('e') || held.has('pageup')) u += 1;
  if (held.has('q') || held.has('pagedown')) u -= 1;
  if (f === 0 && s === 0 && u === 0) return;
  camera.eye[0] += (ahead[0] * f + right[0] * s) * k;
  camera.eye[1] += (ahead[1] * f + right[1] * s) * k;
  camera.eye[2] += u * k;
  moved();
}

function resize() {
  const w = Math.max(1, Math.round(canvas.clientWidth));
  const h = Math.max(1, Math.round(canvas.clientHeight));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
    moved();
  }
}

let last = performance.now();
function frame(now) {
  fly(Math.min((now - last) / 1000, 0.1));
  last = now;
  resize();
  // While the camera moves, a scene every quarter second; once it stops, at once.
  if (dirty && !inFlight && now - lastAsked > 250) ask();
  draw();
  requestAnimationFrame(frame);
}

// ---- start -------------------------------------------------------------------------------

function fromHash() {
  const p = new URLSearchParams(location.hash.slice(1));
  const vec = (name) => {
    const v = (p.get(name) || '').split(',').map(Number);
    return v.length === 3 && v.every(Number.isFinite) ? v : null;
  };
  if (p.get('tau')) $('tau').value = p.get('tau');
  if (p.get('colour')) $('colour').value = p.get('colour');
  if (p.get('cracks')) $('cracks').value = p.get('cracks');
  if (p.get('max_error')) $('tin').value = p.get('max_error');
  return { item: p.get('item'), eye: vec('eye'), target: vec('target') };
}

async function start() {
  if (!gl) { fail('this browser has no WebGL 2'); return; }
  try {
    compile();
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    viewer.renderer = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    const listing = await answer('/api/items', 'json');
    items = listing.items;
    levelColours = listing.level_colours;
    if (items.length === 0) { fail('the server serves nothing'); return; }
    const asked = fromHash();
    const select = $('item');
    for (const it of items) {
      const o = document.createElement('option');
      o.value = it.name;
      o.textContent = `${it.name} (${it.kind}, ${it.width}×${it.height})`;
      select.appendChild(o);
    }
    item = items.find((i) => i.name === asked.item) || items[0];
    select.value = item.name;
    defaultView(item);
    if (asked.eye && asked.target) lookAt(asked.eye, asked.target);
    select.addEventListener('change', () => {
      item = items.find((i) => i.name === select.value);
      defaultView(item);
      moved();
    });
    const tau = $('tau');
    const showTau = () => { $('tau-value').textContent = Number(tau.value).toFixed(2); };
    showTau();
    tau.addEventListener('input', () => { showTau(); moved(); });
    $('cracks').addEventListener('change', moved);
    const tin = $('tin');
    const showTin = () => { $('cracks').disabled = tin.value !== ''; };
    showTin();
    tin.addEventListener('change', () => { showTin(); moved(); });
    requestAnimationFrame(frame);
  } catch (e) {
    fail(e.message || e);
  }
}

start();
