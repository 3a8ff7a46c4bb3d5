"""The mock policy server of frmd_client with MetaWorld's scripted expert as `--policy expert`.

    python -m frmd_metaworld.mock_server --policy zeros [--horizon 12 --exec-steps 8 ...]
    python -m frmd_metaworld.mock_server --policy expert --task push-v3 [--float f32]

`expert`: horizon 1, f64 by default because the experts act on float64 observations.
"""
from __future__ import annotations

import sys

from frmd_client import mock_server
from frmd_client import protocol as p


def expert_session(args, float_type):
    """(ModelInfo, act) of MetaWorld's expert for args.task."""
    import numpy as np
    from .tasks import ACTION_DIM, DT, OBS_DIM, expert_policy
    expert = expert_policy(args.task)
    info = p.ModelInfo(OBS_DIM, ACTION_DIM, 1, 1, 1, float_type, DT, f"metaworld expert {args.task} ({args.float})")
    return info, lambda obs, prev, rate: expert(np.asarray(obs[-1], dtype=np.float64))


def main(argv=None) -> int:
    return mock_server.main(argv, expert=expert_session, default_task="reach-v3",
                            prog="python -m frmd_metaworld.mock_server")


if __name__ == "__main__":
    sys.exit(main())
