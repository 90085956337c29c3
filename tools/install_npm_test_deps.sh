#!/usr/bin/env bash
# Foxglove's npm libraries for test/conformance (pinned in its package.json), installed into
# test/.npm before the tests enter their network namespace, which holds only loopback: the
# npm registry cannot be reached from inside. Without npm this does nothing and the
# conformance test skips itself with the reason.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v npm >/dev/null 2>&1 || ! command -v node >/dev/null 2>&1; then
    echo "node/npm not found: the Foxglove conformance test will be skipped"
    exit 0
fi
mkdir -p test/.npm
if [ -d test/.npm/node_modules ] && cmp -s test/conformance/package.json test/.npm/package.json; then
    exit 0
fi
cp test/conformance/package.json test/.npm/package.json
(cd test/.npm && npm install --no-audit --no-fund --no-package-lock --loglevel=error)
echo "installed Foxglove's npm libraries into test/.npm"
