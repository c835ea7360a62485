// macro view: the page's logic (docs/viewer.md). The camera lives here (OpenCV conventions as in
// gs/cameras/camera.h: x right, y down, z forward, world-to-camera x_c = R (x_w - c)); every frame
// is rendered by the server (POST /api/render -> PNG) and drawn 1:1 on the canvas. While the
// camera moves frames are requested at half resolution; once it rests, at full resolution.
'use strict';

const $ = (id) => document.getElementById(id);
const V = {
  scene: null,
  cam: null,      // {name, width, height, fx, fy, cx, cy, R: [9] rows, c: [3]}
  exact: null,    // the camera JSON as listed by the server, until the camera moves
  target: [0, 0, 0],
  up: [0, 0, 1],
  lastMove: 0,
  inflight: false,
  shownKey: '',   // the camera + scale of the frame on the canvas
  shownFull: false,
  frameMs: null,
  closeups: [],
  busy: false,
};

// ---- small vector maths ----------------------------------------------------------------------
const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
const mul = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
const norm = (a) => Math.sqrt(dot(a, a));
const unit = (a) => mul(a, 1 / (norm(a) || 1));
const row = (R, i) => [R[3 * i], R[3 * i + 1], R[3 * i + 2]];
// Rotation by `angle` about the unit `axis` (Rodrigues), as 3x3 rows.
function rotation(axis, angle) {
  const [x, y, z] = unit(axis), c = Math.cos(angle), s = Math.sin(angle), t = 1 - c;
  return [t * x * x + c, t * x * y - s * z, t * x * z + s * y,
          t * x * y + s * z, t * y * y + c, t * y * z - s * x,
          t * x * z - s * y, t * y * z + s * x, t * z * z + c];
}
const apply = (M, v) => [dot(row(M, 0), v), dot(row(M, 1), v), dot(row(M, 2), v)];
// R * M^T: the camera after the world-attached rotation M.
function rotateCamera(R, M) {
  const out = [];
  for (let i = 0; i < 3; i++) for (let j = 0; j < 3; j++) out.push(dot(row(R, i), row(M, j)));
  return orthonormal(out);
}
function orthonormal(R) {
  const x = unit(row(R, 0));
  const z = unit(cross(x, row(R, 1)));
  const y = cross(z, x);
  return [...x, ...y, ...z];
}

// ---- camera <-> JSON ---------------------------------------------------------------------------
function fromJson(j) {
  const m = j.world_to_camera;
  const R = [m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2]];
  const t = [m[0][3], m[1][3], m[2][3]];
  // c = -R^T t
  const c = [0, 1, 2].map((k) => -(R[k] * t[0] + R[3 + k] * t[1] + R[6 + k] * t[2]));
  return {name: j.name || '', width: j.width, height: j.height, fx: j.fx, fy: j.fy, cx: j.cx,
          cy: j.cy, R, c};
}
function toJson(cam) {
  if (V.exact) return V.exact;
  const t = mul(apply(cam.R, cam.c), -1);
  const R = cam.R;
  return {name: cam.name, width: cam.width, height: cam.height, fx: cam.fx, fy: cam.fy,
          cx: cam.cx, cy: cam.cy,
          world_to_camera: [[R[0], R[1], R[2], t[0]], [R[3], R[4], R[5], t[1]],
                            [R[6], R[7], R[8], t[2]], [0, 0, 0, 1]]};
}
const forward = () => row(V.cam.R, 2);

function setCamera(j) {
  V.cam = fromJson(j);
  V.exact = j;
  const d = Math.max(0.1 * V.scene.bounds.radius, dot(sub(V.scene.bounds.center, V.cam.c), forward()));
  V.target = add(V.cam.c, mul(forward(), d));
  sizeCanvases();
  showFov();
  moved(false);
}
function moved(interactive = true) {
  if (interactive) V.exact = null;
  V.lastMove = interactive ? performance.now() : 0;
  drawOverlay();
}

