#!/usr/bin/env bash
# Installs the `tether` Python package (crates/tether-py) into PYTHON's
# environment (default: python3), with the runtime library that
# `tether.export_fmu` writes into exported FMUs as package data: the library
# is built with the wheel's profile, copied into the package's folder while
# maturin builds the wheel (it must not be git-ignored: maturin leaves
# git-ignored files out of a wheel) and removed again afterwards.
# Usage: tools/install-python.sh [extra pip arguments]
set -euo pipefail
cd "$(dirname "$0")/.."
python="${PYTHON:-python3}"
cargo build --profile wheel -p tether-fmu-export
target="${CARGO_TARGET_DIR:-target}"
copy=crates/tether-py/python/tether/libtether_fmu_export.so
cp "$target/wheel/libtether_fmu_export.so" "$copy"
trap 'rm -f "$copy"' EXIT
"$python" -m pip install --disable-pip-version-check "$@" ./crates/tether-py
