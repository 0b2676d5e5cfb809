#!/bin/sh
# Rebuilds three.min.js, the three.js bundle inlined into every viewer page: three.js, its
# OrbitControls and its GLTFLoader from npm, bundled by esbuild into one minified IIFE that
# defines the global `THREE` (a classic script, since pages opened from file:// cannot import modules). Needs node
# and npm; works in a scratch folder and writes only three.min.js and three.LICENSE here.
set -eu
THREE_VERSION=0.187.0
ESBUILD_VERSION=0.28.2
here=$(cd "$(dirname "$0")" && pwd)
scratch=$(mktemp -d)
trap 'rm -rf "$scratch"' EXIT
cd "$scratch"
npm init -y >/dev/null
npm install --no-audit --no-fund --silent "three@$THREE_VERSION" "esbuild@$ESBUILD_VERSION"
cp "$here/three-entry.js" .
./node_modules/.bin/esbuild three-entry.js --bundle --format=iife --minify --global-name=THREE \
  --log-level=warning --outfile="$here/three.min.js"
cp node_modules/three/LICENSE "$here/three.LICENSE"
echo "three.min.js: three@$THREE_VERSION, esbuild@$ESBUILD_VERSION, $(wc -c <"$here/three.min.js") bytes"
