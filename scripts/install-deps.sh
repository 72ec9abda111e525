#!/usr/bin/env bash
# Installs the Debian 12 packages slamd needs to build, test and run. Idempotent: does nothing
# when everything is present; otherwise runs apt-get update then installs only what is missing.
# Uses sudo when not root. Exits non-zero with a clear message when it cannot.
# `install-deps.sh fuzz` adds what `make fuzz` needs (clang and its libFuzzer runtime).
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake pkg-config ccache git clang-format
  # libraries (the project's dependency list)
  liblcm-dev liblcm-bin libglib2.0-dev libeigen3-dev libopencv-dev liboctomap-dev
  libopenni2-dev libsuitesparse-dev zlib1g-dev
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # integration tests: network namespaces (unshare, ip), octomap tools
  iproute2 util-linux octomap-tools
  # benchmarks: peak memory and CPU time of each run; the web and soak benchmarks' summaries
  time python3
  # slamd-spy: lcm-spy (LCM's Java library and its chart library), a JDK for the types' jar, and
  # for its test an X server, a screenshot tool and a font
  liblcm-java libjchart2d-java default-jdk-headless default-jre xvfb x11-apps netpbm
  fonts-dejavu-core
  # slamd-web: its HTTP + WebSocket server, three.js for its page, and a headless browser for
  # its test
  libcivetweb-dev libjs-three chromium-headless-shell
)
if [ "${1:-}" = "fuzz" ]; then
  PACKAGES+=(clang libclang-rt-14-dev)
fi

missing=()
for pkg in "${PACKAGES[@]}"; do
  status=$(dpkg-query -W -f='${db:Status-Status}' "$pkg" 2>/dev/null || true)
  [ "$status" = "installed" ] || missing+=("$pkg")
done

if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#PACKAGES[@]} packages present"
  exit 0
fi

if ! command -v apt-get >/dev/null 2>&1; then
  echo "install-deps: apt-get not found; slamd's installer supports Debian 12 (bookworm)." >&2
  echo "install-deps: install these packages by hand: ${missing[*]}" >&2
  exit 1
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then
  if command -v sudo >/dev/null 2>&1; then
    SUDO="sudo"
  else
    echo "install-deps: not root and sudo is not available; run as root or install: ${missing[*]}" >&2
    exit 1
  fi
fi

echo "install-deps: installing ${#missing[@]} missing packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
if ! $SUDO apt-get update -qq; then
  echo "install-deps: 'apt-get update' failed (no network or no Debian mirror?)" >&2
  exit 1
fi
if ! $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"; then
  echo "install-deps: 'apt-get install' failed for: ${missing[*]}" >&2
  exit 1
fi
echo "install-deps: done"
