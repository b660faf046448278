#!/usr/bin/env bash
# Set-up on a fresh machine: system packages (Mesa's software Vulkan device, used by the GPU-path
# tests and off-screen GGUI rendering; Xvfb and xdotool for the window test; g++ builds mesh2sdf from source), then the package with its
# test, benchmark and batch (Dask distributed) extras.
set -euo pipefail
cd "$(dirname "$0")"
if command -v apt-get >/dev/null 2>&1; then
  SUDO=""
  if [ "$(id -u)" != "0" ]; then SUDO="sudo -n"; fi
  if $SUDO true 2>/dev/null; then
    $SUDO apt-get update -qq
    # xvfb + xdotool: the grooming window opened on a virtual screen and driven by synthetic input (tests)
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq mesa-vulkan-drivers libvulkan1 g++ xvfb xdotool >/dev/null
  else
    echo "setup.sh: no root: skipping apt-get (mesa-vulkan-drivers); the Vulkan test will be skipped" >&2
  fi
fi
export PIP_DISABLE_PIP_VERSION_CHECK=1
python3 -m pip install -q -e ".[test,bench,batch]"
