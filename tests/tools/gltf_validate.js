// Runs the Khronos glTF-Validator (npm `gltf-validator`) on each file named on the command
// line and prints its report; exits non-zero when any file has an error.
// Usage: node gltf_validate.js PATH/TO/node_modules/gltf-validator FILE.gltf...
const validator = require(process.argv[2]);
const fs = require('fs');
const path = require('path');
(async () => {
  let bad = 0;
  for (const f of process.argv.slice(3)) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(f)), {
      uri: path.basename(f),
    });
    const i = report.issues;
    console.log(`${f}: errors ${i.numErrors}, warnings ${i.numWarnings}, infos ${i.numInfos}, hints ${i.numHints}`);
    for (const m of i.messages) console.log(`  ${m.severity} ${m.code} ${m.pointer || ''} ${m.message}`);
    if (i.numErrors > 0) bad++;
  }
  process.exit(bad ? 1 : 0);
})().catch((e) => { console.error(e); process.exit(2); });
