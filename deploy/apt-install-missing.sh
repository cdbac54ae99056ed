#!/usr/bin/env bash
# Installs those of the Debian packages named that are not installed, with apt-get (sudo when
# not root): deploy/install-deps.sh and deploy/check-arm64.sh share it.
#   deploy/apt-install-missing.sh WHO PACKAGE...
# WHO names the caller in its lines. A package is installed when it is for this machine's
# architecture (or for all); one named PACKAGE:ARCH, for that architecture: a multi-arch package
# may be there for another one (check-arm64.sh adds arm64 copies of liblz4-dev and the like).
set -euo pipefail
who="$1"
shift
host="$(dpkg --print-architecture)"
missing=()
for p in "$@"; do
  arch="$host|all"
  case "$p" in *:*) arch="${p##*:}" ;; esac
  status="$(dpkg-query -W -f='${Architecture} ${Status}\n' "$p" 2>/dev/null || true)"
  grep -qE "^($arch) install ok installed$" <<<"$status" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "$who: all $# packages already installed"
  exit 0
fi
echo "$who: installing ${missing[*]}"
sudo=""
if [ "$(id -u)" != 0 ]; then sudo="sudo"; fi
# (env: sudo would drop DEBIAN_FRONTEND; the lock timeout waits out apt's daily run on a new VM)
apt=($sudo env DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600)
"${apt[@]}" update -qq
"${apt[@]}" install -y -qq --no-install-recommends "${missing[@]}"
