#!/usr/bin/env node
// Validates glTF 2.0 binaries with the Khronos glTF validator.
//   node validate.js FILE.glb...
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "messages"}, where
// messages lists every error and warning as "CODE at POINTER: message". Exit status: 0 when
// no file has an error, 1 when one has, 2 when a file cannot be read.
'use strict';

const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

async function validate(file) {
  const bytes = new Uint8Array(fs.readFileSync(file));
  const report = await validator.validateBytes(bytes, {
    uri: path.basename(file),
    maxIssues: 0,  // report every issue
    // An exported .glb is self-contained: any external reference is a failure to load.
    externalResourceFunction: (uri) => Promise.reject(new Error(`unexpected external resource ${uri}`)),
  });
  const issues = report.issues;
  const messages = issues.messages
    .filter((m) => m.severity <= 1)
    .map((m) => `${m.severity === 0 ? 'error' : 'warning'} ${m.code} at ${m.pointer || '/'}: ${m.message}`);
  return {
    file,
    errors: issues.numErrors,
    warnings: issues.numWarnings,
    infos: issues.numInfos,
    messages,
  };
}

async function main() {
  const files = process.argv.slice(2);
  if (files.length === 0) {
    process.stderr.write('usage: validate.js FILE.glb...\n');
    process.exit(2);
  }
  let failed = false;
  for (const file of files) {
    let result;
    try {
      result = await validate(file);
    } catch (error) {
      process.stderr.write(`${file}: ${error.message}\n`);
      process.exit(2);
    }
    process.stdout.write(JSON.stringify(result) + '\n');
    if (result.errors > 0) failed = true;
  }
  process.exit(failed ? 1 : 0);
}

main();
