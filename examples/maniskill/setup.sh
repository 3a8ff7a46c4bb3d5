#!/usr/bin/env bash
# Everything examples/maniskill needs on a fresh Debian 12 machine: the system packages of
# setup-system.sh (Mesa 25's lavapipe from bookworm-backports and the Vulkan loader; needs root
# unless they are there already), then .venv with the exact pins of requirements.txt and the
# shared package examples/frmd_client on its path, then a smoke test that builds a ManiSkill
# scene on the CPU. About 4-5 minutes and 6.5 GB (torch's CUDA libraries) the first time.
# Usage (from anywhere): bash examples/maniskill/setup.sh   [PYTHON=python3.11]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-python3}"
start=$(date +%s)
bash "$here/setup-system.sh"
"$python" - <<'PY'
import sys
if sys.version_info[:2] != (3, 11):
    sys.exit(f"Python 3.11 is needed (the pinned wheels of requirements.txt, e.g. mplib 0.1.1 and sapien 3.0.3, "
             f"are cp311), found {sys.version.split()[0]}; give another with PYTHON=python3.11")
PY
if ! "$python" -m venv --help >/dev/null 2>&1; then
    echo "setup.sh: $python has no venv module; on Debian: apt-get install python3-venv" >&2
    exit 1
fi
if [ ! -x "$here/.venv/bin/python" ]; then
    "$python" -m venv "$here/.venv"
fi
"$here/.venv/bin/python" -m pip install --quiet --upgrade pip
# --no-deps: requirements.txt is the complete set (nothing else is resolved or fetched).
"$here/.venv/bin/python" -m pip install --quiet --no-deps -r "$here/requirements.txt"
# The shared client package, imported from the repository as an editable install would be.
"$here/.venv/bin/python" - "$here/../frmd_client" <<'PY'
import os, sys, sysconfig
shared = os.path.realpath(sys.argv[1])
if not os.path.isfile(os.path.join(shared, "frmd_client", "__init__.py")):
    sys.exit(f"setup.sh: the shared package is missing: {shared}/frmd_client")
with open(os.path.join(sysconfig.get_paths()["purelib"], "frmd_client.pth"), "w") as f:
    f.write(shared + "\n")
PY
# Smoke test: a PickCube scene on the CPU (SAPIEN needs the Vulkan device even without rendering).
(cd "$here" && .venv/bin/python -m frmd_maniskill check)
echo "venv ready: $here/.venv ($(( $(date +%s) - start )) s)"
