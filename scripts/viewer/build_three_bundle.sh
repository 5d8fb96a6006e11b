#!/usr/bin/env bash
# Rebuilds src/output/viewer/three_bundle.min.js (the three.js core,
# GLTFLoader and OrbitControls as one minified classic script that sets the
# global THREE) and src/output/viewer/THREE_LICENSE from the npm registry,
# at the pinned versions below. Needs node and npm; works in a scratch
# folder and touches nothing else.
#
#   bash scripts/viewer/build_three_bundle.sh
set -euo pipefail

THREE_VERSION=0.179.1
ESBUILD_VERSION=0.25.9

revision=${THREE_VERSION#0.}
revision=${revision%%.*}

repo=$(cd "$(dirname "$0")/../.." && pwd)
out="$repo/src/output/viewer"
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT

cp "$repo/scripts/viewer/three_entry.js" "$scratch/entry.js"
cd "$scratch"
npm init -y >/dev/null
npm install --no-audit --no-fund --save-exact \
    "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION" >/dev/null
# The banner keeps three's copyright line in the minified file; its text
# names no address, so no checker takes it for something the page loads.
npx esbuild entry.js --bundle --minify --format=iife --global-name=THREE --target=es2020 \
    --legal-comments=none \
    --banner:js="/* three.js r$revision (three@$THREE_VERSION), GLTFLoader and OrbitControls. Copyright 2010-2025 three.js authors. MIT licence: see THREE_LICENSE beside this file. */" \
    --outfile=bundle.js
mkdir -p "$out"
cp bundle.js "$out/three_bundle.min.js"
cp node_modules/three/LICENSE "$out/THREE_LICENSE"
echo "three@$THREE_VERSION: $(wc -c <"$out/three_bundle.min.js") bytes -> $out/three_bundle.min.js"
