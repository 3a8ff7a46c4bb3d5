"""`collect --policy-server`: a served policy's rollouts recorded as a dataset. The scripted
expert behind the protocol (mock server, f64) records exactly the demonstrations `collect`
writes for the same seeds."""
import os
import sys

import numpy as np
import pytest

from conftest import ROOT
from frmd_metaworld.collect import collect, record_policy
from frmd_metaworld.evaluate import ServedPolicy


def test_served_expert_records_the_demonstrations():
    os.environ["PYTHONPATH"] = ROOT
    served = ServedPolicy(f"{sys.executable} -m frmd_metaworld.mock_server --policy expert --task reach-v3")
    try:
        recorded, stats = record_policy("reach-v3", served, episodes=2, seed=5)
        with pytest.raises(ValueError, match="collection seeds"):
            record_policy("reach-v3", served, episodes=2, seed=2**63 - 1)
    finally:
        served.close()
    demos, _ = collect("reach-v3", 2, seed=5)
    assert stats["successes"] == 2 and "every episode kept" in recorded.source
    np.testing.assert_array_equal(recorded.obs, demos.obs)
    np.testing.assert_array_equal(recorded.action, demos.action)
    np.testing.assert_array_equal(recorded.episode_ends, demos.episode_ends)
