"""Moved to the shared package: `frmd_client.protocol` (examples/frmd_client). This name stays for
scripts written against it."""
from frmd_client.protocol import *  # noqa: F401,F403
