#!/usr/bin/env bash
# One-command setup on a fresh Debian/Ubuntu machine: system libraries, then monoplane, its test
# tools and the plugin packages in plugins/ (editable installs).
set -euo pipefail
cd "$(dirname "$0")"

# libgl1 libegl1 libx11-6 libgomp1 libusb-1.0-0: needed by `import open3d` (libusb is missing on
#   fresh machines and the import then fails).
# libegl-mesa0 libgl1-mesa-dri: Mesa's OpenGL drivers, for Open3D's own renderer and viewers
#   (monoplane's reports draw their 3D views without OpenGL).
# chromium: the test that opens a report's interactive 3D view in a real (headless) browser.
# Every Python dependency ships manylinux wheels, so no compiler is needed.
APT_PACKAGES="libgl1 libegl1 libx11-6 libgomp1 libusb-1.0-0 libegl-mesa0 libgl1-mesa-dri chromium"
SUDO=""
if [ "$(id -u)" != 0 ]; then SUDO="sudo"; fi
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends $APT_PACKAGES >/dev/null

PYTHON="${PYTHON:-python3}"
# The ray and rerun extras are installed too, so that the tests exercise
# `monoplane batch --engine ray` and the --rerun recordings.
"$PYTHON" -m pip install --quiet -e ".[dev,ray,rerun]"
for plugin in plugins/*/; do
  if [ -f "$plugin/pyproject.toml" ]; then
    "$PYTHON" -m pip install --quiet -e "$plugin"
  fi
done
# Compile monoplane's numba kernels now (cached on disk beside the sources; 30-60 s on 2 cores),
# so that the first run does not spend 20-30 s doing it; a failure here only leaves that cost
# to the first run.
"$PYTHON" -m monoplane.warmup --quiet \
  || echo "setup.sh: the kernel warm-up failed; the first run will compile the kernels" >&2
"$PYTHON" -c "import monoplane, open3d, pycolmap, onnxruntime; print('monoplane', monoplane.__version__, 'ready')"
