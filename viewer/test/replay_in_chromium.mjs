// Opens a replay page in headless Chromium (Debian's `chromium`, software
// WebGL through SwiftShader) and checks what it draws against the run it
// was written from:
//   - it loads with no request beyond the page's own file, and no console error;
//   - at t = 0 and at the end, the pixels where the page's camera projects
//     the body's trajectory.csv position have the body's colour, and at the
//     end its starting place no longer does (it moved, and the page moved it);
//   - the page's positions are the trajectory's (to f32 rounding);
//   - playing at 4x stops at the end, where the slider's time and the clock
//     equal summary.json's sim_time_s; clicking the body picks it.
//
//   node viewer/test/replay_in_chromium.mjs --page OUT/replay.html --run OUT --body 1 [--screenshots DIR]
//   node viewer/test/replay_in_chromium.mjs --page OUT/replay.html --measure [--shot FILE --at T --pick BODY]
//
// --measure only loads the page and prints its size and the time until it
// first drew (the numbers docs/viewer.md states); --shot takes a picture.

import { chromium } from 'playwright-core';
import { readFileSync, statSync, writeFileSync, mkdirSync } from 'node:fs';
import { inflateSync } from 'node:zlib';
import { resolve, join } from 'node:path';
import { pathToFileURL } from 'node:url';

const args = parseArgs(process.argv.slice(2));
const VIEWPORT = { width: 1000, height: 640 };
// A patch this wide around a projected point is averaged; a body must cover it.
const PATCH = 2;
// Chromaticity (r, g, b over their sum) of a lit face stays within this of its
// colour's: shading scales a colour, it hardly turns it.
const SAME_COLOUR = 0.06;

function parseArgs(list) {
  const out = {};
  for (let i = 0; i < list.length; i++) {
    const key = list[i].replace(/^--/, '');
    const next = list[i + 1];
    if (next === undefined || next.startsWith('--')) out[key] = true;
    else { out[key] = next; i++; }
  }
  return out;
}

const failures = [];
function check(ok, what) {
  console.log(`${ok ? 'ok' : 'FAILED'}: ${what}`);
  if (!ok) failures.push(what);
}

// ---- PNG (as Chromium writes screenshots: 8-bit RGB or RGBA, not interlaced)
function decodePng(buffer) {
  let offset = 8;
  let width = 0, height = 0, channels = 0;
  const idat = [];
  while (offset < buffer.length) {
    const length = buffer.readUInt32BE(offset);
    const type = buffer.toString('latin1', offset + 4, offset + 8);
    const data = buffer.subarray(offset + 8, offset + 8 + length);
    if (type === 'IHDR') {
      width = data.readUInt32BE(0); height = data.readUInt32BE(4);
      const [depth, colourType, , , interlace] = data.subarray(8, 13);
      if (depth !== 8 || interlace !== 0 || (colourType !== 2 && colourType !== 6)) throw new Error('unexpected PNG kind');
      channels = colourType === 6 ? 4 : 3;
    } else if (type === 'IDAT') idat.push(data);
    offset += 12 + length;
  }
  const raw = inflateSync(Buffer.concat(idat));
  const stride = width * channels;
  const pixels = Buffer.alloc(height * stride);
  for (let y = 0; y < height; y++) {
    const filter = raw[y * (stride + 1)];
    const line = raw.subarray(y * (stride + 1) + 1, (y + 1) * (stride + 1));
    for (let x = 0; x < stride; x++) {
      const left = x >= channels ? pixels[y * stride + x - channels] : 0;
      const up = y > 0 ? pixels[(y - 1) * stride + x] : 0;
      const upLeft = y > 0 && x >= channels ? pixels[(y - 1) * stride + x - channels] : 0;
      let value = line[x];
      if (filter === 1) value += left;
      else if (filter === 2) value += up;
      else if (filter === 3) value += (left + up) >> 1;
      else if (filter === 4) {
        const p = left + up - upLeft;
        const pa = Math.abs(p - left), pb = Math.abs(p - up), pc = Math.abs(p - upLeft);
        value += pa <= pb && pa <= pc ? left : pb <= pc ? up : upLeft;
      }
      pixels[y * stride + x] = value & 0xff;
    }
  }
  return { width, height, channels, pixels };
}

function patchColour(image, x, y) {
  const sum = [0, 0, 0];
  let n = 0;
  for (let dy = -PATCH; dy <= PATCH; dy++) for (let dx = -PATCH; dx <= PATCH; dx++) {
    const px = Math.round(x) + dx, py = Math.round(y) + dy;
    if (px < 0 || py < 0 || px >= image.width || py >= image.height) continue;
    const i = (py * image.width + px) * image.channels;
    for (let c = 0; c < 3; c++) sum[c] += image.pixels[i + c];
    n++;
  }
  return sum.map((s) => s / Math.max(n, 1));
}

