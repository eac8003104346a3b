// Validate glTF/GLB files with the Khronos validator; prints one JSON report per file.
// Usage: node validate.js FILE...
const fs = require('fs');
const path = require('path');
const validator = require('gltf-validator');

async function validate(file) {
  const data = new Uint8Array(fs.readFileSync(file));
  const dir = path.dirname(file);
  const report = await validator.validateBytes(data, {
    uri: path.basename(file),
    maxIssues: 200,
    externalResourceFunction: (uri) => new Promise((resolve, reject) => {
      try {
        resolve(new Uint8Array(fs.readFileSync(path.resolve(dir, decodeURIComponent(uri)))));
      } catch (e) { reject(e.toString()); }
    }),
  });
  return report;
}

(async () => {
  const out = [];
  for (const f of process.argv.slice(2)) {
    const r = await validate(f);
    out.push({file: f, numErrors: r.issues.numErrors, numWarnings: r.issues.numWarnings,
              messages: r.issues.messages.filter(m => m.severity === 0).slice(0, 20)});
  }
  process.stdout.write(JSON.stringify(out));
})().catch((e) => { console.error(String(e)); process.exit(1); });
