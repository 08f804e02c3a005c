// Validates glTF files (.glb, or .gltf with its buffer beside it) with the Khronos glTF
// validator (npm `gltf-validator`) and prints, for
// each file given, one JSON line: its path, the counts of errors, warnings, infos and hints,
// and the first messages. Used by tests/mesh_real.rs; exits 2 when the validator cannot run.
import fs from 'fs';
import nodePath from 'path';
import validator from 'gltf-validator';

for (const path of process.argv.slice(2)) {
  const bytes = new Uint8Array(fs.readFileSync(path));
  // A .gltf names its buffer by a URI relative to itself: the validator loads it from there.
  const report = await validator.validateBytes(bytes, {
    maxIssues: 20,
    uri: path,
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      fs.readFile(nodePath.resolve(nodePath.dirname(path), decodeURIComponent(uri)), (err, data) => {
        if (err) reject(err); else resolve(new Uint8Array(data));
      });
    }),
  });
  console.log(JSON.stringify({
    path,
    errors: report.issues.numErrors,
    warnings: report.issues.numWarnings,
    infos: report.issues.numInfos,
    hints: report.issues.numHints,
    messages: report.issues.messages.map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`),
    triangles: report.info.totalTriangleCount,
    drawCalls: report.info.drawCallCount,
  }));
}
