// Bundles src/main.js with three.js and its orbit controls into one script,
// dist/viewer.js, which `rigidsim view` inlines into every replay page
// (src/view/page.rs compiles it into the binary). Run `npm ci && npm run build`
// here after changing src/main.js or the three.js version, and commit the
// result: the Rust build then needs no npm.
import { build } from 'esbuild';
import { readFileSync, writeFileSync, copyFileSync } from 'node:fs';

const out = 'dist/viewer.js';
await build({
  entryPoints: ['src/main.js'],
  bundle: true,
  format: 'iife',
  minify: true,
  target: 'es2020',
  legalComments: 'none', // three.js's licence travels as dist/THREE_LICENSE and a header line
  outfile: out,
});
const three = JSON.parse(readFileSync('node_modules/three/package.json', 'utf8'));
const bundle = readFileSync(out, 'utf8');
// The page inlines the bundle in a <script> element, which would end at the
// first `</script` and reads `<!--` specially: refuse a bundle with either.
const lower = bundle.toLowerCase();
if (lower.includes('</script') || lower.includes('<!--')) {
  throw new Error(`${out} contains </script or <!--, which cannot be inlined in a <script> element`);
}
writeFileSync(out, `/* rigidsim viewer; includes three.js ${three.version} (MIT, see THREE_LICENSE) */\n${bundle}`);
copyFileSync('node_modules/three/LICENSE', 'dist/THREE_LICENSE');
console.log(`${out}: ${(bundle.length / 1024).toFixed(0)} KiB, three.js ${three.version}`);