// ---- interaction -------------------------------------------------------------------------------
function orbit(dx, dy) {
  const M = rotation(V.up, -dx * 0.005);
  const N = rotation(row(V.cam.R, 0), -dy * 0.005);
  for (const Q of [M, N]) {
    V.cam.c = add(V.target, apply(Q, sub(V.cam.c, V.target)));
    V.cam.R = rotateCamera(V.cam.R, Q);
  }
  moved();
}
function look(yaw, pitch) {
  const d = norm(sub(V.target, V.cam.c));
  V.cam.R = rotateCamera(V.cam.R, rotation(V.up, yaw));
  V.cam.R = rotateCamera(V.cam.R, rotation(row(V.cam.R, 0), pitch));
  V.target = add(V.cam.c, mul(forward(), d));
  moved();
}
function pan(dx, dy) {
  const k = norm(sub(V.target, V.cam.c)) / V.cam.fy;
  const delta = add(mul(row(V.cam.R, 0), -dx * k), mul(row(V.cam.R, 1), -dy * k));
  V.cam.c = add(V.cam.c, delta);
  V.target = add(V.target, delta);
  moved();
}
function zoom(steps) {
  const f = Math.exp(steps * 0.1);
  V.cam.c = add(V.target, mul(sub(V.cam.c, V.target), f));
  moved();
}
function fly(dir) {
  const step = 0.03 * V.scene.bounds.radius;
  const delta = mul(dir, step);
  V.cam.c = add(V.cam.c, delta);
  V.target = add(V.target, delta);
  moved();
}

function installControls() {
  const cv = $('frame');
  let drag = null;
  cv.addEventListener('contextmenu', (e) => e.preventDefault());
  cv.addEventListener('mousedown', (e) => {
    cv.focus();
    drag = {x: e.clientX, y: e.clientY, pan: e.button === 2 || e.shiftKey};
    e.preventDefault();
  });
  window.addEventListener('mousemove', (e) => {
    if (!drag || !V.cam) return;
    const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
    drag.x = e.clientX;
    drag.y = e.clientY;
    if (dx === 0 && dy === 0) return;
    if (drag.pan) pan(dx, dy); else orbit(dx, dy);
  });
  window.addEventListener('mouseup', () => { drag = null; });
  cv.addEventListener('wheel', (e) => {
    e.preventDefault();
    if (V.cam) zoom(Math.sign(e.deltaY));
  }, {passive: false});
  cv.addEventListener('keydown', (e) => {
    if (!V.cam) return;
    const R = V.cam.R, k = e.key.toLowerCase();
    const moves = {w: row(R, 2), s: mul(row(R, 2), -1), d: row(R, 0), a: mul(row(R, 0), -1),
                   e: mul(row(R, 1), -1), q: row(R, 1)};
    const looks = {arrowleft: [0.03, 0], arrowright: [-0.03, 0], arrowup: [0, 0.03],
                   arrowdown: [0, -0.03]};
    if (moves[k]) fly(moves[k]);
    else if (looks[k]) look(...looks[k]);
    else return;
    e.preventDefault();
  });
}

// ---- frames ------------------------------------------------------------------------------------
function sizeCanvases() {
  for (const id of ['frame', 'overlay']) {
    const c = $(id);
    if (c.width !== V.cam.width || c.height !== V.cam.height) {
      c.width = V.cam.width;
      c.height = V.cam.height;
    }
  }
}

async function api(path, body) {
  const init = body === undefined ? {} : {method: 'POST', body: JSON.stringify(body),
                                          headers: {'Content-Type': 'application/json'}};
  const r = await fetch(path, init);
  const type = r.headers.get('Content-Type') || '';
  const data = type.startsWith('application/json') ? await r.json() : await r.blob();
  if (!r.ok) throw new Error((data && data.error) || (r.status + ' ' + r.statusText));
  return {data, headers: r.headers};
}

function status(text, ok = false) {
  $('status').textContent = text;
  $('status').className = ok ? 'ok' : '';
}

async function tick() {
  requestAnimationFrame(tick);
  if (!V.cam || V.inflight) return;
  const movingNow = performance.now() - V.lastMove < 250;
  const scale = movingNow ? 0.5 : 1;
  const cam = toJson(V.cam);
  const key = JSON.stringify(cam) + '@' + scale;
  if (key === V.shownKey) return;
  V.inflight = true;
  const t0 = performance.now();
  try {
    const {data, headers} = await api('/api/render', {camera: cam, scale});
    const bmp = await createImageBitmap(data, {colorSpaceConversion: 'none',
                                                premultiplyAlpha: 'none'});
    const ctx = $('frame').getContext('2d');
    ctx.imageSmoothingEnabled = scale !== 1;
    ctx.drawImage(bmp, 0, 0, $('frame').width, $('frame').height);
    V.shownKey = key;
    V.shownFull = scale === 1;
    V.frameMs = {render: +headers.get('X-Render-Ms'), encode: +headers.get('X-Encode-Ms'),
                 total: performance.now() - t0, size: headers.get('X-Frame-Size')};
    $('hud').textContent = `frame ${V.frameMs.size}${scale === 1 ? '' : ' (moving)'}: render ` +
        `${V.frameMs.render.toFixed(1)} ms, png ${V.frameMs.encode.toFixed(1)} ms, round trip ` +
        `${V.frameMs.total.toFixed(1)} ms`;
  } catch (err) {
    status('render: ' + err.message);
    V.shownKey = key;  // not retried until the camera changes
  } finally {
    V.inflight = false;
  }
}

