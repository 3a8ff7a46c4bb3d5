"""A short closed-loop evaluation of the expert gives a report with frmd eval's fields, and the
same expert behind the protocol (mock server, f64) gives the same episodes."""
import json
import os
import sys

import numpy as np

from conftest import ROOT
from frmd_metaworld.evaluate import EPISODE_FIELDS, FRMD_EVAL_FIELDS, ExpertPolicy, ServedPolicy, evaluate
from frmd_metaworld.tasks import EVAL_SEED_OFFSET, SeededEnv, eval_seed


def check_report(report, episodes):
    json.dumps(report)
    for key in FRMD_EVAL_FIELDS:
        assert key in report, key
    assert report["episodes"] == len(report["per_episode"]) == episodes
    assert 0 <= report["success_ci95"][0] <= report["success_rate"] <= report["success_ci95"][1] <= 1
    assert report["chunk_calls"] > 0 and report["latency_us_median"] > 0 and report["sim_step_us"] > 0
    for episode in report["per_episode"]:
        assert sorted(episode) == sorted(EPISODE_FIELDS)
        assert episode["seed"] >= EVAL_SEED_OFFSET and 1 <= episode["length"] <= 500


def test_expert_report():
    report = evaluate("reach-v3", ExpertPolicy("reach-v3"), episodes=2)
    check_report(report, 2)
    assert report["successes"] == 2 and report["exec_steps"] == 1 and report["history"] == 1


def test_expert_through_the_protocol_gives_the_same_episodes():
    command = f"{sys.executable} -m frmd_metaworld.mock_server --policy expert --task reach-v3"
    os.environ["PYTHONPATH"] = ROOT
    served = ServedPolicy(command)
    try:
        report = evaluate("reach-v3", served, episodes=2)
    finally:
        served.close()
    check_report(report, 2)
    direct = evaluate("reach-v3", ExpertPolicy("reach-v3"), episodes=2)
    assert report["per_episode"] == direct["per_episode"]
    assert report["roundtrip_us_median"] >= report["latency_us_median"]


def test_evaluation_layouts_differ_from_demonstration_layouts():
    env = SeededEnv("push-v3")
    demos = []
    for seed in range(100):
        env.reset(seed)
        demos.append(env.initial_condition())
    for i in range(50):
        env.reset(eval_seed(0, i))
        layout = env.initial_condition()
        assert min(np.abs(d - layout).max() for d in demos) > 1e-6
