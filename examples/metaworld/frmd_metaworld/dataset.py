"""Moved to the shared package: `frmd_client.dataset` (examples/frmd_client). This name stays for
scripts written against it."""
from frmd_client.dataset import *  # noqa: F401,F403
