#!/usr/bin/env bash
# Idempotent set-up: Debian packages (libLLVM >= 16 for Mitsuba's CPU backend, libusb for open3d,
# headless Chromium for the report test, Node.js for the report's 3D view and the glTF validator), a local
# virtualenv (.venv) with the pinned Python packages, dpi itself (editable), and the pinned JavaScript
# packages of package-lock.json in node_modules/.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}
DEBIAN_PACKAGES=(libllvm19 libusb-1.0-0 chromium)
# Node.js from Debian only where none is on the PATH (a NodeSource nodejs brings its own npm, which Debian's conflicts with)
command -v node >/dev/null || DEBIAN_PACKAGES+=(nodejs)
command -v npm >/dev/null || DEBIAN_PACKAGES+=(npm)

missing=()
for pkg in "${DEBIAN_PACKAGES[@]}"; do
  dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed" || missing+=("$pkg")
done
if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null; then SUDO="sudo"; else SUDO="none"; fi
  if [ "$SUDO" = none ] || ! command -v apt-get >/dev/null; then
    echo "setup: cannot install ${missing[*]} (needs apt-get as root). Mitsuba's CPU backend needs libLLVM >= 16:" >&2
    echo "       install it yourself, or set DRJIT_LIBLLVM_PATH to a libLLVM-16+ library." >&2
  else
    echo "setup: installing Debian packages ${missing[*]}"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${missing[@]}" >/dev/null
  fi
fi

if command -v npm >/dev/null && { [ ! -d node_modules ] || [ package-lock.json -nt node_modules ]; }; then
  if npm ci --no-audit --no-fund --loglevel=error >/dev/null; then
    touch node_modules
  else
    echo "setup: npm ci failed: the report's 3D view is left out and the glTF validator test skipped" >&2
  fi
fi

stamp="$VENV/.dpi-installed"
if [ -f "$stamp" ] && [ "$stamp" -nt requirements.txt ] && [ "$stamp" -nt pyproject.toml ]; then
  exit 0
fi
[ -x "$VENV/bin/python" ] || "$PYTHON" -m venv "$VENV"
"$VENV/bin/python" -m pip install -q --upgrade pip >/dev/null
# torch first and pinned: an unpinned torch would pull the CUDA build (gigabytes).
"$VENV/bin/python" -m pip install -q torch==2.13.0
"$VENV/bin/python" -m pip install -q -r requirements.txt
# SAM 2 is a source package whose build needs torch: built against the installed one, without its CUDA extension
SAM2_BUILD_CUDA=0 "$VENV/bin/python" -m pip install -q --no-build-isolation --no-deps sam2==1.1.0
"$VENV/bin/python" -m pip install -q --no-deps -e .
touch "$stamp"
echo "setup: environment ready in $VENV"
