// The live page of `rigidsim live`: the replay viewer's scene, camera and
// picking, fed by the live run's WebSocket (messages in docs/live.md). A
// person grabs a body with the mouse and drags it (grab, drag, release:
// the hand's spring pulls the grabbed point towards the point under the
// cursor, in the plane facing the camera through the grab point), pushes
// one with shift-click, and pauses, resets or stops the run.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// Fallen bodies are drawn in this grey, a held or picked one lightened
// towards white (as in the replay).
const FALLEN_GREY = srgb([0.42, 0.42, 0.44]);
const PICK_LIGHTEN = 0.55;
// A push changes the pushed body's speed by about this much, m/s.
const PUSH_SPEED = 1.0;

function srgb([r, g, b]) { return new THREE.Color().setRGB(r, g, b, THREE.SRGBColorSpace); }

// ---- scene, camera, lights ---------------------------------------------
const canvas = document.getElementById('view');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0xdde3ea);
scene.add(new THREE.HemisphereLight(0xffffff, 0x8a8f99, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.8);
scene.add(sun);
const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 100);
camera.up.set(0, 0, 1); // rigidsim's z is up
const controls = new OrbitControls(camera, canvas);
controls.enableDamping = false;

const factsText = document.getElementById('facts');
const clock = document.getElementById('clock');
const pickedPanel = document.getElementById('picked');
const statusPanel = document.getElementById('status');
const pauseButton = document.getElementById('pause');

let header = null; // the scene message
let meshes = [];
let instanceOf = null;
let state = null; // the latest state message
let ended = null;
let statesSeen = 0;
let errorsSeen = [];
let framed = false;

// ---- the connection -------------------------------------------------------
// The page's own query (a token, when the run is served beyond loopback)
// goes with the upgrade.
const socket = new WebSocket(`${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}/ws${location.search}`);
const send = (message) => { if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify(message)); };
socket.addEventListener('message', (event) => {
  const message = JSON.parse(event.data);
  if (message.type === 'scene') build(message);
  else if (message.type === 'state') { state = message; statesSeen++; }
  else if (message.type === 'error') { errorsSeen.push(message.message); statusPanel.textContent = message.message; }
  else if (message.type === 'end') { ended = message.end_reason; showFacts(); }
});
socket.addEventListener('close', () => { if (!ended) { ended = 'connection closed'; showFacts(); } });

function build(message) {
  header = message;
  document.getElementById('scene-name').textContent = header.scene;
  meshes = header.objects.map((object, index) => {
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(object.vertices), 3));
    geometry.setIndex(new THREE.BufferAttribute(new Uint32Array(object.indices), 1));
    geometry.computeBoundingSphere();
    const bodies = [];
    for (let i = 0; i < header.bodies; i++) if (header.body_object[i] === index) bodies.push(i);
    const material = new THREE.MeshStandardMaterial({ flatShading: true, roughness: 0.6, metalness: 0.1 });
    const mesh = new THREE.InstancedMesh(geometry, material, Math.max(bodies.length, 1));
    mesh.count = bodies.length;
    mesh.instanceMatrix.setUsage(THREE.DynamicDrawUsage);
    mesh.frustumCulled = false; // bodies move
    mesh.userData = { bodies, colour: srgb(object.color) };
    scene.add(mesh);
    return mesh;
  });
  instanceOf = new Int32Array(header.bodies);
  for (const mesh of meshes) mesh.userData.bodies.forEach((body, k) => { instanceOf[body] = k; });
  const floor = header.floor;
  const grid = new THREE.GridHelper(2 * floor.half_size, 20, 0x59606b, 0x9aa1ab);
  grid.rotation.x = Math.PI / 2; // GridHelper lies in x-z; rigidsim's floor is x-y
  grid.position.set(floor.center[0], floor.center[1], floor.z + 1e-3 * floor.half_size);
  scene.add(grid);
  if (header.camera) camera.fov = header.camera.fov_y_deg;
}

// ---- bodies as the latest state has them ----------------------------------
const matrix = new THREE.Matrix4();
const one = new THREE.Vector3(1, 1, 1);
const colour = new THREE.Color();
const white = new THREE.Color(1, 1, 1);
const place = new THREE.Vector3();
const turn = new THREE.Quaternion();

