#!/usr/bin/env bash
# Installs those of the given Debian packages that are missing (apt-get, with sudo unless root),
# and nothing when all are there. Shared by install_deps.sh and install_opensplat.sh.
#
#   scripts/apt_install.sh NAME PACKAGE...      NAME prefixes the messages
set -euo pipefail
name=$1
shift
missing=()
for p in "$@"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "$name: all $# packages present"
  exit 0
fi
echo "$name: installing ${missing[*]}"
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
