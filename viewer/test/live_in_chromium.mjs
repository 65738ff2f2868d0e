// Opens the live page of a running `rigidsim live` in headless Chromium
// (software WebGL through SwiftShader) and drives it as a person would:
//   - the page connects, gets the scene and states, and draws;
//   - a mouse press on the body where the page's camera projects it grabs
//     it, and moving the mouse up drags it: the states show it rising;
//   - releasing lets it go; the stop button ends the live run;
//   - nothing is logged as an error, and no message was refused.
//
//   node viewer/test/live_in_chromium.mjs --url http://127.0.0.1:PORT/ --body 1

import { chromium } from 'playwright-core';

const args = parseArgs(process.argv.slice(2));
const VIEWPORT = { width: 1000, height: 640 };
const body = Number(args.body ?? 1);

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

/// Where the page's camera draws world point p, in CSS pixels.
function project(camera, p) {
  const m = camera.viewProjection;
  const x = m[0] * p[0] + m[4] * p[1] + m[8] * p[2] + m[12];
  const y = m[1] * p[0] + m[5] * p[1] + m[9] * p[2] + m[13];
  const w = m[3] * p[0] + m[7] * p[1] + m[11] * p[2] + m[15];
  return [camera.left + ((x / w + 1) / 2) * camera.width, camera.top + ((1 - y / w) / 2) * camera.height];
}

const browser = await chromium.launch({
  executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
  headless: true,
  // Software WebGL (SwiftShader): no GPU on the test machines. The sandbox
  // needs user namespaces that CI containers running as root lack.
  args: ['--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist', '--no-sandbox'],
});
try {
  const page = await browser.newPage({ viewport: VIEWPORT, deviceScaleFactor: 1 });
  const consoleErrors = [];
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  await page.goto(args.url, { waitUntil: 'load', timeout: 120_000 });
  await page.waitForFunction(() => window.rigidsimLive && window.rigidsimLive.ready() && window.rigidsimLive.framesDrawn() > 2,
    null, { timeout: 120_000 });
  check(true, 'the page connected, got the scene and states, and drew');

  // Let the body come to rest first (render_check's cube lands at 0.29 s).
  await page.waitForFunction(() => window.rigidsimLive.time() > 1.0, null, { timeout: 60_000 });
  const live = (f, a) => page.evaluate(f, a);
  const start = await live((b) => window.rigidsimLive.bodyPosition(b), body);
  const camera = await live(() => window.rigidsimLive.camera());
  const [x, y] = project(camera, start);
  await page.mouse.move(x, y);
  await page.mouse.down();
  const held = await live(() => window.rigidsimLive.held());
  check(held === body, `a press on body ${body} grabs it (held: ${held})`);
  // Up the screen, in steps, as a hand moves.
  for (let i = 1; i <= 20; i++) {
    await page.mouse.move(x, y - 15 * i);
    await page.waitForTimeout(40);
  }
  await page.waitForTimeout(1500);
  const raised = await live((b) => window.rigidsimLive.bodyPosition(b), body);
  check(raised[2] > start[2] + 0.04,
    `dragged up the screen, body ${body} rose from z = ${start[2].toFixed(3)} to ${raised[2].toFixed(3)} m`);
  await page.mouse.up();
  check(await live(() => window.rigidsimLive.held()) === -1, 'releasing the mouse lets the body go');

  await page.click('#stop');
  await page.waitForFunction(() => window.rigidsimLive.ended() !== null, null, { timeout: 30_000 });
  const ended = await live(() => window.rigidsimLive.ended());
  check(ended === 'stopped', `the stop button ends the live run (ended by ${ended})`);
  const refused = await live(() => window.rigidsimLive.errors());
  check(refused.length === 0, `no message refused (${refused.join(' | ')})`);
  check(consoleErrors.length === 0, `no console errors (${consoleErrors.join(' | ')})`);
} finally {
  await browser.close();
}
if (failures.length) {
  console.error(`${failures.length} check(s) failed`);
  process.exit(1);
}