function bodyPose(body, position, orientation) {
  const b = state.bodies[body];
  position.set(b[0], b[1], b[2]);
  orientation.set(b[4], b[5], b[6], b[3]).normalize(); // three.js: x, y, z, w
}

function placeBodies() {
  const fallen = new Set(state.fallen);
  for (const mesh of meshes) {
    const { bodies, colour: base } = mesh.userData;
    for (let k = 0; k < bodies.length; k++) {
      const body = bodies[k];
      bodyPose(body, place, turn);
      matrix.compose(place, turn, one);
      mesh.setMatrixAt(k, matrix);
      colour.copy(fallen.has(body) ? FALLEN_GREY : base);
      if (body === picked || (grab && body === grab.body)) colour.lerp(white, PICK_LIGHTEN);
      mesh.setColorAt(k, colour);
    }
    mesh.instanceMatrix.needsUpdate = true;
    if (mesh.instanceColor) mesh.instanceColor.needsUpdate = true;
  }
}

function frameCamera() {
  if (header.camera) {
    camera.position.fromArray(header.camera.eye);
    controls.target.fromArray(header.camera.target);
  } else {
    // Frame the moving bodies where the first state has them.
    const box = new THREE.Box3();
    const all = [...Array(header.bodies).keys()];
    const dynamic = all.filter((i) => header.body_kind[i] === 'dynamic');
    for (const body of dynamic.length ? dynamic : all) {
      const radius = meshes[header.body_object[body]].geometry.boundingSphere.radius;
      bodyPose(body, place, turn);
      box.expandByPoint(place.clone().addScalar(radius)).expandByPoint(place.clone().addScalar(-radius));
    }
    const centre = box.getCenter(new THREE.Vector3());
    const size = Math.max(box.getSize(new THREE.Vector3()).length(), 0.1);
    controls.target.copy(centre);
    camera.position.copy(centre).add(new THREE.Vector3(0.8, -1.1, 0.7).normalize().multiplyScalar(1.6 * size));
  }
  const distance = camera.position.distanceTo(controls.target);
  camera.near = distance / 1000;
  camera.far = 20 * (distance + header.floor.half_size);
  camera.updateProjectionMatrix();
  sun.position.copy(camera.position).add(new THREE.Vector3(0, 0, distance));
  controls.update();
}

function showFacts() {
  if (!header) return;
  const bits = [`· ${header.bodies} bodies`];
  if (ended) bits.push(`· ended by ${ended}`);
  else if (state?.paused) bits.push('· paused');
  factsText.textContent = bits.join(' ');
}

function showClock() {
  if (!state) return;
  const behind = state.worst_frame_s > state.frame_interval_s;
  clock.textContent = `t = ${state.t.toFixed(2)} s · ${state.paused ? 'paused' : `${state.realtime_factor.toFixed(2)}× real time`}` +
    ` · worst frame ${(1000 * state.worst_frame_s).toFixed(1)} ms${behind ? ' (behind)' : ''}`;
  pauseButton.textContent = state.paused ? 'resume' : 'pause';
}

// ---- picking, the hand, pushes ------------------------------------------------
const raycaster = new THREE.Raycaster();
function rayAt(x, y) {
  const rect = canvas.getBoundingClientRect();
  const ndc = new THREE.Vector2(((x - rect.left) / rect.width) * 2 - 1, -((y - rect.top) / rect.height) * 2 + 1);
  raycaster.setFromCamera(ndc, camera);
  return raycaster.ray;
}

/// The body under the pixel and where the ray meets it, or null.
function hitAt(x, y) {
  if (!state) return null;
  rayAt(x, y);
  for (const mesh of meshes) mesh.computeBoundingSphere(); // instances moved
  const hit = raycaster.intersectObjects(meshes, false)[0];
  return hit ? { body: hit.object.userData.bodies[hit.instanceId], point: hit.point.clone() } : null;
}

let picked = -1;
let grab = null; // { body, plane } while the hand holds a body

function showPicked() {
  if (picked < 0 || !state) { pickedPanel.textContent = 'click a body'; return; }
  bodyPose(picked, place, turn);
  const object = header.objects[header.body_object[picked]].name;
  pickedPanel.textContent = [
    `body ${picked} · ${object} (${header.body_kind[picked]})`,
    `mass      ${header.body_mass[picked].toPrecision(4)} kg`,
    `position  ${place.x.toFixed(4)}, ${place.y.toFixed(4)}, ${place.z.toFixed(4)} m`,
    grab ? 'held' : (state.resting.includes(picked) ? 'resting' : ''),
  ].join('\n');
}

