#!/usr/bin/env bash
# Set up PREDISAT on Debian/Ubuntu: the system libraries open3d links against, a virtual
# environment in .venv and the package (editable) with the [synth] extra the demo renders with.
# `--dev` adds the test and lint tools and Chromium for the report tests. (`pip install .` alone
# is the core: no renderer.)
# Safe to run again: it installs only what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."

extras="[synth]"
if [ "${1:-}" = "--dev" ]; then extras="[synth,dev]"; fi

# open3d's binary links libEGL/libGL/libX11/libudev/libusb; a minimal Debian lacks libusb-1.0-0.
pkgs="libusb-1.0-0 libudev1 libgl1 libegl1 libx11-6 libgomp1 python3-venv"
# --dev: the report tests open the HTML report in Debian's headless Chromium through its
# chromedriver (/usr/bin/chromium, /usr/bin/chromedriver; nothing is downloaded by selenium)
if [ "${1:-}" = "--dev" ]; then pkgs="$pkgs chromium chromium-driver"; fi
missing=""
for p in $pkgs; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
if [ -n "$missing" ] && command -v apt-get >/dev/null 2>&1; then
  sudo=""; if [ "$(id -u)" -ne 0 ]; then sudo="sudo"; fi
  echo "setup: installing system packages:$missing"
  $sudo apt-get update -qq
  # shellcheck disable=SC2086
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq $missing >/dev/null
fi

python=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then "$python" -m venv .venv; fi
.venv/bin/python -m pip install -q --disable-pip-version-check --upgrade pip
.venv/bin/python -m pip install -q --disable-pip-version-check -e ".${extras}"
echo "setup: ready (.venv/bin/predisat, .venv/bin/locator)"