function chromaticityDistance(a, b) {
  const chroma = (c) => { const s = c[0] + c[1] + c[2] || 1; return c.map((v) => v / s); };
  const ca = chroma(a), cb = chroma(b);
  return Math.hypot(ca[0] - cb[0], ca[1] - cb[1], ca[2] - cb[2]);
}

function project(camera, [x, y, z]) {
  const m = camera.viewProjection; // column-major
  const cx = m[0] * x + m[4] * y + m[8] * z + m[12];
  const cy = m[1] * x + m[5] * y + m[9] * z + m[13];
  const cw = m[3] * x + m[7] * y + m[11] * z + m[15];
  return [camera.left + ((cx / cw + 1) / 2) * camera.width, camera.top + ((1 - cy / cw) / 2) * camera.height];
}

/// trajectory.csv's rows of one body: [[time, x, y, z], ...].
function trajectoryOf(csvPath, body) {
  return readFileSync(csvPath, 'utf8').trim().split('\n').slice(1)
    .map((line) => line.split(',').map(Number))
    .filter((row) => row[1] === body)
    .map((row) => [row[0], row[2], row[3], row[4]]);
}

async function openPage(pagePath) {
  const browser = await chromium.launch({
    executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
    headless: true,
    // Software WebGL (SwiftShader): no GPU on the test machines. The sandbox
    // needs user namespaces that CI containers running as root lack.
    args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--no-sandbox'],
  });
  const page = await browser.newPage({ viewport: VIEWPORT, deviceScaleFactor: 1 });
  const consoleErrors = [];
  const requests = [];
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  const url = pathToFileURL(resolve(pagePath)).href;
  await page.route('**/*', (route) => {
    const requested = route.request().url();
    if (requested === url) return route.continue();
    requests.push(requested);
    return route.abort();
  });
  const started = Date.now();
  await page.goto(url, { waitUntil: 'load', timeout: 120_000 });
  await page.waitForFunction(() => window.rigidsimReplay && window.rigidsimReplay.framesDrawn() >= 1, null, { timeout: 120_000 });
  const loadMs = Date.now() - started;
  return { browser, page, consoleErrors, requests, loadMs };
}

/// Waits until the page has drawn `frames` more frames (what is on screen
/// then shows the state set before).
async function drawn(page, frames = 2) {
  const start = await page.evaluate(() => window.rigidsimReplay.framesDrawn());
  await page.waitForFunction((n) => window.rigidsimReplay.framesDrawn() >= n, start + frames, { timeout: 60_000 });
}

async function measure() {
  const bytes = statSync(args.page).size;
  const { browser, page, consoleErrors, loadMs } = await openPage(args.page);
  // A frame's cost once loaded, over 20 frames at 20 times across the run:
  // the viewer's own work (placing every body, panels, plot), and the whole
  // frame, which in SwiftShader is mostly rasterising on the CPU.
  const timing = await page.evaluate(async () => {
    const replay = window.rigidsimReplay;
    const nextFrame = () => new Promise((done) => requestAnimationFrame(() => done()));
    await nextFrame();
    let update = 0;
    const started = performance.now();
    for (let i = 1; i <= 20; i++) {
      replay.setTime((i / 20) * replay.endTime);
      await nextFrame();
      await nextFrame();
      update += replay.updateMs();
    }
    return { update: update / 20, frame: (performance.now() - started) / 40 };
  });
  console.log(`page ${(bytes / 1e6).toFixed(2)} MB, first frame drawn ${loadMs} ms after navigation; ` +
    `then ${timing.update.toFixed(1)} ms of the viewer's work a frame, ${timing.frame.toFixed(0)} ms a frame in all ` +
    `(${VIEWPORT.width}x${VIEWPORT.height}, SwiftShader)`);
  if (args.shot) {
    const at = args.at === undefined ? 0 : Number(args.at);
    await page.evaluate((t) => window.rigidsimReplay.setTime(t), at);
    if (args.pick !== undefined) {
      await drawn(page);
      const camera = await page.evaluate(() => window.rigidsimReplay.camera());
      const p = await page.evaluate((b) => window.rigidsimReplay.bodyPosition(b), Number(args.pick));
      const [x, y] = project(camera, p);
      await page.mouse.click(x, y);
    }
    await drawn(page, 3);
    writeFileSync(args.shot, await page.screenshot());
    console.log(`screenshot at t = ${at} s: ${args.shot}`);
  }
  check(consoleErrors.length === 0, `no console errors (${consoleErrors.join(' | ')})`);
  await browser.close();
}

