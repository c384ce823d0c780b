#!/usr/bin/env bash
# Installs the `tether` Python package (crates/tether-py) into PYTHON's
# environment (default: python3), with the runtime library that
# `tether.export_fmu` writes into exported FMUs and the host program
# (`tether-fmi-host`) an exported FMU carries for its isolated members, as
# package data.
#
# The workspace is compiled once: maturin (pip's build backend) builds the
# extension module with everything it depends on, the runtime library's crate
# included; then cargo builds the runtime library and the host program from
# that target folder with the same features and pyo3 configuration, which
# links them and compiles nothing again. The two programs are added to the
# wheel, and pip installs it.
#
# Nothing is written into the source tree: the build goes to
# $CARGO_TARGET_DIR, else to the checkout's target/ when it can be written,
# else to ~/.cache/tether/target (a read-only checkout); the wheel to a
# temporary folder.
# Usage: tools/install-python.sh [extra pip arguments]
set -euo pipefail
src="$(cd "$(dirname "$0")/.." && pwd)"
python="${PYTHON:-python3}"
if [ -n "${CARGO_TARGET_DIR:-}" ]; then
    target="$CARGO_TARGET_DIR"
elif [ -w "$src" ] && { [ ! -e "$src/target" ] || [ -w "$src/target" ]; }; then
    target="$src/target"
else
    target="${XDG_CACHE_HOME:-$HOME/.cache}/tether/target"
    echo "install-python: $src cannot be written: building in $target"
fi
mkdir -p "$target"
export CARGO_TARGET_DIR="$target"
# pyo3 reads the interpreter in its build script: the same one for both builds.
PYO3_PYTHON="$("$python" -c 'import sys; print(sys.executable)')"
export PYO3_PYTHON
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
start=$SECONDS
verbose=-v
for arg in "$@"; do
    case "$arg" in -q|--quiet) verbose= ;; esac
done
echo "install-python: compiling the workspace once (a few minutes on 2 cores the first time)"
MATURIN_PEP517_ARGS="--locked" "$python" -m pip wheel --disable-pip-version-check $verbose \
    --no-deps --wheel-dir "$work/wheel" "$src/crates/tether-py"
# maturin's pyo3 configuration for this interpreter: with it cargo finds pyo3
# and the extension module built.
version="$("$python" -c 'import sys; print("%d.%d" % sys.version_info[:2])')"
config=("$target"/maturin/pyo3-config-*-"$version"-abi3.txt)
if [ -f "${config[0]}" ]; then
    export PYO3_CONFIG_FILE="${config[0]}"
fi
cargo build --release --locked --manifest-path "$src/Cargo.toml" \
    -p tether-py -p tether-fmu-export -p tether-fmi-host \
    --features tether-py/extension-module
wheel="$(ls "$work"/wheel/tether-*.whl)"
"$python" - "$wheel" "$target/release/libtether_fmu_export.so" "$target/release/tether-fmi-host" <<'PY'
"""Adds files to a wheel's `tether/` package, with their RECORD lines."""
import base64, hashlib, os, shutil, sys, tempfile, zipfile

wheel, extra = sys.argv[1], sys.argv[2:]
fd, tmp = tempfile.mkstemp(suffix=".whl", dir=os.path.dirname(wheel))
os.close(fd)
with zipfile.ZipFile(wheel) as old, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as new:
    record = next(n for n in old.namelist() if n.endswith(".dist-info/RECORD"))
    lines = old.read(record).decode().splitlines()
    for item in old.infolist():
        if item.filename != record:
            new.writestr(item, old.read(item.filename))
    for path in extra:
        name = "tether/" + os.path.basename(path)
        data = open(path, "rb").read()
        info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
        info.external_attr = 0o755 << 16
        info.compress_type = zipfile.ZIP_DEFLATED
        new.writestr(info, data)
        digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
        lines.insert(len(lines) - 1, f"{name},sha256={digest},{len(data)}")
    new.writestr(record, "\n".join(lines) + "\n")
shutil.move(tmp, wheel)
PY
# Its dependencies (numpy), then the package itself, replacing an installed one.
"$python" -m pip install --disable-pip-version-check "$@" "$wheel"
"$python" -m pip install --disable-pip-version-check --force-reinstall --no-deps "$@" "$wheel"
echo "install-python: tether installed into $("$python" -c 'import sys; print(sys.prefix)') in $((SECONDS - start)) s"