// ---- overlay: the scene cameras' frusta, drawn into the current view --------------------------
function drawOverlay() {
  const cv = $('overlay'), ctx = cv.getContext('2d');
  ctx.clearRect(0, 0, cv.width, cv.height);
  if (!V.cam || !$('show-frusta').checked) return;
  const me = V.cam;
  const project = (X) => {
    const p = apply(me.R, sub(X, me.c));
    if (p[2] <= 1e-3) return null;
    return [me.fx * p[0] / p[2] + me.cx, me.fy * p[1] / p[2] + me.cy];
  };
  const depth = 0.15 * V.scene.bounds.radius;
  const draw = (j, colour) => {
    const cam = fromJson(j);
    if (norm(sub(cam.c, me.c)) < 1e-9) return;  // the camera we look through
    const corners = [[0, 0], [cam.width, 0], [cam.width, cam.height], [0, cam.height]].map(
        ([u, v]) => {
          const dirCam = [(u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy, 1];
          // world direction = R^T dirCam
          const d = [0, 1, 2].map((k) => cam.R[k] * dirCam[0] + cam.R[3 + k] * dirCam[1] +
                                          cam.R[6 + k] * dirCam[2]);
          return project(add(cam.c, mul(d, depth)));
        });
    const apex = project(cam.c);
    ctx.strokeStyle = colour;
    ctx.beginPath();
    for (let i = 0; i < 4; i++) {
      const a = corners[i], b = corners[(i + 1) % 4];
      if (a && b) { ctx.moveTo(...a); ctx.lineTo(...b); }
      if (apex && a) { ctx.moveTo(...apex); ctx.lineTo(...a); }
    }
    ctx.stroke();
  };
  for (const j of V.scene.cameras) draw(j, 'rgba(255, 200, 0, 0.8)');
  for (const j of V.closeups) draw(j, 'rgba(0, 220, 255, 0.8)');
}

function showFov() {
  $('fov').value = (2 * Math.atan(V.cam.height / 2 / V.cam.fy) * 180 / Math.PI).toFixed(2);
}

// ---- close-ups ---------------------------------------------------------------------------------
async function loadCloseups(select) {
  const {data} = await api('/api/closeups');
  V.closeups = data.closeups;
  $('closeup-file').textContent = `${data.file} (${data.kind})`;
  const list = $('closeups');
  list.innerHTML = '';
  for (const c of data.closeups) list.add(new Option(c.name, c.name));
  if (select) list.value = select;
  drawOverlay();
}

async function saveCloseup() {
  const name = $('closeup-name').value.trim();
  try {
    const {data} = await api('/api/closeups', {name, camera: toJson(V.cam),
                                               overwrite: $('overwrite').checked});
    status(`saved ${data.saved} to ${data.file}`, true);
    await loadCloseups(name);
    V.cam.name = name;
  } catch (err) {
    status('save: ' + err.message);
  }
}

function reopenCloseup() {
  const c = V.closeups.find((x) => x.name === $('closeups').value);
  if (!c) return status('reopen: choose a saved close-up first');
  setCamera(c);
  $('closeup-name').value = c.name;
  status(`close-up ${c.name}`, true);
}

// ---- plan and enhance --------------------------------------------------------------------------
const resultUrl = (rel) => '/api/results/' + rel;

async function runPlan() {
  if (V.busy) return;
  V.busy = true;
  $('job').textContent = 'planning...';
  try {
    const {data} = await api('/api/plan', {camera: toJson(V.cam)});
    V.plan = data;
    const p = data.plan;
    const refs = (p.references || []).map((r) => r.name).join(', ');
    $('plan-summary').textContent = `references: ${refs}; ${(p.planes || []).length} planes, ` +
        `${(p.crops || []).length} crops, model ${p.model_size}`;
    $('plan-download').href = resultUrl(data.folder + '/plan.json');
    const box = $('plan-images');
    box.innerHTML = '';
    const order = (f) => (f.includes('plane_map') ? 0 : f.includes('crop_') ? 2 : 1);
    const images = data.files.filter((f) => f.endsWith('.png')).sort((a, b) => order(a) - order(b));
    for (const f of images) {
      const fig = document.createElement('figure');
      const a = document.createElement('a');
      a.href = resultUrl(f);
      a.download = f.split('/')[1];
      const img = document.createElement('img');
      img.src = resultUrl(f);
      a.appendChild(img);
      const cap = document.createElement('figcaption');
      cap.textContent = f.split('/')[1];
      fig.append(a, cap);
      box.appendChild(fig);
    }
    $('plan-pane').hidden = false;
    $('job').textContent = `plan done (${p.timings_ms ? p.timings_ms.total.toFixed(0) + ' ms' : ''})`;
  } catch (err) {
    $('job').textContent = '';
    status('plan: ' + err.message);
  } finally {
    V.busy = false;
  }
}

async function runEnhance() {
  if (V.busy) return;
  V.busy = true;
  try {
    await api('/api/enhance', {camera: toJson(V.cam)});
    for (;;) {
      await new Promise((r) => setTimeout(r, 250));
      const {data} = await api('/api/enhance');
      $('job').textContent = `enhance ${data.state}: ${data.stage} (${(data.elapsed_ms / 1000).toFixed(1)} s)`;
      if (data.state === 'failed') throw new Error(data.error);
      if (data.state === 'done') {
        V.enhance = data.result;
        showEnhanced(data.result);
        break;
      }
    }
  } catch (err) {
    status('enhance: ' + err.message);
  } finally {
    V.busy = false;
  }
}

function showEnhanced(r) {
  $('cmp-enhanced').src = resultUrl(r.enhanced);
  $('cmp-render').src = resultUrl(r.render);
  $('dl-render').href = resultUrl(r.render);
  $('dl-enhanced').href = resultUrl(r.enhanced);
  $('dl-side').href = resultUrl(r.side_by_side);
  $('slider').style.width = r.size[0] + 'px';
  $('enhance-pane').hidden = false;
  $('job').textContent = `enhanced with ${r.enhancer}, ${(r.ms_total / 1000).toFixed(1)} s`;
}

// ---- start -------------------------------------------------------------------------------------
async function start() {
  installControls();
  try {
    const {data} = await api('/api/scene');
    V.scene = data;
    V.up = data.up;
    $('scene-name').textContent = `${data.scene} (${data.gaussians} Gaussians)`;
    const list = $('cameras');
    for (const c of data.cameras) list.add(new Option(`${c.name}  ${c.width}x${c.height}`, c.name));
    list.addEventListener('change', () => {
      const c = data.cameras.find((x) => x.name === list.value);
      if (c) setCamera(c);
    });
    $('show-frusta').addEventListener('change', drawOverlay);
    $('fov').addEventListener('change', () => {
      const deg = +$('fov').value;
      if (!(deg > 0 && deg < 180)) return showFov();
      const fy = V.cam.height / 2 / Math.tan(deg * Math.PI / 360);
      V.cam.fx *= fy / V.cam.fy;
      V.cam.fy = fy;
      moved();
    });
    $('save').addEventListener('click', saveCloseup);
    $('reopen').addEventListener('click', reopenCloseup);
    $('closeups').addEventListener('dblclick', reopenCloseup);
    $('plan').addEventListener('click', runPlan);
    $('enhance').addEventListener('click', runEnhance);
    $('plan').disabled = $('enhance').disabled = !data.can_plan;
    $('slider').addEventListener('input', () => {
      $('cmp-clip').style.width = $('slider').value + '%';
    });
    await loadCloseups();
    if (data.cameras.length) {
      list.value = data.cameras[0].name;
      setCamera(data.cameras[0]);
    } else if (V.closeups.length) {
      setCamera(V.closeups[0]);
    } else {
      status('the scene has no cameras to start from');
    }
    requestAnimationFrame(tick);
  } catch (err) {
    status('scene: ' + err.message);
  }
}

// What the browser test reads (tests/test_view_browser.cpp).
window.viewer = {
  camera: () => (V.cam ? toJson(V.cam) : null),
  // The canvas shows the full-resolution frame of the current camera and nothing is pending.
  idle: () => !!V.cam && !V.inflight && V.shownFull &&
      V.shownKey === JSON.stringify(toJson(V.cam)) + '@1' && performance.now() - V.lastMove > 300,
  state: V,
};

start();
