"""The data options of collect (relative observation vectors, expert steps after the first
success) and their counterpart in evaluation."""
import numpy as np
import pytest

from frmd_metaworld.collect import collect
from frmd_metaworld.evaluate import ExpertPolicy, evaluate
from frmd_metaworld.tasks import GOAL, HAND, OBJECT, SeededEnv, layout_dim, layout_of_dim, observe


def test_relative_layout_appends_the_three_differences():
    obs = np.arange(39, dtype=np.float64)
    rel = observe(obs, "relative")
    assert rel.shape == (48,) and np.array_equal(rel[:39], obs)
    assert np.array_equal(rel[39:42], obs[GOAL] - obs[HAND])
    assert np.array_equal(rel[42:45], obs[OBJECT] - obs[HAND])
    assert np.array_equal(rel[45:48], obs[GOAL] - obs[OBJECT])
    assert observe(obs, "raw") is obs
    assert layout_of_dim(48) == "relative" and layout_of_dim(39) == "raw"
    with pytest.raises(ValueError, match="no observation layout has 40"):
        layout_of_dim(40)
    with pytest.raises(ValueError, match="unknown observation layout"):
        layout_dim("absolute")


def test_after_success_records_that_many_more_expert_steps():
    plain, _ = collect("reach-v3", episodes=1, seed=10)
    longer, _ = collect("reach-v3", episodes=1, seed=10, obs_layout="relative", after_success=5)
    assert len(longer.obs) == len(plain.obs) + 5
    assert longer.obs.shape[1] == 48 and longer.extra["obs_layout"] == "relative"
    assert longer.extra["after_success"] == "5"
    # The first rows are the same episode seen through the other layout.
    assert np.array_equal(longer.obs[: len(plain.obs), :39], plain.obs)
    assert np.array_equal(longer.action[: len(plain.action)], plain.action)
    env = SeededEnv("reach-v3")
    env.reset(10)
    flags = [env.step(a)[1] for a in longer.action]
    assert flags.index(True) == len(plain.action) - 1


def test_evaluation_checks_the_layout_against_the_policy():
    expert = ExpertPolicy("reach-v3")
    with pytest.raises(ValueError, match="observes 39 floats"):
        evaluate("reach-v3", expert, episodes=1, obs_layout="relative")
    report = evaluate("reach-v3", expert, episodes=1)
    assert report["obs_layout"] == "raw"
