#!/usr/bin/env bash
# Install Debian's chromium for the studio's browser tests when it is missing (no browser
# download by Playwright). Needs root or sudo; otherwise the browser tests skip.
set -euo pipefail
command -v chromium >/dev/null && exit 0
if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else exit 1; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq >/dev/null
$SUDO apt-get install -y -qq chromium >/dev/null
