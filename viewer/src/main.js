// The replay page of `rigidsim view`: reads the header and the binary block
// the page embeds (layout in src/view/replay_data.rs), draws every object's
// bodies as one instanced mesh, and plays the sampled trajectory back,
// interpolating positions linearly and orientations by slerp.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const FORMAT = 1;
const SPEEDS = [0.25, 0.5, 1, 2, 4];
// Fallen bodies are drawn in this grey, a picked one lightened towards white.
const FALLEN_GREY = srgb([0.42, 0.42, 0.44]);
const PICK_LIGHTEN = 0.55;
const KINETIC_COLOUR = '#d4651a';
const POTENTIAL_COLOUR = '#2a62b8';
const TOTAL_COLOUR = '#7a8290';

// A scene's colours are sRGB, as an image viewer shows them; three.js
// lights in linear RGB and converts back when it writes the canvas.
function srgb([r, g, b]) { return new THREE.Color().setRGB(r, g, b, THREE.SRGBColorSpace); }

const header = JSON.parse(document.getElementById('replay-header').textContent);
if (header.format !== FORMAT) {
  throw new Error(`replay data format ${header.format}, this viewer reads ${FORMAT}`);
}
const binary = decodeBase64(document.getElementById('replay-data').textContent);
const view = (slice, Type) => new Type(binary.buffer, slice.offset, slice.count);
const times = view(header.times, Float64Array);
const positions = view(header.positions, Float32Array);
const orientations = view(header.orientations, Int16Array);
const speeds = view(header.speeds, Float32Array);
const bodyCount = header.bodies;
// A run resumed into a new folder starts its trajectory at the checkpoint's
// time: the replay spans the samples there are.
const startTime = times[0];
const endTime = times[times.length - 1];

function decodeBase64(text) {
  const chars = atob(text.trim());
  const bytes = new Uint8Array(chars.length);
  for (let i = 0; i < chars.length; i++) bytes[i] = chars.charCodeAt(i);
  return bytes;
}

// Fall times: `summary.json`'s list; a dynamic body below the cut-off
// (a run that predates the list) is greyed out from that sample on.
const fellAt = new Float64Array(bodyCount).fill(Infinity);
for (const [body, time] of header.fallen) fellAt[body] = Math.min(fellAt[body], time);
const fallZ = header.fall_z ?? -Infinity;

// ---- scene, camera, lights ---------------------------------------------
const canvas = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xdde3ea);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
scene.add(sun);

const camera = new THREE.PerspectiveCamera(header.camera?.fov_y_deg ?? 45, 1, 0.01, 100);
camera.up.set(0, 0, 1); // rigidsim's z is up; OrbitControls orbits about camera.up
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = false;

// ---- one instanced mesh per object ---------------------------------------
const meshes = header.objects.map((object, index) => {
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(view(object.vertices, Float32Array), 3));
  geometry.setIndex(new THREE.BufferAttribute(view(object.indices, Uint32Array), 1));
  geometry.computeBoundingSphere();
  const bodies = [];
  for (let i = 0; i < bodyCount; i++) if (header.body_object[i] === index) bodies.push(i);
  const material = new THREE.MeshStandardMaterial({ flatShading: true, roughness: 0.6, metalness: 0.1 });
  const mesh = new THREE.InstancedMesh(geometry, material, Math.max(bodies.length, 1));
  mesh.count = bodies.length;
  mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
  // Bodies move: the bounds three.js would cull by are those of t = 0.
  mesh.frustumCulled = false;
  mesh.userData = { bodies, colour: srgb(object.color), name: object.name };
  scene.add(mesh);
  return mesh;
});
const instanceOf = new Int32Array(bodyCount); // body -> its place in its object's mesh
for (const mesh of meshes) mesh.userData.bodies.forEach((body, k) => { instanceOf[body] = k; });

const floor = header.floor;
const grid = new THREE.GridHelper(2 * floor.half_size, 20, 0x59606b, 0x9aa1ab);
grid.rotation.x = Math.PI / 2; // GridHelper lies in x-z; rigidsim's floor is x-y
grid.position.set(floor.center[0], floor.center[1], floor.z + 1e-3 * floor.half_size);
scene.add(grid);

// ---- the state at a time ------------------------------------------------
const qa = new THREE.Quaternion();
const qb = new THREE.Quaternion();
const matrix = new THREE.Matrix4();
const one = new THREE.Vector3(1, 1, 1);
const colour = new THREE.Color();

