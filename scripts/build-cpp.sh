#!/usr/bin/env bash
# Build examples/cpp_robot (the C++ client of trace-recorder) into build/cpp_robot with
# Debian's CMake and g++. Installs them with apt-get only when missing and running as root.
set -euo pipefail
cd "$(dirname "$0")/.."
missing=()
command -v cmake >/dev/null || missing+=(cmake)
command -v g++ >/dev/null || missing+=(g++)
if ((${#missing[@]})); then
  if [[ $(id -u) -ne 0 ]]; then
    echo "build-cpp.sh: ${missing[*]} not installed; run: sudo apt-get install -y cmake g++" >&2
    exit 1
  fi
  apt-get update -qq && apt-get install -y -qq cmake g++ >/dev/null
fi
cmake -S examples/cpp_robot -B build/cpp_robot-cmake -DCMAKE_BUILD_TYPE=Release >/dev/null
cmake --build build/cpp_robot-cmake --parallel 2 >/dev/null
cp build/cpp_robot-cmake/cpp_robot build/cpp_robot.tmp
mv build/cpp_robot.tmp build/cpp_robot
