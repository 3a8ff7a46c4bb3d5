"""The evaluation loop against the mock server (report fields of frmd eval), and the results
file's targets on hand-made rows."""
import os
import sys
from dataclasses import asdict

from frmd_client.evaluation import EPISODE_FIELDS, FRMD_EVAL_FIELDS
from frmd_client.policy_client import ServedPolicy
from frmd_maniskill import report
from frmd_maniskill.benchmark import BenchConfig
from frmd_maniskill.evaluate import evaluate
from frmd_maniskill.tasks import EVAL_SEED_OFFSET

from conftest import ROOT


def test_mock_server_episode_has_the_report_fields():
    env = {**os.environ, "PYTHONPATH": os.path.join(ROOT, "..", "frmd_client")}
    os.environ["PYTHONPATH"] = env["PYTHONPATH"]
    policy = ServedPolicy(f"{sys.executable} -m frmd_client.mock_server --policy hold --obs-dim 42 --action-dim 8 "
                          "--dt 0.05", dt=0.05)
    try:
        r = evaluate("PickCube-v1", policy, episodes=1, warmup_calls=1)
    finally:
        policy.close()
    assert all(k in r for k in FRMD_EVAL_FIELDS) and sorted(r["per_episode"][0]) == sorted(EPISODE_FIELDS)
    # `hold` repeats RESET's initial action: the arm stays put, the cube is never picked up.
    ep = r["per_episode"][0]
    assert ep["seed"] == EVAL_SEED_OFFSET and not ep["success"] and ep["length"] == r["max_steps"] == 200
    assert r["controller"] == "pd_joint_pos" and r["chunk_calls"] == 25


def row(task, seed, method, successes, per_step):
    return {"task": task, "group": "hard" if task == "PegInsertionSide-v1" else "easy", "seed": seed,
            "method": method, "episodes": 50, "successes": successes, "success_rate": successes / 50,
            "success_ci95": [0.0, 1.0], "latency_us_median": 100.0, "latency_us_p99": 100.0,
            "roundtrip_us_median": None, "non_smooth_ee_mean": per_step * 100, "non_smooth_action_mean": 1.0,
            "rms_jerk_mean": 1.0, "mean_length": 100.0}


def test_targets_of_issue_23(tmp_path):
    rows = []
    for seed in (0, 1, 2):
        rows += [row("PegInsertionSide-v1", seed, "teacher", 20, 0.5), row("PegInsertionSide-v1", seed, "student-1", 19, 0.4),
                 row("PegInsertionSide-v1", seed, "dp-ddpm-100", 10, 0.6)]
    rows += [row("PickCube-v1", 0, "student-1", 50, 0.7), row("PickCube-v1", 0, "dp-ddpm-100", 50, 0.6)]
    cfg = asdict(BenchConfig(tasks=["PickCube-v1", "PegInsertionSide-v1"], only=["dp-ddpm-100", "teacher", "student-1"]))
    results = {"config": cfg, "rows": rows, "demos": {}}
    checks = {t: (v, ok) for t, v, ok in report.targets(report.shared.summarize(rows, report.GROUPS,
                                                                                 report.methods_of(cfg)), results)}
    # 9 tasks x 7 methods, of which PegInsertionSide-v1 has 3 methods and PickCube-v1 2.
    assert checks["every task has a row for every method"] == ("58 (task, method) pairs missing, e.g. PickCube-v1 "
                                                               "dp-ddim-10", False)
    assert checks["hard group: one-step student >= teacher - 2 points"] == ("-2.0 points", True)
    assert checks["hard group: one-step student >= DP DDPM-100"] == ("+18.0 points", True)
    v, ok = checks["non-smooth transitions per step: one-step student <= DP DDPM-100 on every task"]
    assert not ok and v.startswith("1 of 2 tasks; not on PickCube-v1 0.700 > 0.600")
    written = report.write(results, tmp_path / "results.md", "cmd", ["a note"])
    text = (tmp_path / "results.md").read_text()
    assert "## Beside the paper" in text and "| hard | student-1 |" in text and "## Targets (issue 23)" in text
    assert (tmp_path / "results.png").read_bytes().startswith(b"\x89PNG") and len(written["targets"]) == 4