/// The sample k with times[k] <= t < times[k + 1] and the fraction of the way to k + 1.
function sampleAt(t) {
  if (t <= times[0]) return [0, 0];
  const last = times.length - 1;
  if (t >= times[last]) return [last, 0];
  let lo = 0, hi = last;
  while (hi - lo > 1) {
    const mid = (lo + hi) >> 1;
    if (times[mid] <= t) lo = mid; else hi = mid;
  }
  return [lo, (t - times[lo]) / (times[lo + 1] - times[lo])];
}

function quaternionAt(k, body, out) {
  const j = 4 * (k * bodyCount + body);
  return out.set(orientations[j], orientations[j + 1], orientations[j + 2], orientations[j + 3]).normalize();
}

/// Body `body` at time t: its centre of mass into `position`, its
/// orientation into `orientation`; returns its speed.
function bodyStateInto(body, t, position, orientation) {
  const [k, f] = sampleAt(t);
  const k1 = Math.min(k + 1, times.length - 1);
  const a = 3 * (k * bodyCount + body), b = 3 * (k1 * bodyCount + body);
  position.set(
    positions[a] + f * (positions[b] - positions[a]),
    positions[a + 1] + f * (positions[b + 1] - positions[a + 1]),
    positions[a + 2] + f * (positions[b + 2] - positions[a + 2]));
  orientation.slerpQuaternions(quaternionAt(k, body, qa), quaternionAt(k1, body, qb), f);
  const s0 = speeds[k * bodyCount + body], s1 = speeds[k1 * bodyCount + body];
  return s0 + f * (s1 - s0);
}

function bodyState(body, t) {
  const position = new THREE.Vector3(), orientation = new THREE.Quaternion();
  const speed = bodyStateInto(body, t, position, orientation);
  return { position, orientation, speed };
}

function hasFallen(body, t, z) {
  return header.body_kind[body] === 'dynamic' && (fellAt[body] <= t || z < fallZ);
}

let currentTime = startTime;
let picked = -1;
let framesDrawn = 0;

const place = new THREE.Vector3();
const turn = new THREE.Quaternion();
const white = new THREE.Color(1, 1, 1);
function placeBodies(t) {
  for (const mesh of meshes) {
    const { bodies, colour: base } = mesh.userData;
    for (let k = 0; k < bodies.length; k++) {
      const body = bodies[k];
      bodyStateInto(body, t, place, turn);
      matrix.compose(place, turn, one);
      mesh.setMatrixAt(k, matrix);
      colour.copy(hasFallen(body, t, place.z) ? FALLEN_GREY : base);
      if (body === picked) colour.lerp(white, PICK_LIGHTEN);
      mesh.setColorAt(k, colour);
    }
    mesh.instanceMatrix.needsUpdate = true;
    if (mesh.instanceColor) mesh.instanceColor.needsUpdate = true;
  }
}

// ---- camera framing -------------------------------------------------------
function frameCamera() {
  if (header.camera) {
    camera.position.fromArray(header.camera.eye);
    controls.target.fromArray(header.camera.target);
  } else {
    // Frame the moving bodies at t = 0 (all bodies if none moves).
    const box = new THREE.Box3();
    const dynamic = [...Array(bodyCount).keys()].filter((i) => header.body_kind[i] === 'dynamic');
    for (const body of dynamic.length ? dynamic : [...Array(bodyCount).keys()]) {
      const radius = meshes[header.body_object[body]].geometry.boundingSphere.radius;
      const p = bodyState(body, 0).position;
      box.expandByPoint(p.clone().addScalar(radius)).expandByPoint(p.clone().addScalar(-radius));
    }
    const centre = box.getCenter(new THREE.Vector3());
    const size = Math.max(box.getSize(new THREE.Vector3()).length(), 0.1);
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(0.8, -1.1, 0.7).normalize().multiplyScalar(1.6 * size));
  }
  const distance = camera.position.distanceTo(controls.target);
  camera.near = distance / 1000;
  camera.far = 20 * (distance + floor.half_size);
  camera.updateProjectionMatrix();
  sun.position.copy(camera.position).add(new THREE.Vector3(0, 0, distance));
  controls.update();
}

// ---- controls: play, speed, time ------------------------------------------
const playButton = document.getElementById('play');
const speedSelect = document.getElementById('speed');
const slider = document.getElementById('time');
const clock = document.getElementById('clock');
const pickedPanel = document.getElementById('picked');
slider.min = String(startTime);
slider.max = String(endTime);
document.getElementById('scene-name').textContent = header.scene;
document.getElementById('facts').textContent =
  `· ${bodyCount} bodies · ${endTime.toFixed(3)} s · ended by ${header.end_reason}` +
  (header.fallen.length ? ` · ${header.fallen.length} fell` : '');

