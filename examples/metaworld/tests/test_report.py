"""The results file's seed spread and target checks, on hand-made rows."""
from dataclasses import asdict

from frmd_metaworld import report
from frmd_metaworld.benchmark import BenchConfig


def row(task, seed, method, successes, latency):
    return {"task": task, "group": "easy", "seed": seed, "method": method, "episodes": 50,
            "successes": successes, "success_rate": successes / 50, "success_ci95": [0.0, 1.0],
            "latency_us_median": latency, "latency_us_p99": latency, "roundtrip_us_median": None,
            "non_smooth_ee_mean": 1.0, "non_smooth_action_mean": 1.0, "rms_jerk_mean": 1.0, "mean_length": 40.0}


def results():
    rows = [row("reach-v3", None, "expert", 50, 1.0)]
    for seed, student in [(0, 45), (1, 40), (2, 50)]:
        rows += [row("reach-v3", seed, "dp-ddpm-100", 48, 5000.0), row("reach-v3", seed, "dp-ddim-10", 44, 500.0),
                 row("reach-v3", seed, "teacher", 46, 900.0), row("reach-v3", seed, "student-1", student, 100.0),
                 row("reach-v3", seed, "student-2", 47, 200.0),
                 row("reach-v3", seed, "int8-student", student, 40.0 if seed else 80.0)]
    rows += [row("push-v3", 0, "teacher", 50, 900.0), row("push-v3", 0, "student-1", 45, 100.0)]
    return {"config": asdict(BenchConfig(tasks=["reach-v3", "push-v3"])), "rows": rows}


def test_targets_pool_every_seed_and_name_the_worst_task():
    res = results()
    checks = {t: (v, ok) for t, v, ok in report.targets(report.summarize(res), res)}
    # pooled over reach s0-s2 and push s0: student 180/200, teacher 188/200, DDPM 144/150
    assert checks["one-step student >= teacher - 1 point"] == ("-4.0 points", False)
    assert checks["no task more than 4 points under its teacher (one-step student, mean over seeds)"] == (
        "worst push-v3 -10.0 points", False)
    assert checks["one-step student >= DP DDPM-100 - 1 point"] == ("-6.0 points", False)
    assert checks["int8 student within 1 point of the float student"][1]
    latency, ok = checks["int8 student latency <= 1/100 of DP DDPM-100 (every task-seed)"]
    assert not ok and latency.startswith("DDPM-100 / int8 = 62x at worst, 125x median (3 task-seeds)")


def test_spread_and_files(tmp_path):
    res = results()
    spread = {(x["task"], x["method"]): x for x in report.seed_spread(res)}
    s = spread[("reach-v3", "student-1")]
    assert s["seeds"] == 3 and abs(s["mean"] - 0.9) < 1e-12 and s["min"] == 0.8 and s["max"] == 1.0
    assert ("reach-v3", "expert") not in spread
    written = report.write(res, tmp_path / "results.md", "cmd", ["a note"],
                           {"student-1": 250_000, "student-2": 500_000, "teacher": 4_500_000})
    text = (tmp_path / "results.md").read_text()
    assert "## Targets (overall table)" in text and "| NO |" in text
    assert "## Spread over training seeds" in text and "- a note" in text
    assert "student-1 90.0 % at 0.25 M; student-2 94.0 % at 0.50 M; teacher 94.0 % at 4.50 M" in text
    assert "| push-v3 | medium | - | - | - | 100.0 | 90.0 | - | - |" in text
    assert [t["met"] for t in written["targets"]] == [False, False, False, True, False]
