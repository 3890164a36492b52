#!/usr/bin/env bash
# Installs every Debian 12 package Specula builds, tests and runs with (clang-15 and
# libfuzzer-15-dev: the asan preset, which also builds the fuzzers; lld: the CI presets link with it).
# Idempotent: a fast no-op when everything is present.
set -euo pipefail

# What the build, the tests and the demo use (the Vulkan backend runs on Mesa's lavapipe where
# there is no GPU; the editor and the games present through GLFW and Dear ImGui, and their
# windowed tests run under Xvfb).
packages=(
  build-essential cmake ninja-build pkg-config
  libembree-dev libtbb-dev libglm-dev libopenmesh-dev
  libtinygltf-dev libstb-dev nlohmann-json3-dev libcli11-dev
  libopenexr-dev
  libvulkan-dev mesa-vulkan-drivers glslang-tools
  libglfw3-dev libimgui-dev xvfb xauth
  libgtest-dev
  clang-15 libfuzzer-15-dev
  lld
  assimp-testmodels
)

missing=()
for p in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$p")
  fi
done

if [ ${#missing[@]} -eq 0 ]; then
  exit 0
fi

echo "deps.sh: installing ${missing[*]}"
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
