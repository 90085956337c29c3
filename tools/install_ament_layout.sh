#!/usr/bin/env bash
# Give the venv the layout `ros2 run` expects of an installed ament_python package:
# the package in the ament index and each node executable under lib/hiros/.
set -euo pipefail
venv=$(cd "$1" && pwd)
mkdir -p "$venv/share/ament_index/resource_index/packages" "$venv/lib/hiros" "$venv/share/hiros"
touch "$venv/share/ament_index/resource_index/packages/hiros"
cp package.xml "$venv/share/hiros/package.xml"
for exe in $("$venv/bin/python" - <<'PY'
import ast, pathlib
tree = ast.parse(pathlib.Path("setup.py").read_text())
for node in ast.walk(tree):
    if isinstance(node, ast.Assign) and getattr(node.targets[0], "id", "") == "NODES":
        print(" ".join(ast.literal_eval(node.value)))
PY
); do
  ln -sf "$venv/bin/$exe" "$venv/lib/hiros/$exe"
done
