"""Demonstrations: the file is what frmd-host reads, the rows are the planner's episodes (their
actions replayed from the seed reach success at the last row), and evaluation seeds give other
initial conditions than the demonstrations'."""
import json
import struct

import numpy as np
import pytest

from frmd_client.dataset import Dataset
from frmd_maniskill.demos import collect
from frmd_maniskill.tasks import EVAL_SEED_OFFSET, SeededEnv, eval_seed


@pytest.fixture(scope="module")
def pick(tmp_path_factory):
    data, stats = collect("PickCube-v1", episodes=2, seed=5)
    path = tmp_path_factory.mktemp("d") / "pick.safetensors"
    data.save(path)
    return data, stats, path


def test_written_file_is_what_frmd_reads(pick):
    data, stats, path = pick
    raw = path.read_bytes()
    header = json.loads(raw[8:8 + struct.unpack("<Q", raw[:8])[0]])
    steps = stats["steps"]
    assert header["obs"] == {**header["obs"], "dtype": "F32", "shape": [steps, 42]}
    assert header["action"]["dtype"] == "F32" and header["action"]["shape"] == [steps, 8]
    assert header["episode_ends"]["dtype"] == "I64" and header["episode_ends"]["shape"] == [2]
    meta = header["__metadata__"]
    assert meta["task"] == "maniskill/PickCube-v1" and float(meta["dt"]) == 0.05
    assert meta["controller"] == "pd_joint_pos" and meta["action_before_start"] == "first"
    assert json.loads(meta["episode_seeds"]) == [5, 6]
    assert json.loads(meta["versions"])["mani_skill"] == "3.0.1"
    loaded = Dataset.load(path)
    assert np.array_equal(loaded.obs, data.obs) and np.array_equal(loaded.action, data.action)


def test_rows_replay_to_success_at_the_last_row(pick):
    data, _, _ = pick
    env = SeededEnv("PickCube-v1")
    for seed, episode in zip([5, 6], data.episodes()):
        obs = env.reset(seed)
        assert np.allclose(data.obs[episode.start], obs.astype(np.float32), atol=1e-6)
        flags = [env.step(a)[1] for a in data.action[episode]]
        assert flags[-1] and not any(flags[:-1])
    # Absolute joint targets: RESET's initial action is where the arm is, with the gripper open,
    # close to the planner's first command (what training puts before the episode).
    env.reset(5)
    assert np.abs(np.array(env.init_action()) - data.action[0]).max() < 0.05
    env.close()


def test_evaluation_layouts_differ_from_demonstration_layouts():
    env = SeededEnv("PushCube-v1")
    demos = [env.reset(s) for s in range(30)]
    for i in range(30):
        layout = env.reset(eval_seed(0, i))
        assert min(np.abs(d - layout).max() for d in demos) > 1e-4
    env.close()


def test_collection_refuses_the_evaluation_seed_stream():
    with pytest.raises(ValueError, match="2\\*\\*31"):
        collect("PickCube-v1", episodes=2, seed=EVAL_SEED_OFFSET - 1)


def test_demo_metrics_replays_the_file_and_names_missing_metadata(pick, tmp_path):
    from frmd_maniskill.evaluate import demo_metrics
    data, stats, path = pick
    m = demo_metrics(path)
    assert m["episodes"] == 2 and m["success_at_last_row"] == 2 and m["steps"] == stats["steps"]
    assert 0.0 < m["non_smooth_per_step"] < 1.0 and m["rms_jerk_mean"] > 0.0
    bare = tmp_path / "bare.safetensors"
    Dataset(data.obs, data.action, data.episode_ends, data.task, data.dt, data.source, {}).save(bare)
    with pytest.raises(ValueError, match="bare.safetensors: metadata field 'maniskill_task'"):
        demo_metrics(bare)
