#!/usr/bin/env node
// Validates one .glb/.gltf file with the Khronos glTF validator (npm package gltf-validator,
// installed into tools/node_modules by scripts/install_deps.sh).
//
// Usage: node tools/validate_gltf.js FILE
// Prints a JSON summary (counts and every message) on stdout. Exit status: 0 when the report
// has no errors and no warnings (infos and hints are allowed), 1 when it has any, 2 when the
// validator is not installed or the file cannot be read. The tests treat anything but 0 as a
// failure, so a missing validator fails them instead of silently skipping.
'use strict';

const fs = require('fs');
const path = require('path');

function fail(message) {
  console.error('validate_gltf: ' + message);
  process.exit(2);
}

let validator;
try {
  // Resolve next to this script so the check does not depend on the caller's working directory.
  validator = require(path.join(__dirname, 'node_modules', 'gltf-validator'));
} catch (e) {
  fail('the npm package gltf-validator is not installed in ' + path.join(__dirname, 'node_modules') +
       '; run scripts/install_deps.sh (' + e.message.split('\n')[0] + ')');
}

if (process.argv.length !== 3) fail('usage: node validate_gltf.js FILE.glb|FILE.gltf');
const file = path.resolve(process.argv[2]);
let bytes;
try {
  bytes = fs.readFileSync(file);
} catch (e) {
  fail(file + ': ' + e.message);
}

validator.validateBytes(new Uint8Array(bytes), {
  uri: path.basename(file),
  maxIssues: 0,  // 0 = unlimited: a failing test should show every message
  // Only needed for .gltf files that reference buffers by relative URI (ours embed them).
  externalResourceFunction: (uri) => new Promise((resolve, reject) => {
    const resolved = path.resolve(path.dirname(file), decodeURIComponent(uri));
    fs.readFile(resolved, (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
  }),
}).then((report) => {
  const issues = report.issues;
  const summary = {
    file: file,
    numErrors: issues.numErrors,
    numWarnings: issues.numWarnings,
    numInfos: issues.numInfos,
    numHints: issues.numHints,
    messages: issues.messages.map((m) => ({
      code: m.code, severity: ['error', 'warning', 'info', 'hint'][m.severity] || m.severity,
      pointer: m.pointer, message: m.message,
    })),
    extensionsUsed: (report.info && report.info.extensionsUsed) || [],
  };
  console.log(JSON.stringify(summary, null, 2));
  process.exit(issues.numErrors === 0 && issues.numWarnings === 0 ? 0 : 1);
}).catch((e) => fail(file + ': validator failed: ' + e));
