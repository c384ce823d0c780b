#!/usr/bin/env bash
# Run every validation variant with `tether run` and with the fmpy reference,
# and compare the two result files with `tether compare` (docs/validation.md).
#
#   tools/fmpy_reference/validate.sh [TETHER_BINARY] [PYTHON]
#
# Defaults: target/release/tether and $TETHER_PYTHON (else python3). The FMUs
# must be packaged (cargo xtask fmus). Results go to target/validation/.
# Exits non-zero if any variant deviates beyond its tolerance, or if a variant
# expected to diverge does not stop (in both hosts).
set -euo pipefail
cd "$(dirname "$0")/../.."
tether=${1:-target/release/tether}
python=${2:-${TETHER_PYTHON:-python3}}
out=target/validation
mkdir -p "$out"
summary=()
failed=0

# variant SYSTEM TAG EXPECT RTOL ATOL -- FLAGS...
# SYSTEM is a name in tests/validation/ or examples/. EXPECT is "completes" or
# "diverges" (both hosts must stop at the same step).
variant() {
  local system=$1 tag=$2 expect=$3 rtol=$4 atol=$5
  shift 6
  local a="$out/$tag-tether.csv" b="$out/$tag-fmpy.csv" sa=0 sb=0 file="tests/validation/$system.toml"
  [ -f "$file" ] || file="examples/$system.toml"
  "$tether" run "$file" "$@" --quiet --out "$a" 2>"$out/$tag-tether.err" || sa=$?
  "$python" tools/fmpy_reference "$file" "$@" --quiet --out "$b" 2>"$out/$tag-fmpy.err" || sb=$?
  if [ "$expect" = completes ] && { [ $sa -ne 0 ] || [ $sb -ne 0 ]; }; then
    echo "$tag: a run failed:" >&2; cat "$out/$tag-tether.err" "$out/$tag-fmpy.err" >&2
    failed=1; return
  fi
  if [ "$expect" = diverges ] && { [ $sa -eq 0 ] || [ $sb -eq 0 ]; }; then
    echo "$tag: expected both runs to stop as diverged" >&2
    failed=1; return
  fi
  local report
  if report=$("$tether" compare "$a" "$b" --rtol "$rtol" --atol "$atol" 2>&1); then
    :
  else
    echo "$report" >&2; failed=1
  fi
  local rows dev
  rows=$(grep -c -v '^#' "$b")
  dev=$(echo "$report" | sed -n 's/.*largest relative deviation \([^ ]*\).*/\1/p')
  if [ "$atol" != 0 ]; then
    # The largest relative deviation of the columns that deviate by more than
    # atol (the others, such as a residual of 1e-5, pass on atol), and where.
    dev=$(echo "$report" | awk -v atol="$atol" '
      NF == 6 && ($6 == "yes" || $6 == "no") && $2 + 0 > atol + 0 && $5 + 0 >= m { m = $5 + 0; c = $1 }
      END { if (c == "") print "0 (every column within atol)"; else printf "%.3e (%s)\n", m, c }')
  fi
  summary+=("$(printf '%-20s %-16s %5s rows  max relative deviation %-10s (rtol %s, atol %s)  %s' \
    "$tag" "$system" "$((rows - 1))" "${dev:-?}" "$rtol" "$atol" "$*")")
}

i1m1=(--method baumgarte --beta 2e-3 --gamma 1e-6)
i2m1=(--method baumgarte --beta 2e-3)
i3m1=(--method baumgarte --beta 0 --gamma 0)
i1m2=(--method weighted --a 1 --b 1)
i2m2=(--method weighted --a 1)
i3m2=(--method weighted --a 0 --b 0)

# The paper's oscillator: single multiplier, tolerance 1e-9 relative.
variant oscillator m1-index1-k0 completes 1e-9 0 -- "${i1m1[@]}" --order 0
variant oscillator m1-index2-k0 completes 1e-9 0 -- "${i2m1[@]}" --order 0
variant oscillator m1-index3-k0 completes 1e-9 0 -- "${i3m1[@]}" --order 0
variant oscillator m2-index1-k0 completes 1e-9 0 -- "${i1m2[@]}" --order 0
variant oscillator m2-index2-k0 completes 1e-9 0 -- "${i2m2[@]}" --order 0
variant oscillator m2-index3-k0 completes 1e-9 0 -- "${i3m2[@]}" --order 0
variant oscillator m1-index1-k1 completes 1e-9 0 -- "${i1m1[@]}" --order 1
variant oscillator m2-index1-k1 completes 1e-9 0 -- "${i1m2[@]}" --order 1
variant oscillator m1-index1-k2 completes 1e-9 0 -- "${i1m1[@]}" --order 2
variant oscillator explicit completes 1e-9 0 -- --method explicit --mu 1e-2
# Unstable at H = 1e-3 (docs/algorithm.md): both hosts stop at the same step.
variant oscillator m1-index2-k1 diverges 1e-9 0 -- "${i2m1[@]}" --order 1
variant oscillator m1-index3-k1 diverges 1e-9 0 -- "${i3m1[@]}" --order 1
variant oscillator m2-index2-k1 diverges 1e-9 0 -- "${i2m2[@]}" --order 1
variant oscillator m2-index3-k1 diverges 1e-9 0 -- "${i3m2[@]}" --order 1
variant oscillator m2-index1-k2 diverges 1e-9 0 -- "${i1m2[@]}" --order 2
# Two coupled multipliers (2x2 Jacobian, off-diagonal entries).
variant chain chain-m1-index2-k0 completes 1e-9 0 -- "${i2m1[@]}" --order 0
variant chain chain-m1-index1-k0 completes 1e-9 0 -- "${i1m1[@]}" --order 0
variant chain chain-m2-index1-k1 completes 1e-9 0 -- "${i1m2[@]}" --order 1
variant chain chain-explicit completes 1e-9 0 -- --method explicit --mu 1e-2

# Joints between marker ports (docs/joints.md), over a short time: the link
# FMUs take 8 internal steps per macro step and fmpy is slow.
variant double_pendulum dp-m1-index1-k0 completes 1e-9 0 -- "${i1m1[@]}" --order 0 --stop 0.2
variant double_pendulum dp-m2-index1-k0 completes 1e-9 0 -- "${i1m2[@]}" --order 0 --stop 0.2
variant slider_crank sc-m1-index2-k0 completes 1e-9 0 -- "${i2m1[@]}" --gamma 0 --order 0 --stop 0.2
variant slider_crank sc-m2-index2-k0 completes 1e-9 0 -- "${i2m2[@]}" --order 0 --stop 0.2
variant slider_crank sc-m1-index1-k1 completes 1e-9 0 -- "${i1m1[@]}" --order 1 --stop 0.2
# The paper's style: multipliers as FMU inputs, and a [[coupling_variable]].
variant pendulum_paper pp-m1-index1-k0 completes 1e-9 0 -- "${i1m1[@]}" --order 0
variant pendulum_paper pp-m2-index1-k1 completes 1e-9 0 -- "${i1m2[@]}" --order 1
variant pendulum_paper pp-explicit completes 1e-9 0 -- --method explicit --mu 1e-2
# Beyond the paper (docs/algorithm.md): iterated correction, adaptive macro
# steps (the same error estimate and PI controller, so the same time grid) and
# Jacobian reuse (the same rule and sparse Broyden updates).
variant oscillator m1-index1-k0-iter3 completes 1e-9 0 -- "${i1m1[@]}" --order 0 --iterations 3
variant oscillator m1-index3-k0-iter5 completes 1e-9 0 -- "${i3m1[@]}" --order 0 --iterations 5
variant oscillator m1-index2-k0-adaptive completes 1e-9 0 -- "${i2m1[@]}" --order 0 --step-rtol 1e-4 --step-atol 1e-4
variant oscillator m2-index1-k1-adaptive completes 1e-9 0 -- "${i1m2[@]}" --order 1 --step-rtol 1e-5 --step-atol 1e-5
variant oscillator m1-index1-k2-adaptive completes 1e-9 0 -- "${i1m1[@]}" --order 2 --step-rtol 1e-4 --step-atol 1e-4
variant oscillator m1-index1-k0-reuse completes 1e-9 0 -- "${i1m1[@]}" --order 0 --jacobian reuse
variant double_pendulum dp-adaptive-reuse-iter2 completes 1e-9 0 -- "${i1m1[@]}" --order 1 --stop 0.2 --step-rtol 1e-5 --step-atol 1e-5 --jacobian reuse --iterations 2
variant slider_crank sc-adaptive-reuse completes 1e-9 0 -- "${i2m1[@]}" --gamma 0 --order 0 --stop 0.2 --step-rtol 1e-4 --step-atol 1e-4 --jacobian reuse
variant slider_crank sc-reuse completes 1e-9 0 -- "${i2m1[@]}" --gamma 0 --order 0 --stop 0.2 --jacobian reuse
# A loose tolerance over the dead centres: corrections the reused Jacobian
# mispredicted are made again with a fresh one before the step is accepted.
variant slider_crank sc-adaptive-reuse-loose completes 1e-9 0 -- "${i2m1[@]}" --gamma 0 --order 0 --step-rtol 1e-2 --step-atol 1e-2 --jacobian reuse
# A sparse Jacobian pattern (links a and c share no instance): the sparse
# Broyden update on the stored entries only.
variant chain4 chain4-reuse completes 1e-9 0 -- "${i2m1[@]}" --order 0 --jacobian reuse
variant chain4 chain4-adaptive-reuse completes 1e-9 0 -- "${i2m1[@]}" --order 0 --stop 0.2 --step-rtol 1e-4 --step-atol 1e-4 --jacobian reuse

# Every 3D joint kind but the two elementary ones alone (body3d FMUs; each
# example's own method, Method 1 index 2).
for kind in revolute universal cylindrical translational planar inline orientation; do
  variant "3d_$kind" "3d-$kind" completes 1e-9 0 -- --stop 0.1
done

# Signal connections (docs/algorithm.md, "Signal connections"), bit for bit
# (rtol = atol = 0). A control loop through direct feedthrough (PI controller
# and plant, loop gain 0.5): solved at T_0 in initialization mode, closed at
# the macro points under Gauss-Seidel (examples/control_loop.toml) and Jacobi;
# with k = 1 the plant takes the interpolated (Gauss-Seidel) or extrapolated
# (Jacobi, unstable in the loop: both hosts stop at the same step) inputs.
variant control_loop loop-gs completes 0 0 --
variant control_loop_jacobi loop-jacobi completes 0 0 --
variant control_loop loop-gs-k1 completes 0 0 -- --order 1
variant control_loop_jacobi loop-jacobi-k1 diverges 0 0 -- --order 1
# Loop gain 2: the sweeps at T_0 diverge and Newton solves the loop; closed at
# the macro points the loop is unstable and both hosts stop at the same step.
variant control_loop_gain2 loop-gain2 diverges 0 0 --
# Signals with a constraint (a controller without rollback on the paper's
# rigid pair, Jacobi, k = 1), and with adaptive steps whose rejected tries roll
# back the instance the Gauss-Seidel sweep stepped.
variant controlled_oscillator signals-ctrl completes 0 0 --
variant driven_oscillator signals-adaptive completes 0 0 --
# Iterated signal steps ([signals] iterations): the control loop with a PI
# controller that can roll back, each macro step repeated from the saved states
# until the exchanged values agree (Jacobi and Gauss-Seidel fixed point, Newton;
# k = 0 and k = 1), at most 2 repetitions (no step converges, the last stands;
# with strict = true both hosts fail the first step), and a rigid pair whose
# controller's signals are iterated around the predictor/corrector step.
variant loop_iterated_jacobi loop-iter-jacobi completes 0 0 --
variant loop_iterated_gauss_seidel loop-iter-gs completes 0 0 --
variant loop_newton loop-newton completes 0 0 --
variant loop_iterated_jacobi loop-iter-jacobi-k1 completes 0 0 -- --order 1
variant loop_iterated_gauss_seidel loop-iter-gs-k1 completes 0 0 -- --order 1
variant loop_newton loop-newton-k1 completes 0 0 -- --order 1
variant loop_iterated_2 loop-iter-2 completes 0 0 --
variant loop_iterated_strict loop-iter-strict diverges 0 0 --
variant controlled_oscillator_newton signals-ctrl-newton completes 0 0 --
variant controlled_oscillator_gauss_seidel signals-ctrl-iter-gs completes 0 0 --
variant controlled_oscillator_newton signals-ctrl-newton-explicit completes 0 0 -- --method explicit --mu 1e-2 --order 0

# FMI 3.0: the workspace FMUs built as FMI 3.0 (docs/fmu-kit.md), alone and mixed
# with FMI 2.0 in one system; deviation exactly 0 (rtol = atol = 0). At k = 1 the
# FMI 3.0 instances take the polynomials through the intermediate update callback
# (the constraint's multiplier, and the control loop's signal).
variant oscillator_fmi3 fmi3-m1-index1-k0 completes 0 0 -- "${i1m1[@]}" --order 0
variant oscillator_fmi3 fmi3-m1-index1-k1 completes 0 0 -- "${i1m1[@]}" --order 1
variant mixed_fmi3 fmi3-mixed-m1-index1-k1 completes 0 0 -- "${i1m1[@]}" --order 1
variant control_loop_fmi3 fmi3-loop-gs-k1 completes 0 0 -- --order 1
variant oscillator_fmi3 fmi3-m2-index2-k0 completes 0 0 -- "${i2m2[@]}" --order 0
variant mixed_fmi3 fmi3-mixed-m1-index1-k0 completes 0 0 -- "${i1m1[@]}" --order 0
variant double_pendulum_fmi3 fmi3-dp-m1-index1-k0 completes 0 0 -- "${i1m1[@]}" --order 0 --stop 0.2
variant control_loop_fmi3 fmi3-loop-gs completes 0 0 --

# Model-exchange instances (docs/validation.md, "Model-exchange instances"):
# Tether integrates them with its rk45, the reference with fmpy's CVode (BDF),
# both at rtol 1e-12 and restarted at every step. Not bit for bit: the two
# integrators' errors, 1e-12 per step, add up to about 1e-10 of the states over
# 1000 steps, and the finite-difference interface Jacobian divides the
# difference of two runs' integration errors by G*du, so the multipliers (and
# the accelerations they drive) deviate more, most at index 3 (position level,
# the smallest G). Each rtol is the power of ten at least 2.5 times the
# measured deviation (in the comment: the largest over x, v, a and lambda,
# relative to the column's scale); atol 1e-8 bounds the residual link.g (in
# metres), which is integration noise of 1e-11 to 4e-9 beside positions of 3.
variant oscillator_me me-m1-index1-k0 completes 1e-5 1e-8 -- "${i1m1[@]}" --order 0 # 1.7e-6 (lambda)
variant oscillator_me me-m1-index2-k0 completes 1e-5 1e-8 -- "${i2m1[@]}" --order 0 # 3.8e-6
variant oscillator_me me-m1-index3-k0 completes 1e-4 1e-8 -- "${i3m1[@]}" --order 0 # 2.5e-5
variant oscillator_me me-m2-index1-k0 completes 1e-5 1e-8 -- "${i1m2[@]}" --order 0 # 9.3e-7
variant oscillator_me me-m2-index2-k0 completes 1e-5 1e-8 -- "${i2m2[@]}" --order 0 # 3.8e-6
variant oscillator_me me-m2-index3-k0 completes 1e-4 1e-8 -- "${i3m2[@]}" --order 0 # 2.5e-5
variant oscillator_me me-m1-index1-k1 completes 1e-6 1e-8 -- "${i1m1[@]}" --order 1 # 2.3e-7
variant oscillator_me me-m2-index1-k1 completes 1e-5 1e-8 -- "${i1m2[@]}" --order 1 # 1.8e-6
variant oscillator_me me-m1-index1-k2 completes 1e-6 1e-8 -- "${i1m1[@]}" --order 2 # 3.7e-8
# Unstable (the paper's index 3 with k = 1, index 2 with k = 1; Method 2
# index 1 with k = 2): both hosts stop at the same step, for the same reason
# (diverged at t = 0.018; the constraint broken at t = 0.12 and 0.162).
# The instability amplifies the integrators' difference on the way (up to
# 2e-2 at the last row), so the tolerance is loose: what is checked is where
# and why the runs stop.
variant oscillator_me me-m1-index3-k1 diverges 1e-1 1e-5 -- "${i3m1[@]}" --order 1 # 2.6e-4, 18 rows
variant oscillator_me me-m1-index2-k1 diverges 1e-1 1e-5 -- "${i2m1[@]}" --order 1 # 1.9e-2, 120 rows
variant oscillator_me me-m2-index1-k2 diverges 1e-1 1e-5 -- "${i1m2[@]}" --order 2 # 1.6e-2, 162 rows
# Adaptive steps: rejected tries roll the model-exchange instances back. Both
# hosts accept 675 steps and reject 9, but the step sizes follow the error
# estimates, which the integrators move a little: the grids differ by up to
# 1.3e-5 s and compare interpolates (lambda 7.6e-6, link.g 4.3e-8 m).
variant oscillator_me me-m1-index2-k0-adaptive completes 1e-4 1e-7 -- "${i2m1[@]}" --order 0 --step-rtol 1e-4 --step-atol 1e-4 # 7.6e-6
# The FMI 3.0 build's model exchange (fmpy's FMU3Model), k = 1: the same
# numbers as the FMI 2.0 build's in each host.
variant oscillator_me_fmi3 me-fmi3-m1-index1-k1 completes 1e-6 1e-8 -- "${i1m1[@]}" --order 1 # 2.3e-7
# The explicit method takes no finite-difference Jacobian through the steps:
# what is left is the integrators' own difference.
variant oscillator_me me-explicit completes 1e-8 1e-8 -- --method explicit --mu 1e-2 # 4.4e-10
# fmi_type = "auto" on edited copies of the oscillator FMU: mass 1's
# co-simulation interface lacks canGetAndSetFMUstate, mass 2's FMU has no
# co-simulation; both hosts take model exchange for both masses under
# Method 1 (the numbers of me-m1-index1-k0), and under the explicit method,
# which needs no rollback, keep co-simulation for mass 1.
"$python" tools/fmpy_reference/auto_fmus.py target/fmus/oscillator.fmu "$out/auto"
variant oscillator_auto auto-m1-index1-k0 completes 1e-5 1e-8 -- "${i1m1[@]}" --order 0 # 1.7e-6
variant oscillator_auto auto-explicit completes 1e-8 1e-8 -- --method explicit --mu 1e-2 # 3.6e-10
# The double pendulum on the link FMU's model exchange: 1.7e-6 and 1.5e-6
# (the acceleration of link 1's end B); link1.A.a, the pinned end's, is
# rounding noise of 1e-16 and passes on atol.
variant double_pendulum_me me-dp-m1-index1-k0 completes 1e-5 1e-8 -- "${i1m1[@]}" --order 0 --stop 0.2
variant double_pendulum_me me-dp-m2-index1-k0 completes 1e-5 1e-8 -- "${i1m2[@]}" --order 0 --stop 0.2
# Signal connections into and out of model-exchange instances (the control
# loop with the source and the plant on the lti FMU's model exchange, k = 0):
# no finite-difference Jacobian, so the integrators' difference alone, 1.7e-9
# (controller.u); at k = 1 each input follows its own polynomial in both
# hosts: 1.5e-9.
variant control_loop_me me-loop-gs completes 1e-8 1e-10 -- # 1.7e-9
variant control_loop_me me-loop-gs-k1 completes 1e-8 1e-10 -- --order 1 # 1.5e-9
# [signals] iterations (Newton) with every instance on model exchange: each
# repetition of a macro step rolls them back: 3.4e-10 (controller.y).
variant loop_newton_me me-loop-newton completes 1e-9 1e-10 -- # 3.4e-10
# State events: the Reference FMUs' BouncingBall alone (each bounce located by
# each host's own event detection, rtol 1e-10): 5.4e-7 (ball.v after a bounce).
variant bouncing_ball_me me-bouncing-ball completes 1e-5 1e-8 -- # 5.4e-7

printf '%s\n' "${summary[@]}"
exit $failed
