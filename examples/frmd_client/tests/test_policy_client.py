"""`frmd serve` command lines as in-process load options, and the dt check (no wheel needed)."""
import pytest

from frmd_client.policy_client import check_dt, load_options


def test_serve_commands_become_load_options():
    assert load_options("frmd serve --baked runs/x/baked") == ("runs/x/baked", {})
    assert load_options("../../target/debug/frmd serve --ckpt 'a b/dp' --steps 100 --solver heun --exec-steps 4 "
                        "--float f64 --dt 0.0125 --init-action 0,-1.5") == \
        ("a b/dp", {"steps": 100, "solver": "heun", "exec_steps": 4, "float64": True, "dt": 0.0125,
                    "init_action": [0.0, -1.5]})
    for bad, text in [("frmd serve --baked a --socket s", "--socket"), ("frmd serve --steps 2", "one of"),
                      ("frmd serve --ckpt a --blob b", "one of"), ("python -m mock_server", "not a `frmd serve`"),
                      ("frmd serve --blob b --zeros", "--zeros")]:
        with pytest.raises(ValueError, match=text):
            load_options(bad)


def test_dt_is_compared_with_a_tolerance():
    check_dt(float(__import__("numpy").float32(0.0125)), 0.0125, "p")  # an f32 widened
    check_dt(0.0, 0.0125, "p")  # unknown
    check_dt(0.05, None, "p")  # nothing to compare with
    with pytest.raises(ValueError, match="trained at dt 0.05 s"):
        check_dt(0.05, 0.0125, "the policy")
