import json

import pytest

from frmd_client.runner import StepFailed, carry_over, load_previous, run_and_report


class Config:
    """Two tasks; B has training seeds 0 and 1; methods m1 and m2."""

    def runs(self):
        return [("A", 0), ("B", 0), ("B", 1)]

    def methods(self):
        return ["m1", "m2"]


def row(task, seed, method, successes=1):
    return {"task": task, "seed": seed, "method": method, "episodes": 2, "successes": successes,
            "report": f"/gone/{task}/seed{seed}/{method}.json"}


def test_carry_over_fills_only_configured_runs_without_a_report():
    here = {"rows": [row("A", 0, "m1", successes=2)], "demos": {"A": {"kept": 3}}}
    previous = {"rows": [row("A", 0, "m1"), row("A", 0, "m2"), row("B", 1, "m1"),
                         row("B", 2, "m1"), row("A", 0, "m3")],
                "demos": {"A": {"kept": 9}, "B": {"kept": 5}}}
    assert carry_over(here, previous, Config()) == 2
    keys = [(r["task"], r["seed"], r["method"]) for r in here["rows"]]
    assert keys == [("A", 0, "m1"), ("A", 0, "m2"), ("B", 1, "m1")]
    # the run's own report wins over the earlier row; earlier paths are kept as recorded
    assert here["rows"][0]["successes"] == 2
    assert here["rows"][2]["report"] == "/gone/B/seed1/m1.json"
    assert here["demos"] == {"A": {"kept": 3}, "B": {"kept": 5}}


@pytest.mark.parametrize("text, expected", [("not json", "unreadable"), ("[]", "'rows' list"),
                                            ('{"rows": [{"task": "A"}]}', "'rows' list")])
def test_load_previous_names_the_file_and_the_problem(tmp_path, text, expected):
    path = tmp_path / "results.json"
    path.write_text(text)
    with pytest.raises(StepFailed, match=expected) as e:
        load_previous(path)
    assert str(path) in str(e.value)


def test_bad_previous_stops_before_any_step(tmp_path, capsys):
    class Runner:
        def all(self):
            raise AssertionError("a step ran")

    status = run_and_report(Runner(), Config(), None, None, None, tmp_path / "r.md", "cmd", [],
                            previous=tmp_path / "missing.json")
    assert status == 2
    assert "missing.json" in capsys.readouterr().err


def test_report_notes_the_carried_rows(tmp_path):
    previous = tmp_path / "old.json"
    previous.write_text(json.dumps({"rows": [row("B", 1, "m2")]}))
    written = {}

    class Runner:
        def say(self, text):
            pass

    def write_report(results, md, command, notes):
        written.update(results=results, notes=notes)

    status = run_and_report(Runner(), Config(), lambda cfg: {"rows": [row("A", 0, "m1"), row("B", 0, "m1")]},
                            write_report, None, tmp_path / "r.md", "cmd", [], report_only=True,
                            previous=previous)
    assert status == 0
    assert len(written["results"]["rows"]) == 3
    assert any(n.startswith("1 of the 3 reports are carried over from") for n in written["notes"])
