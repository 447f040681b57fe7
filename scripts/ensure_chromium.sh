#!/usr/bin/env bash
# Kept for the studio docs: installs chromium (and the other Debian packages the tests use).
exec bash "$(dirname "$0")/ensure_apt.sh"