const movable = (body) => header.body_kind[body] === 'dynamic';

// Registered for the capture phase, so it runs before the orbit controls'
// own listener, which it turns off while a body is held.
canvas.addEventListener('pointerdown', (e) => {
  if (e.button !== 0 || ended) return;
  const hit = hitAt(e.clientX, e.clientY);
  if (!hit) return;
  picked = hit.body;
  if (!movable(hit.body)) return;
  if (e.shiftKey) {
    const direction = raycaster.ray.direction.clone();
    const impulse = direction.multiplyScalar(PUSH_SPEED * header.body_mass[hit.body]);
    send({ type: 'push', body: hit.body, point: hit.point.toArray(), impulse: impulse.toArray() });
    return;
  }
  // The plane facing the camera through the grab point.
  const normal = camera.getWorldDirection(new THREE.Vector3());
  grab = { body: hit.body, plane: new THREE.Plane().setFromNormalAndCoplanarPoint(normal, hit.point) };
  controls.enabled = false;
  canvas.setPointerCapture(e.pointerId);
  send({ type: 'grab', body: hit.body, point: hit.point.toArray() });
}, { capture: true });

let pendingTarget = null;
canvas.addEventListener('pointermove', (e) => {
  if (!grab) return;
  const target = rayAt(e.clientX, e.clientY).intersectPlane(grab.plane, new THREE.Vector3());
  if (target) pendingTarget = target; // sent once per drawn frame
});

function letGo(e) {
  if (!grab) return;
  if (pendingTarget) { send({ type: 'drag', target: pendingTarget.toArray() }); pendingTarget = null; }
  send({ type: 'release' });
  grab = null;
  controls.enabled = true;
  if (e && canvas.hasPointerCapture(e.pointerId)) canvas.releasePointerCapture(e.pointerId);
}
canvas.addEventListener('pointerup', letGo);
canvas.addEventListener('pointercancel', letGo);

// ---- buttons ----------------------------------------------------------------
pauseButton.addEventListener('click', () => send({ type: state?.paused ? 'resume' : 'pause' }));
document.getElementById('reset').addEventListener('click', () => { letGo(); send({ type: 'reset' }); });
document.getElementById('stop').addEventListener('click', () => { letGo(); send({ type: 'stop' }); });
window.addEventListener('keydown', (e) => {
  if (e.code === 'Space' && e.target === document.body) { e.preventDefault(); pauseButton.click(); }
});

// ---- the frame loop ---------------------------------------------------------
function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  renderer.setSize(w, h, false);
  camera.aspect = w / Math.max(h, 1);
  camera.updateProjectionMatrix();
}
window.addEventListener('resize', resize);

let framesDrawn = 0;
function frame() {
  if (pendingTarget && grab) { send({ type: 'drag', target: pendingTarget.toArray() }); pendingTarget = null; }
  if (header && state) {
    if (!framed) { frameCamera(); framed = true; }
    placeBodies();
    showClock();
    showFacts();
    showPicked();
  }
  controls.update();
  renderer.render(scene, camera);
  framesDrawn++;
  requestAnimationFrame(frame);
}
resize();
requestAnimationFrame(frame);

// ---- a hook for tests (tests/live.rs drives the page in headless Chromium) --
// It reads what the page holds and shows; it changes nothing the page does.
window.rigidsimLive = {
  ready: () => Boolean(header && state && framed),
  statesSeen: () => statesSeen,
  errors: () => errorsSeen.slice(),
  ended: () => ended,
  time: () => state?.t,
  framesDrawn: () => framesDrawn,
  bodyPosition: (body) => state.bodies[body].slice(0, 3),
  held: () => (grab ? grab.body : -1),
  /// The camera's view-projection matrix (column-major) and the canvas
  /// size in CSS pixels, for projecting world points as the page does.
  camera: () => {
    camera.updateMatrixWorld();
    const m = new THREE.Matrix4().multiplyMatrices(camera.projectionMatrix, camera.matrixWorldInverse);
    const rect = canvas.getBoundingClientRect();
    return { viewProjection: m.elements.slice(), left: rect.left, top: rect.top, width: rect.width, height: rect.height };
  },
};
