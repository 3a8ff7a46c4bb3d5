"""Moved to the shared package: `frmd_client.policy_client` (examples/frmd_client). This name stays for
scripts written against it."""
from frmd_client.policy_client import *  # noqa: F401,F403
