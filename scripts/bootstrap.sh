#!/usr/bin/env bash
# Create or refresh .venv for this project; called by `make run` and `make test`.
# Usage: scripts/bootstrap.sh [--test]   (--test also makes sure the browser for report tests exists)
set -euo pipefail
cd "$(dirname "$0")/.."

VENV=.venv
STAMP=$VENV/.installed
PYTHON=${PYTHON:-python3}

need_apt=()
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  need_apt+=(libusb-1.0-0)   # open3d's native library links against it
fi
if [[ "${1:-}" == "--test" ]] && ! command -v chromium >/dev/null 2>&1; then
  need_apt+=(chromium)       # the report test loads the HTML in headless Chromium
fi
if ((${#need_apt[@]})); then
  if [[ $(id -u) -eq 0 ]] && command -v apt-get >/dev/null; then
    echo "bootstrap: installing Debian packages: ${need_apt[*]}"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
  else
    echo "bootstrap: missing Debian packages: ${need_apt[*]}" >&2
    echo "fix: apt-get install -y ${need_apt[*]}   (as root)" >&2
    exit 1
  fi
fi

# The venv is stale when pyproject.toml changed since it was last installed. The tests also need the
# optional viewer (viser), so --test installs that extra and keeps its own stamp.
TARGET=.
if [[ "${1:-}" == "--test" ]]; then
  TARGET=".[viewer]"
  STAMP=$VENV/.installed-test
fi
if [[ ! -x $VENV/bin/python || ! -f $STAMP || pyproject.toml -nt $STAMP ]]; then
  echo "bootstrap: setting up $VENV (torch==2.13.0 CPU build from the local wheel cache where present)"
  [[ -x $VENV/bin/python ]] || "$PYTHON" -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip
  "$VENV/bin/python" -m pip install -q -e "$TARGET"
  touch "$STAMP"
fi
