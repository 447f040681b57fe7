#!/usr/bin/env bash
# Install Debian's chromium for the studio's browser tests when it is missing (no browser
# download by Playwright: the tests drive /usr/bin/chromium). Needs root or sudo; otherwise
# it exits 1 and the browser tests skip with a reason.
set -euo pipefail
[ -x /usr/bin/chromium ] && exit 0
if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo -n"; else exit 1; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq >/dev/null
$SUDO apt-get install -y -qq --no-install-recommends chromium >/dev/null
[ -x /usr/bin/chromium ]
