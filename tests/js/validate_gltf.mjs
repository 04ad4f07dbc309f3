// Runs the Khronos glTF-Validator (npm gltf-validator) on each file named on the command line and
// prints one JSON line per file: its path, its issue counts and the messages of its errors and
// warnings. Exit status 0 when every file has zero errors, 1 otherwise, 2 when the validator
// cannot run. The C++ tests (tests/io/gltf_writer_test.cpp) run it; `npm ci` in this directory
// installs it (scripts/install-deps.sh does).
import { readFile } from 'node:fs/promises';
import { createRequire } from 'node:module';

const require = createRequire(import.meta.url);
let validator;
try {
  validator = require('gltf-validator');
} catch (e) {
  console.error(`validate_gltf: cannot load gltf-validator (run npm ci in tests/js): ${e.message}`);
  process.exit(2);
}

let failed = false;
for (const path of process.argv.slice(2)) {
  const bytes = new Uint8Array(await readFile(path));
  const report = await validator.validateBytes(bytes, {
    uri: path,
    maxIssues: 0,
    externalResourceFunction: () => Promise.reject(new Error('external resources are not expected')),
  });
  const issues = report.issues;
  const messages = issues.messages
    .filter((m) => m.severity <= 1)
    .slice(0, 20)
    .map((m) => `${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer ?? ''}: ${m.message}`);
  console.log(JSON.stringify({
    path,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    validator: report.validatorVersion,
    messages,
  }));
  if (issues.numErrors > 0) failed = true;
}
process.exit(failed ? 1 : 0);
