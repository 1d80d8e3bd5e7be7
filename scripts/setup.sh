#!/usr/bin/env bash
# Installs every build, test and benchmark dependency from Debian packages.
# Idempotent: packages already present are left as they are.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config clang-format
  libboost-iostreams-dev libzstd-dev zlib1g-dev libspdlog-dev libgtest-dev libcli11-dev nlohmann-json3-dev
  # tests and benchmarks only: reference triangulations and independent mesh readers
  libcgal-dev libgmp-dev libmpfr-dev python3 python3-numpy python3-meshio gmsh libgmsh-dev time
  # field: the SciPy (Qhull) comparison test, the docs' density picture
  python3-scipy python3-matplotlib
  # HDF5 input (optional at build time) and the h5py files its tests read
  libhdf5-dev python3-h5py
  # runs under mpirun (optional at build time: -DTETSTREAM_MPI) and their tests
  libopenmpi-dev openmpi-bin
  # the Python package (optional at build time: -DTETSTREAM_PYTHON) and its tests
  pybind11-dev python3-pybind11 python3-dev python3-pytest python3-setuptools python3-pip python3-wheel python3-venv
)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]} == 0)); then
  echo "setup: all ${#packages[@]} packages present"
  exit 0
fi

SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
echo "setup: installing ${missing[*]}"
$SUDO apt-get update -qq
DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
