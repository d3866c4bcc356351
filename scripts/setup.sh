#!/usr/bin/env bash
# Installs what pointlens needs on Debian 12 / Ubuntu, once: the Vulkan
# loader, lavapipe and the validation layer, the shaderc build tools, and a
# current Rust through rustup when the system's is older than 1.88.
# Sourced by scripts/pointlens and scripts/test; safe to run again.
set -euo pipefail

PACKAGES=(mesa-vulkan-drivers vulkan-validationlayers libvulkan-dev vulkan-tools
          cmake ninja-build python3 g++ curl ca-certificates ffmpeg)

as_root() {
    if [ "$(id -u)" = 0 ]; then "$@"; else sudo "$@"; fi
}

missing=()
for p in "${PACKAGES[@]}"; do
    dpkg -s "$p" >/dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "pointlens setup: installing ${missing[*]}" >&2
    as_root apt-get update -qq
    as_root env DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${missing[@]}" >&2
fi

rust_ok() {
    command -v cargo >/dev/null 2>&1 || return 1
    local v
    v=$(rustc --version | awk '{print $2}')
    [ "$(printf '%s\n1.88.0\n' "$v" | sort -V | head -n1)" = "1.88.0" ]
}
[ -f "$HOME/.cargo/env" ] && . "$HOME/.cargo/env"
if ! rust_ok; then
    if command -v rustup >/dev/null 2>&1; then
        rustup toolchain install stable --profile default >&2
        rustup default stable >&2
    else
        echo "pointlens setup: installing Rust with rustup (https://rustup.rs)" >&2
        curl --proto "=https" --tlsv1.2 -sSf https://sh.rustup.rs | sh -s -- -y --profile default >&2
    fi
    . "$HOME/.cargo/env"
fi

# One build cache outside the clone, shared by every checkout on this machine
# (shaderc is compiled from source once, about 10 minutes on 2 cores).
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/pointlens/target}"
mkdir -p "$CARGO_TARGET_DIR"
