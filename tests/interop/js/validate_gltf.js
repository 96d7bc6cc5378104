// Runs the Khronos glTF validator (npm `gltf-validator`) on one file and prints its report's
// issues as JSON. Used by test_glb.py; NODE_PATH must point at the folder holding node_modules.
const fs = require("fs");
const validator = require("gltf-validator");

const bytes = new Uint8Array(fs.readFileSync(process.argv[2]));
validator
  .validateBytes(bytes, { maxIssues: 0 })
  .then((report) => console.log(JSON.stringify(report.issues)))
  .catch((error) => {
    console.error(String(error));
    process.exit(2);
  });
