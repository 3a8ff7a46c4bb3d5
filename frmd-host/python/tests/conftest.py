"""Shared fixtures of the `frmd` module's tests: a tiny reach policy (demonstrations, teacher,
student, DP, their int8 export) trained in seconds with the `frmd` binary, and the pipe client
of the serve protocol (examples/frmd_client/frmd_client/protocol.py, pure Python) to compare
with.

The binary is $FRMD_BIN or target/debug/frmd of this checkout (`cargo build -p frmd-host`).
Without one the tests that need it skip, saying so; with FRMD_REQUIRE_BIN=1 (CI) they fail."""
import os
import subprocess
import sys

import pytest

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", "..", ".."))
sys.path.insert(0, os.path.join(ROOT, "examples", "frmd_client"))
FRMD = os.environ.get("FRMD_BIN") or os.path.join(ROOT, "target", "debug", "frmd")
ENV = {**os.environ, "RAYON_NUM_THREADS": "1"}
TINY = "--batch 8 --warmup 1 --eval-episodes 0 --horizon 8 --num-basis 4 --embed-dim 4".split()


def frmd(cwd, *args):
    subprocess.run([FRMD, *args], check=True, cwd=cwd, env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)


@pytest.fixture(scope="session")
def frmd_bin():
    if not os.path.exists(FRMD):
        if os.environ.get("FRMD_REQUIRE_BIN") == "1":
            pytest.fail(f"no frmd binary at {FRMD} and FRMD_REQUIRE_BIN=1")
        pytest.skip(f"no frmd binary at {FRMD} (cargo build -p frmd-host)")
    return FRMD


@pytest.fixture(scope="session")
def models(frmd_bin, tmp_path_factory):
    """A directory with `d.safetensors`, checkpoints `t`, `s`, `dp`, the export `baked/` and the
    blob `s.blob` (dt known through baked/export.json; the bare blob announces 0)."""
    d = str(tmp_path_factory.mktemp("models"))
    frmd(d, *"collect --task reach --episodes 3 --out d.safetensors".split())
    frmd(d, *"train teacher --data d.safetensors --out t --steps 5 --backbone mlp:16".split(), *TINY)
    frmd(d, *"train student --data d.safetensors --out s --teacher t --steps 5 --batch 8 --warmup 1 "
         "--eval-episodes 0".split())
    frmd(d, *"train dp --data d.safetensors --out dp --steps 5 --backbone mlp:8".split(), *TINY)
    frmd(d, *"export --ckpt s --out baked --blob s.blob".split())
    return d
