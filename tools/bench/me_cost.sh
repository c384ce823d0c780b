#!/usr/bin/env bash
# Instructions a communication step of the kit's oscillator run alone through
# model exchange (Tether's rk45) and through its co-simulation build (Dop853
# inside the FMU), both at rtol 1e-10 and step 1e-3, counted by callgrind:
# `--stop 2` minus `--stop 1` over the 1000 steps between, so that loading
# and unpacking the FMU cancel out. See docs/fmi-import.md, "Cost".
#
#     tools/bench/me_cost.sh
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
cd "$root"
command -v valgrind >/dev/null || { echo "me_cost.sh: valgrind is not installed" >&2; exit 1; }
cargo build --release -q -p tether-cli
tether=target/release/tether
cargo xtask fmus >/dev/null
fmu=target/fmus/oscillator.fmu
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
count() { # stop, extra arguments...
    local stop=$1
    shift
    valgrind --tool=callgrind --callgrind-out-file="$work/cg.out" "$tether" simulate "$fmu" \
        --tolerance 1e-10 --step 1e-3 --stop "$stop" --out "$work/out.csv" "$@" 2>&1 |
        sed -n 's/.*Collected : \([0-9]*\).*/\1/p'
}
me=$(( $(count 2 --fmi-type model-exchange --integrator method=rk45) - $(count 1 --fmi-type model-exchange --integrator method=rk45) ))
cs=$(( $(count 2) - $(count 1) ))
echo "model exchange, rk45:      $(( me / 1000 )) instructions a step"
echo "co-simulation, Dop853:     $(( cs / 1000 )) instructions a step"
awk -v a="$me" -v b="$cs" 'BEGIN { printf "ratio:                     %.2f×\n", a / b }'
