#!/usr/bin/env bash
# Install and start the system pieces RIVET's tests and authoring need, when they are missing:
# the Docker engine (the sandbox), debootstrap (the offline sandbox base image), the Mesa
# EGL/OSMesa libraries (headless rendering), the shared libraries open3d's wheel needs and
# Chromium (the authoring report is rendered headless by its test). As
# root on Debian/Ubuntu it installs them with apt-get and starts dockerd; otherwise it says
# what is missing and how to fix it.
# Idempotent and quiet when everything is in place.
set -euo pipefail

# (libgomp1, libusb-1.0-0: open3d's wheel links them; the toolbox tests import it on the host)
# chromium: the headless browser the authoring report is rendered in by its test
PACKAGES=(docker.io debootstrap libegl1 libegl-mesa0 libgl1-mesa-dri libgbm1 libosmesa6 libgomp1 libusb-1.0-0 chromium)
missing=()
if command -v dpkg-query >/dev/null 2>&1; then
  for p in "${PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
fi
# Docker Desktop / other engines are fine: only insist on docker.io when no engine answers and
# none can be started here (a docker CLI alone, as some images ship in /usr/local/bin, is not
# an engine).
if docker info >/dev/null 2>&1 || command -v dockerd >/dev/null 2>&1; then
  missing=("${missing[@]/docker.io}")
fi
read -r -a missing <<<"${missing[*]:-}"

if [ ${#missing[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then
    echo "bootstrap: installing ${missing[*]}"
    export DEBIAN_FRONTEND=noninteractive
    apt-get update -qq
    apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
  else
    echo "bootstrap: missing system packages: ${missing[*]}" >&2
    echo "bootstrap: install them (e.g. sudo apt-get install ${missing[*]}) and retry" >&2
    exit 1
  fi
fi

if ! docker info >/dev/null 2>&1; then
  if [ "$(id -u)" = 0 ] && command -v dockerd >/dev/null 2>&1; then
    log=/var/log/rivet-dockerd.log
    echo "bootstrap: starting dockerd (log: $log)"
    # setsid: the daemon outlives this make target and the test run that follows.
    setsid dockerd >"$log" 2>&1 </dev/null &
    for _ in $(seq 1 60); do
      docker info >/dev/null 2>&1 && break
      sleep 1
    done
    if ! docker info >/dev/null 2>&1; then
      echo "bootstrap: dockerd did not come up within 60 s; last lines of $log:" >&2
      tail -n 20 "$log" >&2 || true
      exit 1
    fi
  else
    echo "bootstrap: the Docker engine is not reachable (docker info failed)." >&2
    echo "bootstrap: start it (sudo systemctl start docker, or Docker Desktop) and make sure" >&2
    echo "bootstrap: your user may use it (sudo usermod -aG docker \$USER), then retry." >&2
    exit 1
  fi
fi
