#!/usr/bin/env bash
# Installs the Debian 12 packages exid needs, only those missing. Run as root (or with sudo).
# --fuzz: also clang 14 and its libFuzzer/sanitizer runtimes, for the fuzz build (tests/fuzz).
set -euo pipefail
pkgs=(build-essential cmake pkg-config
      libeigen3-dev libboost-dev libboost-filesystem-dev libnlopt-cxx-dev libsundials-dev
      libfmt-dev libyaml-cpp-dev liburdfdom-dev libcli11-dev libgtest-dev libgmock-dev
      libbenchmark-dev libsqlite3-dev libzstd-dev liblz4-dev libxxhash-dev libfcl-dev gnuplot-nox
      libopenmpi-dev openmpi-bin
      # the Python package (docs/python.md), its tests and the notebooks they execute
      pybind11-dev python3-dev python3-numpy python3-pandas python3-pytest python3-matplotlib
      python3-nbconvert python3-nbclient python3-ipykernel python3-jupyter-client
      # the wheel (pyproject.toml): built by pip, installed into a venv (tests/python/wheel.sh)
      python3-pip python3-venv
      # the report as a person sees it: rendered headless (tests/integration/report_html_test)
      chromium
      # exid export's MJCF and SDF read by MuJoCo and libsdformat (tests/robots/export_formats_test)
      libmujoco-dev libsdformat-dev)
for arg in "$@"; do
  case "$arg" in
    --fuzz) pkgs+=(clang-14 libclang-rt-14-dev) ;;
    *) echo "install-deps: unknown argument '$arg' (--fuzz)" >&2; exit 2 ;;
  esac
done
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "install-deps: all ${#pkgs[@]} packages present"
  exit 0
fi
echo "install-deps: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
echo "install-deps: done"
