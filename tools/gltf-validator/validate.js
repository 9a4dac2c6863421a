// Validate glTF/GLB files with the Khronos glTF validator; print its report as JSON.
// usage: node validate.js FILE...   exit 0: no errors; 1: errors; 2: bad usage or unreadable.
'use strict';
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

async function main(files) {
  if (files.length === 0) {
    console.error('usage: node validate.js FILE.glb...');
    return 2;
  }
  let status = 0;
  const reports = [];
  for (const file of files) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)),
                                                 { uri: path.basename(file), maxIssues: 100 });
    reports.push(report);
    if (report.issues.numErrors > 0) status = 1;
  }
  console.log(JSON.stringify(reports.length === 1 ? reports[0] : reports, null, 1));
  return status;
}

main(process.argv.slice(2)).then((code) => process.exit(code),
                                 (err) => { console.error(String(err)); process.exit(2); });
