// Decodes a model file with the splat viewer's own reader (splat-viewer/assets/js/formats.js, a
// browser script evaluated here as it is) and prints what it found as JSON. Used by
// test_render_mode.py: node FORMATS_JS MODEL_FILE.
import fs from "node:fs";

const [formats, model] = process.argv.slice(2);
const decodeModel = new Function(`${fs.readFileSync(formats, "utf8")}\nreturn decodeModel;`)();
const m = await decodeModel(new Uint8Array(fs.readFileSync(model)));
console.log(JSON.stringify({ count: m.count, shDegree: m.shDegree, antialiased: m.antialiased }));
