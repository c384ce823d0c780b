#!/usr/bin/env bash
# Installs the `tether` Python package (crates/tether-py) into PYTHON's
# environment (default: python3), with the runtime library that
# `tether.export_fmu` writes into exported FMUs as package data, and the
# host program (`tether-fmi-host`) an exported FMU carries for its isolated
# members: both are built with the release profile (the wheel's), copied into the package's
# folder while maturin builds the wheel (they must not be git-ignored: maturin
# leaves git-ignored files out of a wheel) and removed again afterwards.
# Usage: tools/install-python.sh [extra pip arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
python="${PYTHON:-python3}"
cargo build --release -p tether-fmu-export -p tether-fmi-host
target="${CARGO_TARGET_DIR:-target}"
package=crates/tether-py/python/tether
cp "$target/release/libtether_fmu_export.so" "$target/release/tether-fmi-host" "$package/"
trap 'rm -f "$package/libtether_fmu_export.so" "$package/tether-fmi-host"' EXIT
"$python" -m pip install --disable-pip-version-check "$@" ./crates/tether-py
