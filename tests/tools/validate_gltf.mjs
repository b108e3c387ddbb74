// Validates a .glb with the Khronos glTF validator and prints its report as JSON
// (tests/export_animation.rs reads `issues.numErrors`).
import { readFile } from "node:fs/promises";
import validator from "gltf-validator";

const path = process.argv[2];
const bytes = new Uint8Array(await readFile(path));
const report = await validator.validateBytes(bytes, { maxIssues: 100 });
console.log(JSON.stringify(report));
