"""Moved to the shared package: `frmd_client.metrics` (examples/frmd_client). This name stays for
scripts written against it."""
from frmd_client.metrics import *  # noqa: F401,F403
