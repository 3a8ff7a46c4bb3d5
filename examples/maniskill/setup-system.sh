#!/usr/bin/env bash
# The system packages ManiSkill3 needs on Debian 12, as root: SAPIEN creates a Vulkan device even
# when nothing is rendered, and Debian 12's own Mesa (22.3) lacks VK_KHR_external_semaphore_fd,
# which lavapipe (Mesa's CPU Vulkan driver) has from Mesa 24.3. bookworm-backports has Mesa 25:
# this script adds that suite from the same archive as the machine's bookworm entry (if no
# backports entry exists), then installs lavapipe and the Vulkan loader from it. Idempotent: a
# machine that already has Mesa >= 24.3's lavapipe is left as it is. Called by setup.sh.
set -euo pipefail
mesa_version() { dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true; }
have="$(mesa_version)"
if [ -n "$have" ] && dpkg --compare-versions "$have" ge 24.3; then
    echo "setup-system: mesa-vulkan-drivers $have is new enough"
    exit 0
fi
if [ "$(id -u)" != 0 ]; then
    echo "setup-system: installing mesa-vulkan-drivers >= 24.3 from bookworm-backports needs root (found '${have:-none}'); run: sudo bash $0" >&2
    exit 1
fi
. /etc/os-release
if [ "${VERSION_CODENAME:-}" != bookworm ]; then
    echo "setup-system: this script knows Debian 12 (bookworm); on $PRETTY_NAME install Mesa >= 24.3's lavapipe (mesa-vulkan-drivers) and the Vulkan loader (libvulkan1) yourself" >&2
    exit 1
fi
if ! apt-get indextargets --format '$(RELEASE)' | grep -qx bookworm-backports; then
    archive="$(apt-get indextargets --format '$(REPO_URI)' 'Release: bookworm' 'Created-By: Packages' | head -n 1)"
    if [ -z "$archive" ]; then
        echo "setup-system: no apt source for bookworm found (apt-get indextargets); add bookworm-backports by hand" >&2
        exit 1
    fi
    cat > /etc/apt/sources.list.d/bookworm-backports.sources <<SRC
Types: deb
URIs: $archive
Suites: bookworm-backports
Components: main
Signed-By: /usr/share/keyrings/debian-archive-keyring.gpg
SRC
    echo "setup-system: added bookworm-backports from $archive"
fi
apt-get update -qq
DEBIAN_FRONTEND=noninteractive apt-get install -y -qq -t bookworm-backports mesa-vulkan-drivers libvulkan1 >/dev/null
echo "setup-system: mesa-vulkan-drivers $(mesa_version) installed"
