"""`frmd import lerobot` on LeRobot datasets written by pyarrow at test time (both layouts): the
demonstrations come back exactly, and a broken dataset is refused with its named error."""
import os
import subprocess

import numpy as np
import pytest

from conftest import ENV

if os.environ.get("FRMD_REQUIRE_BIN") == "1":
    import pyarrow  # noqa: F401  (CI installs it: fail, not skip)
else:
    pytest.importorskip("pyarrow")
import lerobot_writer  # noqa: E402  (needs pyarrow)


def run_import(frmd_bin, src, out):
    return subprocess.run([frmd_bin, "import", "lerobot", str(src), "--out", str(out), "--task", "reach"],
                          env=ENV, capture_output=True, text=True)


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_pyarrow_datasets_import_exactly(models, frmd_bin, tmp_path, version):
    demos = os.path.join(models, "d.safetensors")
    lerobot_writer.write_demos(demos, str(tmp_path / "ds"), version)
    done = run_import(frmd_bin, tmp_path / "ds", tmp_path / "out.safetensors")
    assert done.returncode == 0, done.stderr
    assert f"LeRobot {version}" in done.stdout and "observation.images.front (video)" in done.stdout
    (src, _), (got, meta) = (lerobot_writer.read_safetensors(demos),
                             lerobot_writer.read_safetensors(tmp_path / "out.safetensors"))
    for key in ("obs", "action", "episode_ends"):
        assert np.array_equal(src[key], got[key]), key
    assert (meta["task"], meta["lerobot_version"], meta["episodes"]) == ("reach", version, "3")


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_broken_pyarrow_datasets_are_refused(models, frmd_bin, tmp_path, version):
    src, _ = lerobot_writer.read_safetensors(os.path.join(models, "d.safetensors"))
    cases = {"non-finite": ("non-finite value NaN in `action` of episode 1, frame 2", 10.0),
             "fps": ("fps 25 disagrees with the timestamps", 25.0)}
    for name, (text, fps) in cases.items():
        action = src["action"].copy()
        if name == "non-finite":
            action[int(src["episode_ends"][0]) + 2, 1] = np.nan
        out = tmp_path / name
        lerobot_writer.write(src["obs"], action, src["episode_ends"], 10.0, str(out), version)
        if name == "fps":  # recorded at 10 frames per second, announced as 25
            info = (out / "meta" / "info.json").read_text().replace('"fps": 10.0', '"fps": 25.0')
            (out / "meta" / "info.json").write_text(info)
        done = run_import(frmd_bin, out, tmp_path / f"{name}.safetensors")
        assert done.returncode == 2 and text in done.stderr, (name, done.stderr)
        assert str(out) in done.stderr and not (tmp_path / f"{name}.safetensors").exists()
