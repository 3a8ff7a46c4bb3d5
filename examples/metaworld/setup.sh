#!/usr/bin/env bash
# Creates examples/metaworld/.venv with the pinned packages of requirements.txt.
# Usage (from anywhere): bash examples/metaworld/setup.sh   [PYTHON=python3.11]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-python3}"
"$python" - <<'PY'
import sys
if not (3, 11) <= sys.version_info[:2] < (3, 14):
    sys.exit(f"Python 3.11-3.13 is needed (numpy 2.4 needs >= 3.11, metaworld 3.1.1 < 3.14), found {sys.version.split()[0]}")
PY
if [ ! -x "$here/.venv/bin/python" ]; then
    "$python" -m venv "$here/.venv"
fi
"$here/.venv/bin/python" -m pip install --quiet --upgrade pip
"$here/.venv/bin/python" -m pip install --quiet -r "$here/requirements.txt"
# The shared client package (examples/frmd_client) is imported from the repository, as an
# editable install would: a .pth file in the venv's site-packages names its directory.
"$here/.venv/bin/python" - "$here/../frmd_client" <<'PY'
import os, sys, sysconfig
shared = os.path.realpath(sys.argv[1])
if not os.path.isfile(os.path.join(shared, "frmd_client", "__init__.py")):
    sys.exit(f"setup.sh: the shared package is missing: {shared}/frmd_client")
with open(os.path.join(sysconfig.get_paths()["purelib"], "frmd_client.pth"), "w") as f:
    f.write(shared + "\n")
PY
# Headless: MuJoCo needs no GL for state observations.
"$here/.venv/bin/python" -c "import metaworld, mujoco, frmd_client; from importlib.metadata import version; print('metaworld', version('metaworld'), 'mujoco', mujoco.__version__)"
echo "venv ready: $here/.venv (activate with: source $here/.venv/bin/activate)"
