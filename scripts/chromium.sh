#!/usr/bin/env bash
# Make sure Debian's chromium is installed (the eye renderer's kiosk windows,
# and the browser tests, which drive it with Playwright).
exec "$(dirname "$0")/test-packages.sh" chromium
