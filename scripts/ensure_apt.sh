#!/usr/bin/env bash
# Install Debian packages the tests use when they are missing, in one apt transaction:
#   chromium            studio browser tests (Playwright drives /usr/bin/chromium)
#   blender python3-numpy   creature Blender import + Rigify generate tests (Debian's 3.4 glTF
#                       add-on needs python3-numpy)
#   ffmpeg              MP4 motion previews (GIF works without it)
# Needs root or sudo; otherwise it exits 1 and the tests that need a package skip with a reason.
set -euo pipefail
need=()
[ -x /usr/bin/chromium ] || need+=(chromium)
command -v blender >/dev/null || need+=(blender python3-numpy)
command -v ffmpeg >/dev/null || need+=(ffmpeg)
[ ${#need[@]} -eq 0 ] && exit 0
if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo -n"; else exit 1; fi
export DEBIAN_FRONTEND=noninteractive
echo "installing Debian packages: ${need[*]}"
$SUDO apt-get update -qq >/dev/null
$SUDO apt-get install -y -qq --no-install-recommends "${need[@]}" >/dev/null
