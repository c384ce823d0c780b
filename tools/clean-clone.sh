#!/usr/bin/env bash
# Runs the README's three commands (run the oscillator, run all tests, install the
# Python package) in a fresh clone of this repository's committed HEAD, in an empty
# temporary folder with nothing beside it, and prints the wall time of each. It is
# how a new user meets the repository: nothing from this work tree (no target/, no
# shared/ folder beside it) is used, only the crates.io and PyPI caches.
#
# Usage: tools/clean-clone.sh [run] [test] [python]    (default: all three, in order)
#   KEEP=1 keeps the temporary folder (its path is printed at the end).
set -euo pipefail
src="$(cd "$(dirname "$0")/.." && pwd)"
steps=("$@")
[ ${#steps[@]} -gt 0 ] || steps=(run test python)

# The commands exactly as README.md shows them: the script fails if one drifts.
run_cmd='cargo tether run examples/oscillator.toml --out target/oscillator.csv'
test_cmd='cargo test --workspace --no-fail-fast'
python_cmd='tools/install-python.sh'
for cmd in "$run_cmd" "$test_cmd"; do
  grep -qxF "$cmd" "$src/README.md" || { echo "README.md no longer shows: $cmd" >&2; exit 1; }
done
grep -q "^$python_cmd " "$src/README.md" || { echo "README.md no longer shows: $python_cmd" >&2; exit 1; }

work="$(mktemp -d)"
if [ -z "${KEEP:-}" ]; then trap 'rm -rf "$work"' EXIT; fi
git clone --quiet --no-local "$src" "$work/tether"
cd "$work/tether"
# Nothing of this work tree's build may leak in.
unset CARGO_TARGET_DIR CARGO_BUILD_TARGET_DIR TETHER_PYTHON TETHER_BIN
echo "clone of $(git rev-parse --short HEAD) in $work/tether (nothing beside it: $(ls "$work"))"

timed() {
  local name="$1"; shift
  local start=$SECONDS
  echo "== $name: $*"
  if "$@"; then
    echo "== $name: passed in $((SECONDS - start)) s"
  else
    local code=$?
    echo "== $name: FAILED (exit $code) after $((SECONDS - start)) s"
    exit "$code"
  fi
}

for step in "${steps[@]}"; do
  case "$step" in
    run)
      timed run bash -c "$run_cmd"
      head -n 3 target/oscillator.csv ;;
    test)
      timed test bash -c "$test_cmd" ;;
    python)
      # The README installs into python3's pip; here into a virtualenv of the clone.
      python3 -m venv "$work/venv"
      timed python env PYTHON="$work/venv/bin/python" bash -c "$python_cmd --quiet"
      # The install writes nothing into the source tree (target/ is the build's).
      written="$(git status --porcelain --ignored | grep -v '^!! target/$' || true)"
      [ -z "$written" ] || { echo "the Python install wrote into the clone: $written" >&2; exit 1; }
      # The check below runs the oscillator example, whose FMUs `run` and `test` package.
      [ -f target/fmus/oscillator.fmu ] || cargo xtask fmus >/dev/null
      (cd "$work" && "$work/venv/bin/python" -c \
        'import tether; r = tether.run("tether/examples/oscillator.toml"); print("python: rows", len(r["time"]))') ;;
    *) echo "unknown step '$step' (run, test, python)" >&2; exit 2 ;;
  esac
done
[ -z "${KEEP:-}" ] || echo "kept: $work"