async function test() {
  const body = Number(args.body ?? 1);
  const summary = JSON.parse(readFileSync(join(args.run, 'summary.json'), 'utf8'));
  const rows = trajectoryOf(join(args.run, 'trajectory.csv'), body);
  const first = rows[0], last = rows[rows.length - 1];
  const { browser, page, consoleErrors, requests, loadMs } = await openPage(args.page);
  console.log(`page loaded and drew its first frame in ${loadMs} ms`);
  const shots = args.screenshots;
  if (shots) mkdirSync(shots, { recursive: true });
  const hook = (f, a) => page.evaluate(f, a);

  await hook(() => window.rigidsimReplay.setTime(0));
  await drawn(page);

  // The body where trajectory.csv puts it, through the page's own camera.
  async function bodyDrawnAt(label, row, expectColour) {
    const camera = await hook(() => window.rigidsimReplay.camera());
    const png = await page.screenshot();
    if (shots) writeFileSync(join(shots, `${label}.png`), png);
    const image = decodePng(png);
    const [x, y] = project(camera, row.slice(1));
    const seen = patchColour(image, x, y);
    const distance = chromaticityDistance(seen, expectColour);
    check(distance < SAME_COLOUR,
      `${label}: body ${body} at (${row.slice(1).map((v) => v.toFixed(3))}) is drawn at pixel (${x.toFixed(0)}, ${y.toFixed(0)}): ` +
      `rgb(${seen.map((v) => v.toFixed(0))}), chromaticity ${distance.toFixed(3)} from its colour rgb(${expectColour.map((v) => v.toFixed(0))})`);
    return { image, camera };
  }
  // The colour the page gives the body, in 0..255 sRGB (three.js keeps it linear).
  const linear = await hook((b) => window.rigidsimReplay.colourOf(b), body);
  const toSrgb = (c) => 255 * (c <= 0.0031308 ? 12.92 * c : 1.055 * c ** (1 / 2.4) - 0.055);
  const colour = linear.map(toSrgb);

  const pagePosition0 = await hook((b) => window.rigidsimReplay.bodyPosition(b), body);
  check(pagePosition0.every((v, i) => Math.abs(v - first[i + 1]) <= 1e-6 * Math.max(1, Math.abs(first[i + 1]))),
    `t = 0: the page's position of body ${body} (${pagePosition0.map((v) => v.toFixed(6))}) is trajectory.csv's`);
  await bodyDrawnAt('t0', first, colour);

  // Play it through at 4x: it must stop at the run's end.
  await page.selectOption('#speed', '4');
  await page.click('#play');
  await page.waitForFunction(() => window.rigidsimReplay.time() >= window.rigidsimReplay.endTime, null, { timeout: 120_000 });
  await drawn(page);
  const endState = await hook(() => ({
    time: window.rigidsimReplay.time(),
    sliderMax: window.rigidsimReplay.sliderMax(),
    sliderValue: window.rigidsimReplay.sliderValue(),
    clock: window.rigidsimReplay.clockText(),
    button: document.getElementById('play').textContent,
  }));
  check(endState.sliderMax === summary.sim_time_s && endState.sliderValue === summary.sim_time_s,
    `the slider ends at ${endState.sliderMax} s and stopped at ${endState.sliderValue} s: summary.json's sim_time_s ${summary.sim_time_s}`);
  check(endState.clock.startsWith(`t = ${summary.sim_time_s.toFixed(3)} s`) && endState.button === 'play',
    `playing stopped at the end: "${endState.clock}", button "${endState.button}"`);
  check(last[0] === summary.sim_time_s, `trajectory.csv's last sample is at the run's end (${last[0]} s)`);
  const pagePositionEnd = await hook((b) => window.rigidsimReplay.bodyPosition(b), body);
  check(pagePositionEnd.every((v, i) => Math.abs(v - last[i + 1]) <= 1e-6 * Math.max(1, Math.abs(last[i + 1]))),
    `end: the page's position of body ${body} (${pagePositionEnd.map((v) => v.toFixed(6))}) is trajectory.csv's`);
  const { image, camera } = await bodyDrawnAt('end', last, colour);
  const [x0, y0] = project(camera, first.slice(1));
  const [x1, y1] = project(camera, last.slice(1));
  if (Math.hypot(x1 - x0, y1 - y0) > 40) {
    const left = patchColour(image, x0, y0);
    check(chromaticityDistance(left, colour) > 2 * SAME_COLOUR,
      `end: body ${body}'s starting place (${x0.toFixed(0)}, ${y0.toFixed(0)}) no longer shows it: rgb(${left.map((v) => v.toFixed(0))})`);
  }

  await page.mouse.click(x1, y1);
  await drawn(page);
  const picked = await hook(() => window.rigidsimReplay.pickedText());
  check(picked.startsWith(`body ${body} `), `clicking body ${body} shows it: "${picked.split('\n')[0]}"`);

  check(requests.length === 0, `no request beyond the page's file (${requests.join(', ')})`);
  check(consoleErrors.length === 0, `no console errors (${consoleErrors.join(' | ')})`);
  await browser.close();
}

try {
  if (args.measure) await measure(); else await test();
} catch (e) {
  failures.push(String(e));
  console.log(`FAILED: ${e.stack || e}`);
}
if (failures.length) {
  console.log(`replay_in_chromium: ${failures.length} failed`);
  process.exit(1);
}
