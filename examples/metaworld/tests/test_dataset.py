"""Datasets written by collect are what frmd-host's reader expects (tensor names, dtypes, shapes,
metadata) and record the seeds and package versions."""
import json
import struct

import numpy as np
import pytest

from frmd_metaworld.collect import collect
from frmd_client.dataset import Dataset
from frmd_metaworld.tasks import EVAL_SEED_OFFSET, SeededEnv


@pytest.fixture(scope="module")
def reach(tmp_path_factory):
    data, stats = collect("reach-v3", episodes=2, seed=10)
    path = tmp_path_factory.mktemp("d") / "reach-v3.safetensors"
    data.save(path)
    return data, stats, path


def test_written_file_is_what_frmd_reads(reach):
    data, stats, path = reach
    raw = path.read_bytes()
    header_len = struct.unpack("<Q", raw[:8])[0]
    header = json.loads(raw[8:8 + header_len])
    steps = stats["steps"]
    assert header["obs"]["dtype"] == "F32" and header["obs"]["shape"] == [steps, 39]
    assert header["action"]["dtype"] == "F32" and header["action"]["shape"] == [steps, 4]
    assert header["episode_ends"]["dtype"] == "I64" and header["episode_ends"]["shape"] == [2]
    meta = header["__metadata__"]
    assert meta["task"] == "metaworld/reach-v3" and float(meta["dt"]) == 0.0125 and "expert" in meta["source"]
    assert json.loads(meta["episode_seeds"]) == [10, 11] and json.loads(meta["failed_seeds"]) == []
    # Displacement actions: before an episode the arm rests (the zero action), as `frmd serve` resets.
    assert meta["action_before_start"] == "zero"
    versions = json.loads(meta["versions"])
    assert versions["metaworld"] == "3.1.1" and versions["mujoco"].startswith("3.3.")
    loaded = Dataset.load(path)
    assert np.array_equal(loaded.obs, data.obs) and np.array_equal(loaded.action, data.action)
    assert loaded.episode_ends.tolist()[-1] == steps


def test_rows_are_the_expert_episodes(reach):
    data, _, _ = reach
    first = data.episodes()[0]
    env = SeededEnv("reach-v3")
    obs0 = env.reset(10)
    assert np.array_equal(data.obs[first.start], obs0.astype(np.float32))
    assert np.abs(data.action).max() <= 1.0
    # The last recorded step of each episode is the one that reached success: replaying the
    # recorded actions from the seed reaches it at exactly that step.
    for seed, episode in zip([10, 11], data.episodes()):
        env.reset(seed)
        flags = [env.step(a)[1] for a in data.action[episode]]
        assert flags[-1] and not any(flags[:-1])


def test_validation_names_the_problem():
    ok = Dataset(np.zeros((4, 2), np.float32), np.zeros((4, 1), np.float32), np.array([2, 4]), "t", 0.1, "s")
    ok.validate()
    for change, text in [
        (dict(episode_ends=np.array([3, 3, 4])), "not strictly increasing"),
        (dict(episode_ends=np.array([2, 5])), "last episode end is 5"),
        (dict(obs=np.array([[0, 0], [0, np.nan], [0, 0], [0, 0]], np.float32)), "non-finite value nan at row 1, column 1"),
        (dict(dt=0.0), "dt is 0.0"),
        (dict(task=""), "task name is empty"),
        (dict(action=np.zeros((4, 1))), "dtypes"),
    ]:
        bad = Dataset(**{**ok.__dict__, **change})
        with pytest.raises(ValueError, match=text):
            bad.validate()


def test_collection_refuses_the_evaluation_seed_stream():
    with pytest.raises(ValueError, match="2\\*\\*63"):
        collect("reach-v3", episodes=1, seed=EVAL_SEED_OFFSET - 5)