let playing = false;
let speed = 1;
function setPlaying(on) {
  playing = on && times.length > 1;
  if (playing && currentTime >= endTime) currentTime = startTime;
  playButton.textContent = playing ? 'pause' : 'play';
}
playButton.addEventListener('click', () => setPlaying(!playing));
speedSelect.addEventListener('change', () => { speed = Number(speedSelect.value); });
slider.addEventListener('input', () => { setTime(Number(slider.value)); });
window.addEventListener('keydown', (e) => {
  if (e.code === 'Space' && e.target === document.body) { e.preventDefault(); setPlaying(!playing); }
});

function setTime(t) {
  currentTime = Math.min(Math.max(t, startTime), endTime);
}

const digits = endTime < 100 ? 3 : 2;
function showTime() {
  slider.value = String(currentTime);
  clock.textContent = `t = ${currentTime.toFixed(digits)} s / ${endTime.toFixed(digits)} s`;
}

// ---- picking ----------------------------------------------------------------
const raycaster = new THREE.Raycaster();
function bodyAtPixel(x, y) {
  const rect = canvas.getBoundingClientRect();
  const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
  raycaster.setFromCamera(ndc, camera);
  // Instanced meshes test the ray against their bounds first: refresh them.
  for (const mesh of meshes) mesh.computeBoundingSphere();
  const hit = raycaster.intersectObjects(meshes, false)[0];
  return hit ? hit.object.userData.bodies[hit.instanceId] : -1;
}

function showPicked() {
  if (picked < 0) { pickedPanel.textContent = 'click a body'; return; }
  const s = bodyState(picked, currentTime);
  const p = s.position;
  const object = header.objects[header.body_object[picked]].name;
  const lines = [
    `body ${picked} · ${object} (${header.body_kind[picked]})`,
    `mass      ${header.body_mass[picked].toPrecision(4)} kg`,
    `position  ${p.x.toFixed(4)}, ${p.y.toFixed(4)}, ${p.z.toFixed(4)} m`,
    `speed     ${s.speed.toFixed(4)} m/s`,
  ];
  if (Number.isFinite(fellAt[picked])) lines.push(`fell at   ${fellAt[picked].toFixed(3)} s`);
  else if (hasFallen(picked, currentTime, p.z)) lines.push('below fall_z');
  pickedPanel.textContent = lines.join('\n');
}

let downAt = null;
canvas.addEventListener('pointerdown', (e) => { downAt = [e.clientX, e.clientY]; });
canvas.addEventListener('pointerup', (e) => {
  // A click picks; a drag turns the camera.
  if (downAt && Math.hypot(e.clientX - downAt[0], e.clientY - downAt[1]) < 4) picked = bodyAtPixel(e.clientX, e.clientY);
  downAt = null;
});

