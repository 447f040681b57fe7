#!/usr/bin/env node
// Validate glTF 2.0 files (.glb or .gltf) with the Khronos glTF Validator and print the
// JSON report(s) on stdout.
//
// Usage: node tools/gltf_validate.mjs FILE [FILE ...]
//
// The npm package `gltf-validator` is looked up in $GLTF_VALIDATOR_DIR, then in
// <repo>/.tools/node_modules (where `make tools` installs it), then on the normal Node path.
// Exit codes: 0 = no errors, 1 = at least one file has validation errors,
//             2 = usage error, unreadable file, or the validator package is missing.
// One file prints one report object; several files print a JSON array of reports.
import { readFile } from "node:fs/promises";
import { createRequire } from "node:module";
import path from "node:path";
import { fileURLToPath } from "node:url";

const here = path.dirname(fileURLToPath(import.meta.url));
const candidates = [
  process.env.GLTF_VALIDATOR_DIR,
  path.join(here, "..", ".tools", "node_modules", "gltf-validator"),
  "gltf-validator",
].filter(Boolean);

function loadValidator() {
  const require = createRequire(import.meta.url);
  for (const c of candidates) {
    try {
      return require(c);
    } catch {
      // try the next location
    }
  }
  return null;
}

async function main(argv) {
  const files = argv.slice(2);
  if (files.length === 0) {
    console.error("usage: node tools/gltf_validate.mjs FILE.glb [FILE ...]");
    return 2;
  }
  const validator = loadValidator();
  if (validator === null) {
    console.error("gltf-validator npm package not found (looked in: " + candidates.join(", ") +
      "); install it with: npm install --prefix .tools gltf-validator@2.0.0-dev.3.10");
    return 2;
  }
  const reports = [];
  let failed = false;
  for (const file of files) {
    let data;
    try {
      data = await readFile(file);
    } catch (err) {
      console.error(`${file}: cannot read: ${err.message}`);
      return 2;
    }
    const ext = path.extname(file).toLowerCase();
    const options = {
      uri: path.basename(file),
      maxIssues: 0,
      writeTimestamp: false,
      externalResourceFunction: (uri) =>
        readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)))
          .then((buf) => new Uint8Array(buf)),
    };
    if (ext === ".glb") options.format = "glb";
    if (ext === ".gltf") options.format = "gltf";
    let report;
    try {
      report = await validator.validateBytes(new Uint8Array(data), options);
    } catch (err) {
      // the validator rejects only input it cannot recognise as glTF or GLB at all
      report = {
        uri: path.basename(file),
        issues: {
          numErrors: 1, numWarnings: 0, numInfos: 0, numHints: 0,
          messages: [{ code: "UNRECOGNISED_INPUT", message: String(err), severity: 0 }],
          truncated: false,
        },
      };
    }
    if (report.issues.numErrors > 0) failed = true;
    reports.push(report);
  }
  const out = reports.length === 1 ? reports[0] : reports;
  process.stdout.write(JSON.stringify(out, null, 2) + "\n");
  return failed ? 1 : 0;
}

process.exitCode = await main(process.argv);
