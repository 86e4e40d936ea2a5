#!/usr/bin/env bash
# Installs every Debian 12 package evloc needs to build, test and run.
# Idempotent: packages already present are skipped; nothing is installed with recommends.
# Usage: scripts/install-deps.sh [--check]   (--check only lists what is missing; exit 1 if any)
set -euo pipefail

PACKAGES=(
  # toolchain
  build-essential cmake ninja-build pkg-config ccache git clang clang-format libclang-rt-14-dev
  # core libraries
  libeigen3-dev libopencv-dev libyaml-cpp-dev nlohmann-json3-dev libhdf5-dev libsqlite3-dev
  # ROS1 bag chunks (bz2, lz4); AEDAT4 packets (flatbuffers, lz4, zstd) and its schema compiler
  libbz2-dev liblz4-dev libflatbuffers-dev flatbuffers-compiler libzstd-dev
  # the CRC-32 of evloc's own event files (.evb)
  zlib1g-dev
  # mapping
  colmap libceres-dev libpcl-dev
  # geo-reference (core/geo: WGS84, ECEF, ENU) and the GNSS tags of photos (mapper --geo-exif;
  # exiv2: the command line checks the tags the tests write)
  libgeographiclib-dev libexiv2-dev exiv2
  # plumbing libraries: logging (spdlog, with fmt) and the tools' command lines (CLI11)
  libspdlog-dev libcli11-dev
  # service
  libgrpc++-dev libprotobuf-dev protobuf-compiler protobuf-compiler-grpc
  # token digests (SHA-256, CRYPTO_memcmp) and TLS file checks: OpenSSL libcrypto
  libssl-dev
  # the HTTP server of --metrics and --viewer (localizer/service/http_server.h)
  libcpp-httplib-dev
  # the live viewer's browser test (headless Chromium driven by Selenium, docs/viewer.md)
  chromium chromium-driver python3-selenium
  # tests and benchmarks
  libgtest-dev libgmock-dev libbenchmark-dev
  # the Python package (python/: bindings, client, pytest tests) and its example
  python3 python3-grpcio python3-protobuf python3-numpy python3-dev pybind11-dev
  python3-pytest python3-venv python3-pip python3-setuptools python3-wheel
  # an independent writer of DSEC HDF5 files for the package's reader tests
  python3-h5py
  # the independent writer of the bag tests (core/events/testing/write_test_bags.py)
  python3-rosbag python3-roslz4 python3-pil
  # the independent writer of the AEDAT4 tests (core/events/testing/write_test_aedat4.py)
  python3-flatbuffers python3-lz4 python3-zstandard
  # the ROS 1 node (ros/, docs/ros.md): roscpp and tf2_ros, the message definitions and Debian's
  # gencpp (the node's message headers are generated from ros/msg at build time); its test runs
  # roscore, roslaunch and rosbag play and listens with rospy
  # (libsensor-msgs-dev: the C++ header of sensor_msgs/CameraInfo; nothing else pulls it in)
  libroscpp-dev libtf2-ros-dev libsensor-msgs-dev python3-gencpp python3-genmsg ros-std-msgs
  ros-sensor-msgs ros-geometry-msgs python3-roslaunch python3-rospy python3-std-msgs
  python3-sensor-msgs python3-geometry-msgs python3-tf2-msgs python3-rostopic
  # TLS test certificates
  openssl
  # the service capacity plot (scripts/plot-capacity.py, docs/benchmarks.md)
  python3-matplotlib
)

# npm vendors three.js for the live viewer (scripts/build-viewer.sh); a machine that has npm from
# another Node.js distribution keeps it (Debian's npm would conflict with that nodejs).
if ! command -v npm >/dev/null 2>&1; then
  PACKAGES+=(npm)
fi

missing=()
for pkg in "${PACKAGES[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$pkg" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$pkg")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "install-deps: all ${#PACKAGES[@]} packages are installed."
  exit 0
fi

if [[ "${1:-}" == "--check" ]]; then
  echo "install-deps: missing packages: ${missing[*]}"
  exit 1
fi

echo "install-deps: installing ${#missing[@]} missing packages: ${missing[*]}"

if ! command -v apt-get >/dev/null 2>&1; then
  echo "install-deps: error: apt-get not found. evloc's install script supports Debian 12 (bookworm)." >&2
  echo "  Install these packages with your system's package manager: ${missing[*]}" >&2
  exit 2
fi

SUDO=""
if [[ "$(id -u)" -ne 0 ]]; then
  if command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    SUDO="sudo"
  else
    echo "install-deps: error: installing packages needs root (you are $(id -un))." >&2
    echo "  Run as root, or: sudo $0" >&2
    exit 2
  fi
fi

export DEBIAN_FRONTEND=noninteractive
# A fresh machine has no package lists; refresh them when apt cannot see the first missing package.
if ! apt-cache show "${missing[0]}" >/dev/null 2>&1 || [[ -z "$(ls -A /var/lib/apt/lists 2>/dev/null | grep -v lock)" ]]; then
  $SUDO apt-get update -q || { echo "install-deps: error: 'apt-get update' failed (network or sources.list?)" >&2; exit 2; }
fi
if ! $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"; then
  echo "install-deps: error: 'apt-get install' failed for: ${missing[*]}" >&2
  echo "  Check the messages above (package not found in this release, disk full, dpkg lock held)." >&2
  exit 2
fi
echo "install-deps: done."
