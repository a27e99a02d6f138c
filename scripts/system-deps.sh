#!/usr/bin/env bash
# System libraries the Python stack needs and pip cannot install:
#   libusb-1.0-0  open3d loads it at import
#   libgl1, libgomp1  open3d's renderer and OpenMP (present on most images)
#   libegl1, libegl-mesa0, libgl1-mesa-dri  headless OpenGL for pyrender (PYOPENGL_PLATFORM=egl: the map picture)
#   chromium, chromium-driver  headless Chromium and its WebDriver: the leaderboard site's browser test
#                              (tests/test_site.py) and scripts/site_screenshot.py (Debian's package names)
#   postgresql  the evaluation server's tests on PostgreSQL (tests/test_server_postgres.py starts a throwaway
#               cluster with its initdb and pg_ctl; the server itself needs none for SQLite)
set -euo pipefail
need=()
for pkg in libusb-1.0-0 libgl1 libgomp1 libegl1 libegl-mesa0 libgl1-mesa-dri chromium chromium-driver postgresql; do
    dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || need+=("$pkg")
done
[ ${#need[@]} -eq 0 ] && exit 0
echo "installing system packages: ${need[*]}"
if [ "$(id -u)" -eq 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else
    echo "please install as root: apt-get install ${need[*]}" >&2; exit 1; fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null
