// Usage: node validate.mjs FILE.glb|FILE.gltf ...
// Prints one line per file (errors, warnings) and each error or warning; exits 1 if any
// file has an error.
import { validateBytes } from 'gltf-validator';
import { readFileSync } from 'node:fs';

let failed = 0;
for (const file of process.argv.slice(2)) {
  const report = await validateBytes(new Uint8Array(readFileSync(file)));
  const { numErrors, numWarnings } = report.issues;
  console.log(`${file}: ${numErrors} errors, ${numWarnings} warnings`);
  for (const m of report.issues.messages) {
    if (m.severity <= 1) console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code}: ${m.message} ${m.pointer ?? ''}`);
  }
  if (numErrors > 0) failed += 1;
}
process.exit(failed > 0 ? 1 : 0);
