"""Moved to the shared package: `frmd_client.session` (examples/frmd_client). This name stays for
scripts written against it."""
from frmd_client.session import *  # noqa: F401,F403
