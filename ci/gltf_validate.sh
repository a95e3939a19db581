#!/usr/bin/env bash
# Validates glTF files (.glb, or .gltf with its .bin) with the Khronos glTF validator, the npm
# package gltf-validator, installed on first use into target/gltf-validator (or
# $GLTF_VALIDATOR_DIR). Prints each file's error/warning/info counts and its errors and
# warnings; exits 1 when any file has an error. ci/test runs tests/mesh/gltf.rs with it where it installs;
# tests/mesh/gltf.rs calls it when FOLDFREE_GLTF_VALIDATOR=1. With no file: installs it, validates nothing.
#   bash ci/gltf_validate.sh out.glb other.gltf
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
dir=${GLTF_VALIDATOR_DIR:-$root/target/gltf-validator}
if [ ! -f "$dir/node_modules/gltf-validator/package.json" ]; then
  mkdir -p "$dir"
  npm install --silent --no-audit --no-fund --prefix "$dir" gltf-validator@2.0.0-dev.3.10 >&2
fi
node - "$dir" "$@" <<'JS'
const fs = require('fs');
const path = require('path');
const [dir, ...files] = process.argv.slice(2);
const validator = require(path.join(dir, 'node_modules', 'gltf-validator'));
(async () => {
  let failed = false;
  for (const file of files) {
    const report = await validator.validateBytes(new Uint8Array(fs.readFileSync(file)), {
      uri: path.basename(file),
      externalResourceFunction: (uri) => new Promise((resolve, reject) => {
        fs.readFile(path.resolve(path.dirname(file), decodeURIComponent(uri)),
          (err, data) => (err ? reject(err.toString()) : resolve(new Uint8Array(data))));
      }),
    });
    const i = report.issues;
    console.log(`${file}: ${i.numErrors} errors, ${i.numWarnings} warnings, ${i.numInfos} infos`);
    for (const m of i.messages.filter((m) => m.severity <= 1)) {
      console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code} ${m.pointer || ''}: ${m.message}`);
    }
    if (i.numErrors > 0) failed = true;
  }
  process.exit(failed ? 1 : 0);
})().catch((e) => { console.error(e); process.exit(1); });
JS