// ---- energy plot ------------------------------------------------------------
const energyCanvas = document.getElementById('energy');
const kinetic = header.kinetic_j, potential = header.potential_j;
const total = kinetic.map((k, i) => k + potential[i]);
// Loops, not Math.min(...series): a long run's series would overflow the
// argument list.
let energyMin = 0, energyMax = 1e-12;
for (const series of [kinetic, potential, total]) {
  for (const e of series) { energyMin = Math.min(energyMin, e); energyMax = Math.max(energyMax, e); }
}
const plotMargin = { left: 8, right: 8, top: 20, bottom: 16 };
function drawEnergy() {
  const ratio = window.devicePixelRatio || 1;
  const w = energyCanvas.clientWidth, h = energyCanvas.clientHeight;
  if (energyCanvas.width !== Math.round(w * ratio)) { energyCanvas.width = Math.round(w * ratio); energyCanvas.height = Math.round(h * ratio); }
  const g = energyCanvas.getContext('2d');
  g.setTransform(ratio, 0, 0, ratio, 0, 0);
  g.clearRect(0, 0, w, h);
  const span = endTime - startTime;
  const x = (t) => plotMargin.left + (span > 0 ? (t - startTime) / span : 0) * (w - plotMargin.left - plotMargin.right);
  const y = (e) => h - plotMargin.bottom - ((e - energyMin) / (energyMax - energyMin)) * (h - plotMargin.top - plotMargin.bottom);
  g.strokeStyle = '#c5cbd3'; g.lineWidth = 1;
  g.beginPath(); g.moveTo(x(startTime), y(0)); g.lineTo(x(endTime), y(0)); g.stroke();
  for (const [series, style] of [[total, TOTAL_COLOUR], [potential, POTENTIAL_COLOUR], [kinetic, KINETIC_COLOUR]]) {
    g.strokeStyle = style; g.lineWidth = 1.5; g.beginPath();
    series.forEach((e, i) => (i ? g.lineTo(x(times[i]), y(e)) : g.moveTo(x(times[i]), y(e))));
    g.stroke();
  }
  g.strokeStyle = '#1d2430'; g.lineWidth = 1;
  g.beginPath(); g.moveTo(x(currentTime), plotMargin.top - 4); g.lineTo(x(currentTime), h - plotMargin.bottom + 3); g.stroke();
  const [k, f] = sampleAt(currentTime);
  const k1 = Math.min(k + 1, times.length - 1);
  const at = (s) => s[k] + f * (s[k1] - s[k]);
  g.font = '11px system-ui, sans-serif'; g.textBaseline = 'top';
  g.fillStyle = KINETIC_COLOUR; g.fillText(`kinetic ${formatJ(at(kinetic))}`, 6, 4);
  g.fillStyle = POTENTIAL_COLOUR; g.fillText(`potential ${formatJ(at(potential))}`, 112, 4);
  g.fillStyle = TOTAL_COLOUR; g.fillText(`total ${formatJ(at(total))}`, 232, 4);
  g.fillStyle = '#566'; g.textBaseline = 'bottom';
  g.fillText(`${startTime.toFixed(digits)} s`, plotMargin.left, h - 1);
  g.textAlign = 'right'; g.fillText(`${endTime.toFixed(digits)} s`, w - plotMargin.right, h - 1); g.textAlign = 'left';
}
function formatJ(e) { return `${Math.abs(e) >= 1000 ? e.toFixed(0) : e.toPrecision(3)} J`; }
energyCanvas.addEventListener('click', (e) => {
  const rect = energyCanvas.getBoundingClientRect();
  const fraction = (e.clientX - rect.left - plotMargin.left) / (rect.width - plotMargin.left - plotMargin.right);
  setTime(startTime + fraction * (endTime - startTime));
});

// ---- the frame loop ---------------------------------------------------------
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);

let lastFrame = null;
// The bodies are placed again only when the time or the picked body changed:
// a paused replay of many bodies costs only the draw while the camera turns.
let placedAt = null, placedPick = null;
let updateMs = 0;
function frame(now) {
  const started = performance.now();
  if (playing && lastFrame !== null) {
    currentTime = Math.min(currentTime + ((now - lastFrame) / 1000) * speed, endTime);
    if (currentTime >= endTime) setPlaying(false);
  }
  lastFrame = now;
  if (currentTime !== placedAt || picked !== placedPick) {
    placeBodies(currentTime);
    placedAt = currentTime;
    placedPick = picked;
    showTime();
    drawEnergy();
  }
  showPicked();
  controls.update();
  updateMs = performance.now() - started;
  renderer.render(scene, camera);
  framesDrawn++;
  requestAnimationFrame(frame);
}

resize();
frameCamera();
requestAnimationFrame(frame);

// ---- a hook for the browser test (viewer/test/replay_in_chromium.mjs) ------
// It reads what the page shows and the camera it draws with; it changes
// nothing the viewer does.
window.rigidsimReplay = {
  endTime,
  speeds: SPEEDS,
  framesDrawn: () => framesDrawn,
  /// Milliseconds the last frame spent in the viewer's own code (placing
  /// bodies, panels, plot), before three.js drew it.
  updateMs: () => updateMs,
  time: () => currentTime,
  setTime: (t) => { setPlaying(false); setTime(t); },
  sliderMax: () => Number(slider.max),
  sliderValue: () => Number(slider.value),
  clockText: () => clock.textContent,
  pickedText: () => pickedPanel.textContent,
  bodyPosition: (body) => bodyState(body, currentTime).position.toArray(),
  /// The camera's view-projection matrix (column-major) and the canvas
  /// size in CSS pixels, for projecting world points as the page does.
  camera: () => {
    camera.updateMatrixWorld();
    const m = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
    const rect = canvas.getBoundingClientRect();
    return { viewProjection: m.elements.slice(), left: rect.left, top: rect.top, width: rect.width, height: rect.height };
  },
  colourOf: (body) => {
    const mesh = meshes[header.body_object[body]];
    const c = new THREE.Color();
    mesh.getColorAt(instanceOf[body], c);
    return c.toArray();
  },
};
