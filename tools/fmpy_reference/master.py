"""The coupled run: consistent initial multipliers, the semi-implicit
predictor/corrector step (Schweizer & Lu 2015, Method 1 eq. 55-68, Method 2
eq. 71-76) and the explicit baseline, on the grid T_n = T_0 + n*H.

Written from docs/algorithm.md, independently of crates/tether-master.
"""

import copy
import math

import numpy as np

import polynomials as poly
import joints as jointkinds
import rows as rowkinds
from errors import RunError
from host import REAL, Host, Needs, describe
from linalg import solve
from signals import Signals


class Master:
    def __init__(self, system):
        self.system = system
        self.method = system.method
        self.k = system.order
        self.h = system.step
        self.t0 = system.start
        self.steps = system.macro_steps()
        self.control = None if system.step_control is None else Control(system)
        self.hosts = []
        stop = self.t0 + self.steps * self.h if self.control is None else system.stop
        try:
            for spec in system.instances:
                self.hosts.append(Host(spec, (self.t0, stop, system.tolerance), Needs.of(system, spec.name)))
            self._wire()
            self.signals = Signals(system, self.hosts)
            if self.control is not None and not self.unknowns:
                raise RunError(f"invalid step_control = {system.step_control['rtol']}: expected a system with "
                               f"constraints, joints or coupling variables: the error estimate is on the "
                               f"coupled quantities")
            if self.control is not None:
                # A rejected step rolls back every instance, signal-only ones too.
                for host in self.hosts:
                    for capability in ("canGetAndSetFMUstate", "canHandleVariableCommunicationStepSize"):
                        if not getattr(host.cs, capability):
                            role = "" if host.is_coupled() else \
                                "; a rejected step rolls back signal-only instances too"
                            raise RunError(f"instance '{host.name}' ({host.md.modelName}) does not declare "
                                           f"{capability}, which adaptive macro steps ([step_control]{role}) "
                                           f"needs")
            self.signals.check_rollback()
            for host in self.hosts:
                host.enter_initialization()
            # A loop's values at T_0 are solved in initialization mode.
            if self.signals.loops:
                self.signals.initialize()
            for host in self.hosts:
                host.exit_initialization()
            # Adaptive steps: a rejected try rolls back the instances the
            # Gauss-Seidel sweep stepped too, so it saves them first.
            self.signals.save = self.control is not None
        except Exception:
            self.close()
            raise
        self.levels = ["position"]
        if self.method.needs_velocity():
            self.levels.append("velocity")
        if self.method.needs_acceleration():
            self.levels.append("acceleration")
        # past[m] = [u_N, u_{N-1}, u_{N-2}]
        self.past = [[u.initial] * 3 if u.initial is not None else [0.0] * 3 for u in self.unknowns]
        self.n = 0
        self.jac = None  # the interface Jacobians, kept for Jacobian reuse
        self.pattern = None  # the Jacobians' structure, for the sparse Broyden update
        self.reuse = Reuse(system.jacobian_max_age) if system.jacobian == "reuse" else None
        self.states = None  # adaptive steps: the outputs the error estimate covers
        self.columns = [f"{h.name}.{v.name}" for h in self.hosts for v in h.recorded]
        self.columns += [u.column for u in self.unknowns]
        self.columns += [r.residual for r in self.rows if r.residual is not None]

    # -- set-up -----------------------------------------------------------------

    def _wire(self):
        """Resolve every row and unknown against the FMUs, with the checks of
        `tether run` (docs/system-file.md, "Checks before the run"). Unknowns
        and rows come in Tether's order: constraint multipliers, joint
        multipliers (one per condition), coupling variables, force ports."""
        self.rows, self.unknowns = [], []
        self.index = {h.name: s for s, h in enumerate(self.hosts)}
        self.refs = {}  # (instance, variable) -> (host index, value reference)
        for spec in self.system.constraints:
            row, unknown = rowkinds.from_constraint(spec)
            self.rows.append(row)
            self.unknowns.append(unknown)
        ports = {}  # (instance, input) -> PortRow draft, in order of appearance
        for spec in self.system.joints:
            joint = jointkinds.Joint(spec)
            for side in joint.sides:
                self._check_marker(joint.name, side)
            first = len(self.unknowns)
            owner = f"joint '{joint.name}'"
            for k in range(len(joint.conditions)):
                drives = []
                if spec.multipliers is not None:
                    drives = rowkinds.drives(joint.name, spec.multipliers[k], "multipliers")
                initial = None if spec.initial is None else spec.initial[k]
                self.unknowns.append(rowkinds.Unknown(f"{joint.name}.lambda[{k + 1}]", drives, initial, owner))
                self.rows.append(jointkinds.ConditionRow(joint, k))
            if spec.multipliers is None:
                for side, quantity, axis, component, loading in joint.port_components():
                    s = joint.sides[side]
                    name = f"{s.marker}.{quantity}[{axis + 1}]"
                    var = self.hosts[self.index[s.instance]].variables.get(name)
                    if var is None:
                        raise RunError(f"{owner} needs the force port {s.instance}.{name}, which instance "
                                       f"'{s.instance}' does not declare (docs/marker-ports.md)")
                    draft = ports.setdefault((s.instance, name), jointkinds.PortRow(None))
                    draft.contributions += [(joint, first, k, component) for k in loading]
        for spec in self.system.variables:
            m = len(self.unknowns)
            self.unknowns.append(rowkinds.Unknown(f"{spec.name}.value", rowkinds.drives(spec.name, spec.drives),
                                                  spec.initial, f"coupling variable '{spec.name}'"))
            self.rows.append(rowkinds.VariableRow(spec.name, m, spec.value))
        for (inst, name), row in ports.items():
            row.unknown = len(self.unknowns)
            self.unknowns.append(rowkinds.Unknown(f"{inst}.{name}", [(inst, name, 1.0, 0)], None,
                                                  f"the force port {inst}.{name}"))
            self.rows.append(row)
        for row, unknown in zip(self.rows, self.unknowns):
            for level in row.levels:
                for inst, var, order in row.reads(level):
                    s, v = self._lookup(unknown.owner, inst, var)
                    if v.causality != "output" or v.type not in REAL:
                        raise RunError(f"{inst}.{var} is {describe(v)}, but the {level} level of "
                                       f"{unknown.owner} needs a Real output")
                    host = self.hosts[s]
                    if order > host.cs.maxOutputDerivativeOrder:
                        raise RunError(f"instance '{inst}' ({host.md.modelName}) lacks a large enough "
                                       f"maxOutputDerivativeOrder, which der({inst}.{var}) in "
                                       f"{unknown.owner} needs")
                    host.add_output(v.valueReference, order)
            if not isinstance(row, rowkinds.LinearRow):
                continue
            needs = [("velocity", self.method.needs_velocity(), f"method {self.method.describe()}"),
                     ("acceleration", self.method.needs_acceleration(), f"method {self.method.describe()}")]
            if unknown.initial is None:
                needs.append(("acceleration", True,
                              "a consistent initial multiplier (or give `initial = <value>`)"))
            for level, needed, by in needs:
                if needed and level not in row.levels:
                    raise RunError(f"constraint '{row.name}' has no {level} expression, which {by} needs")
        for m, unknown in enumerate(self.unknowns):
            for inst, var, c, order in unknown.drives:
                s, v = self._lookup(unknown.owner, inst, var)
                if v.causality != "input" or v.type not in REAL or order != 0:
                    raise RunError(f"{inst}.{var} is {describe(v)}, but 'drives' of {unknown.owner} "
                                   f"needs a Real input")
                self.hosts[s].add_input(v.valueReference, m, c)
        self.owners = [[s for s, h in enumerate(self.hosts) if any(m == mm for _, terms in h.inputs
                                                                    for mm, _ in terms)]
                       for m in range(len(self.unknowns))]
        for host in self.hosts:
            if not host.is_coupled():
                continue
            if self.k > 0 and not host.can_interpolate():
                flag = "providesIntermediateUpdate" if host.fmi3 else "canInterpolateInputs"
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) lacks {flag}, "
                               f"which coupling polynomials of degree k = {self.k} need (use order = 0)")
            if self.k > 0 and any(not host.interpolates(vr) for vr, _ in host.inputs):
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) does not declare "
                               f"intermediateUpdate=\"true\" on its coupled inputs, which coupling "
                               f"polynomials of degree k = {self.k} need (use order = 0)")
            if self.method.kind != "explicit" and not host.cs.canGetAndSetFMUstate:
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) lacks canGetAndSetFMUstate, "
                               f"which the predictor/corrector method {self.method.kind} needs")

    def _check_marker(self, joint, side):
        """A marker needs all 24 Real outputs (docs/marker-ports.md)."""
        s = self.index.get(side.instance)
        if s is None:
            raise RunError(f"joint '{joint}' refers to unknown instance '{side.instance}'; "
                           f"instances are: {', '.join(self.index)}")
        variables = self.hosts[s].variables
        if side.names[0] not in variables:
            known = [n[: -len(".r[1]")] for n in variables if n.endswith(".r[1]")]
            hint = f"its markers are: {', '.join(known)}" if known else "it has no marker ports"
            raise RunError(f"joint '{joint}': instance '{side.instance}' has no marker '{side.marker}'; {hint}")
        for name in side.names:
            if name not in variables:
                raise RunError(f"instance '{side.instance}': marker '{side.marker}' lacks the output {name}")

    def _lookup(self, owner, inst, var):
        s = self.index.get(inst)
        if s is None:
            raise RunError(f"{owner} refers to unknown instance '{inst}'; "
                           f"instances are: {', '.join(self.index)}")
        v = self.hosts[s].variable(var)
        self.refs[(inst, var)] = (s, v.valueReference)
        return s, v

    def close(self):
        for host in self.hosts:
            host.close()
        self.hosts = []

    # -- evaluating rows -------------------------------------------------------------

    def _output(self, live=None, base=None):
        """output(instance, variable, order): the latest outputs of the hosts in
        `live` (all if None) and the `base` snapshot of the others. Joints keep
        their marker kinematics in `output.cache` (they depend on nothing else)."""

        def output(inst, var, order):
            s, vr = self.refs[(inst, var)]
            source = self.hosts[s].values if live is None or s in live else base[s]
            return source[(vr, order)]

        output.cache = {}
        return output

    def _pattern(self):
        """Per row and unknown: whether the master's sparse Jacobian stores the
        entry (its structure rule: rows reading an instance the unknown drives,
        rows reading the unknown itself, the joints on such instances with the
        port rows they load, and the joints loading those port rows)."""
        nu = len(self.rows)

        def instances(reads):
            return {self.refs[(i, v)][0] for i, v, _ in reads}

        def kind(row):
            if hasattr(row, "joint"):
                return "condition"
            return "port" if hasattr(row, "contributions") else "row"

        joints = []
        for row in self.rows:
            if kind(row) == "condition" and all(j is not row.joint for j in joints):
                joints.append(row.joint)
        pattern = [[False] * nu for _ in range(nu)]
        for m in range(nu):
            own = set(self.owners[m])
            rows = set()
            for r, row in enumerate(self.rows):
                if kind(row) == "row":
                    levels = getattr(row, "levels", ("position",))
                    if any(instances(row.reads(lv)) & own for lv in levels):
                        rows.add(r)
                    if getattr(row, "unknown", None) == m:
                        rows.add(r)
                elif kind(row) == "port":
                    if row.unknown == m or any(first + k == m for _, first, k, _ in row.contributions):
                        rows.add(r)
            touched = [j for j in joints if instances(j.reads()) & own]
            for r, row in enumerate(self.rows):
                if kind(row) == "port" and any(c[0] is j for c in row.contributions for j in touched):
                    rows.add(r)
            for r in list(rows):
                row = self.rows[r]
                if kind(row) == "port":
                    for c in row.contributions:
                        if all(c[0] is not j for j in touched):
                            touched.append(c[0])
            for r, row in enumerate(self.rows):
                if kind(row) == "condition" and any(row.joint is j for j in touched):
                    rows.add(r)
            for r in rows:
                pattern[r][m] = True
        return pattern

    def _value(self, row, level, u, live=None, base=None, output=None):
        return row.value(level, output or self._output(live, base), u)

    def _read_all(self):
        for host in self.hosts:
            host.read()

    def _snapshot(self):
        return [dict(h.values) for h in self.hosts]

    def _current(self):
        return [p[0] for p in self.past]

    def _apply_constant(self):
        jets = [poly.Jet(p[0]) for p in self.past]
        for host in self.hosts:
            host.apply(jets, 0)
        return jets

    # -- initial multipliers and the explicit method ------------------------------------

    def start(self):
        """Initial multipliers at T_0, then the first recorded point."""
        consistent = [m for m, u in enumerate(self.unknowns) if u.initial is None]
        mu = self.method.mu if self.method.kind == "explicit" else None
        # Signals at T_0 before and after the consistent multipliers, which may
        # depend on signal inputs and change outputs that senders read.
        self.signals.initialize()
        if consistent:
            for _ in range(2):  # Newton; the first step is exact for linear feedthrough
                self._feedthrough_newton(consistent, mu)
        self._apply_constant()
        self.signals.initialize()
        self._accept()
        if self.control is not None:
            self._find_states()

    def _residual(self, m, mu, u, live=None, base=None, output=None):
        """g'' (+ 2 g'/mu + g/mu^2 for the explicit method) of row m."""
        level = "acceleration" if mu is None else ("stabilised", mu)
        return self._value(self.rows[m], level, u, live, base, output)

    def _feedthrough_newton(self, unknowns, mu):
        """One Newton step on the residuals of `unknowns`, with W = d residual / du
        by finite differences of inputs read back without a step."""
        jets = self._apply_constant()
        self._read_all()
        base = self._snapshot()
        u = self._current()
        out = self._output()
        r0 = np.array([self._residual(m, mu, u, output=out) for m in unknowns])
        w = np.zeros((len(unknowns), len(unknowns)))
        eps = self.system.epsilon
        for col, m in enumerate(unknowns):
            delta = eps * max(abs(self.past[m][0]), 1.0)
            perturbed = list(jets)
            perturbed[m] = poly.Jet(jets[m].value + delta)
            up = list(u)
            up[m] = u[m] + delta
            live = set(self.owners[m])
            for s in live:
                self.hosts[s].apply(perturbed, 0)
                self.hosts[s].read()
            out = self._output(live, base)
            for row_i, r in enumerate(unknowns):
                w[row_i, col] = (self._residual(r, mu, up, live, base, out) - r0[row_i]) / delta
            for s in live:
                self.hosts[s].apply(jets, 0)
                self.hosts[s].values = dict(base[s])
        step = solve(w, r0, self.time(), "acceleration", self.system.max_condition)
        for i, m in enumerate(unknowns):
            self.past[m][0] -= float(step[i])

    def _explicit_step(self):
        self.signals.send(self.n, self.time(), self.h, None)
        self._explicit_method()
        self.signals.receive(self.time())

    def _explicit_method(self):
        """The explicit method's step, the signals sent."""
        t = self.time()
        for host in self.hosts:  # inputs hold u_N over the step
            if not host.stepped_ahead:
                host.do_step(t, self.h)
        self.n += 1
        self.past = [[p[0], p[0], p[1]] for p in self.past]
        self._feedthrough_newton(list(range(len(self.unknowns))), self.method.mu)
        self._apply_constant()
        self._accept()

    # -- the predictor/corrector step -------------------------------------------------------

    def _predictor_corrector_step(self):
        if self.control is None:
            self.signals.send(self.n, self.time(), self.h, None)
            self._try_step(self.time(), self.h, None)
            self.signals.receive(self.time())
            return
        c = self.control
        while True:
            remaining = c.stop - c.t
            last = c.h >= remaining or remaining - c.h < 1e-3 * c.h
            # A stop within two steps is reached in two equal ones (no sliver).
            halved = not last and remaining < 2.0 * c.h
            h = remaining if last else 0.5 * remaining if halved else c.h
            t_next = c.stop if last else c.t + h
            self.signals.send(self.n, c.t, h, tuple(c.past))
            error = self._try_step(c.t, h, tuple(c.past), t_next)
            nxt, accepted = c.next(h, error)
            if accepted:
                self.signals.receive(t_next)
                c.t = t_next
                c.past = [h, c.past[0]]
                c.h = max(c.h, nxt) if last or halved else nxt
                c.accepted += 1
                return
            c.rejected += 1
            if h <= c.h_min:
                raise RunError(f"adaptive macro steps: at t = {c.t} the local error estimate is {error:.2f} "
                               f"times the tolerance even at h_min = {c.h_min:e}")
            c.h = nxt

    def _try_step(self, t, h, steps, t_next=None):
        """One macro step over [t, t + h]; `steps` = the two step sizes before
        it on a variable grid (None: uniform). Returns the error norm with
        adaptive steps (a step above 1 is rolled back, not accepted)."""
        k, n = self.k, self.n
        # Start-up: N+1 points of history exist at T_N.
        degree_pred = min(k, n)
        degree_corr = min(k, n + 1)
        nu = len(self.unknowns)
        adaptive = self.control is not None
        if t_next is None:
            t_next = self.time_at(n + 1)
        if nu == 0:
            # Nothing to solve for (signal connections only): every instance
            # steps once (those the Gauss-Seidel sweep stepped have), and that
            # is the accepted point.
            for host in self.hosts:
                if not host.stepped_ahead:
                    host.do_step(t, h)
            self.n += 1
            self._accept()
            return None

        # Predictor: extrapolated polynomials (eq. 56-58). Instances the
        # Gauss-Seidel signal sweep stepped already are not stepped again.
        jets = [poly.predictor(self.past[m], degree_pred, h, steps) for m in range(nu)]
        u_pred = [jets[m].at(h) for m in range(nu)]
        for host in self.hosts:
            if not host.stepped_ahead:
                if host.is_coupled() or adaptive:
                    host.save_state()
                host.apply(jets, k)
                host.do_step(t, h)
            host.read()
        base = self._snapshot()
        out = self._output()
        g = {lv: np.array([self._value(r, lv, u_pred, output=out) for r in self.rows]) for lv in self.levels}

        # Perturbed predictors: column m of each level's Jacobian (eq. 59-64);
        # with Jacobian reuse only when due, and again when the reused one
        # mispredicted the correction (then the correction is made again).
        fresh = self.reuse is None or self.reuse.due(h, n <= k)
        while True:
            if fresh:
                self._jacobian(t, h, steps, jets, u_pred, base, g, degree_corr)
            corrected = self._correction(t, h, steps, u_pred, g, t_next, degree_corr)
            if self.reuse is None:
                break
            out = self._output()
            gc = {lv: [self._value(r, lv, corrected, output=out) for r in self.rows] for lv in self.levels}
            if self.pattern is None:
                self.pattern = self._pattern()
            missed = self.reuse.check(self.jac, self.levels, u_pred, corrected, g, gc)
            if fresh or not missed:
                break
            fresh = True

        error = None
        if adaptive:
            error = self._error_norm(base, degree_corr)
            if not error <= 1.0:
                for host in self.hosts:
                    host.restore_state()
                return error
            self._note_peaks()
        if self.reuse is not None:
            self.reuse.accepted(self.jac, self.pattern, self.levels)
        self.past = [[corrected[m], p[0], p[1]] for m, p in enumerate(self.past)]
        self.n += 1
        self._accept()
        return error

    def _jacobian(self, t, h, steps, jets, u_pred, base, g, degree_corr):
        """The interface Jacobians from one perturbed run per unknown."""
        nu = len(self.unknowns)
        jac = {lv: np.zeros((nu, nu)) for lv in self.levels}
        eps = self.system.epsilon
        for m in range(nu):
            delta = eps * max(abs(self.past[m][0]), 1.0)
            perturbed = list(jets)
            perturbed[m] = poly.through(u_pred[m] + delta, self.past[m], degree_corr, h, steps)
            up = list(u_pred)
            up[m] = u_pred[m] + delta
            live = set(self.owners[m])
            for s in sorted(live):
                host = self.hosts[s]
                host.restore_state()
                host.apply(perturbed, self.k)
                host.do_step(t, h)
                host.read()
            out = self._output(live, base)
            for lv in self.levels:
                for r, row in enumerate(self.rows):
                    jac[lv][r, m] = (self._value(row, lv, up, output=out) - g[lv][r]) / delta
        self.jac = jac
        if self.reuse is not None:
            self.reuse.made(h)

    def _correction(self, t, h, steps, u_pred, g, t_next, degree_corr):
        """The corrected unknowns and the corrector run, iterated as set."""
        jac = self.jac
        corrected = self._corrected(u_pred, g, jac, t_next)
        self._corrector(corrected, degree_corr, t, h, steps)
        # Iterated correction: g at the corrected point, the same Jacobian.
        for _ in range(self.system.iterations - 1):
            out = self._output()
            gc = {lv: np.array([self._value(r, lv, corrected, output=out) for r in self.rows])
                  for lv in self.levels}
            start = corrected
            corrected = self._corrected(start, gc, jac, t_next)
            self._corrector(corrected, degree_corr, t, h, steps)
            tol = self.system.iteration_tol
            if all(abs(u - f) <= tol * max(abs(u), 1.0) for u, f in zip(corrected, start)):
                break
        return corrected

    def _corrector(self, corrected, degree, t, h, steps):
        """Repeat the step with interpolation polynomials; read the outputs."""
        jets = [poly.through(corrected[m], self.past[m], degree, h, steps) for m in range(len(corrected))]
        for host in self.hosts:
            if host.is_coupled():
                host.restore_state()
                host.apply(jets, self.k)
                host.do_step(t, h)
                host.read()

    # -- adaptive steps: Milne's device on the states the levels read ----------------------------

    MILNE = (1.0 / 2.0, 1.0 / 6.0, 1.0 / 10.0)

    def _find_states(self):
        """The outputs whose change (relative 1e-6) changes a position- or
        velocity-level row the method uses, at the current point."""
        levels = [lv for lv in self.levels if lv in ("position", "velocity")]
        u = self._current()

        def rows():
            out = self._output()
            return [self._value(r, lv, u, output=out) for lv in levels for r in self.rows]

        reference = rows()
        self.states = []
        for s, host in enumerate(self.hosts):
            for key in list(host.outputs):
                y = host.values[key]
                host.values[key] = y + 1e-6 * max(abs(y), 1.0)
                changed = rows() != reference
                host.values[key] = y
                if changed:
                    self.states.append((s, key))
        self.peaks = {state: abs(self.hosts[state[0]].values[state[1]]) for state in self.states}

    def _error_norm(self, predicted, degree):
        c = self.control
        milne = self.MILNE[min(degree, 2)]
        worst = 0.0
        for state in self.states:
            s, key = state
            yp, yc = predicted[s][key], self.hosts[s].values[key]
            scale = c.atol + c.rtol * max(self.peaks[state], abs(yp), abs(yc))
            worst = max(worst, milne * abs(yp - yc) / scale)
        return worst

    def _note_peaks(self):
        for state in self.states:
            s, key = state
            self.peaks[state] = max(self.peaks[state], abs(self.hosts[s].values[key]))

    def _corrected(self, u_pred, g, jac, time):
        u_pred = np.array(u_pred)
        limit = self.system.max_condition
        m = self.method
        if m.kind == "baumgarte":
            # Eq. 68: u = u^p - (G + beta G' + gamma G'')^-1 (g + beta g' + gamma g'').
            a, b = jac["position"].copy(), g["position"].copy()
            if "velocity" in jac:
                a = a + m.beta * jac["velocity"]
                b = b + m.beta * g["velocity"]
            if "acceleration" in jac:
                a = a + m.gamma * jac["acceleration"]
                b = b + m.gamma * g["acceleration"]
            # Port and coupling-variable rows are not stabilised.
            for r, row in enumerate(self.rows):
                if row.algebraic:
                    a[r, :] = jac["position"][r, :]
                    b[r] = g["position"][r]
            level = "position" if len(self.levels) == 1 else "baumgarte"
            return [float(x) for x in u_pred - solve(a, b, time, level, limit)]
        # Eq. 73-76: each level on its own, averaged with weights 1, a, b.
        weights = {"position": 1.0, "velocity": m.a, "acceleration": m.b}
        total = 0.0
        acc = np.zeros(len(u_pred))
        for lv in self.levels:
            acc = acc + weights[lv] * (u_pred - solve(jac[lv], g[lv], time, lv, limit))
            total += weights[lv]
        return [float(x) for x in acc / total]

    # -- the run --------------------------------------------------------------------------

    def time(self):
        return self.time_at(self.n) if self.control is None else self.control.t

    def finished(self):
        return self.n >= self.steps if self.control is None else self.control.t >= self.control.stop

    def time_at(self, n):
        return self.t0 + n * self.h

    def _accept(self):
        for host in self.hosts:
            host.read()
            host.read_recorded()
        u = self._current()
        self.row = [x for host in self.hosts for x in host.recorded_values]
        self.row += u
        out = self._output()
        self.row += [self._value(r, "position", u, output=out) for r in self.rows if r.residual is not None]

    def _iterated_step(self):
        """A macro step with iterated signals ([signals] iterations): every
        instance and the method's state saved at T_N, the step (signals sent,
        the method's step) repeated from there as Signals.step_iterated asks."""
        t, n = self.time(), self.n
        for host in self.hosts:
            host.save_state()
        saved = copy.deepcopy((self.past, self.jac, self.reuse))
        explicit = self.method.kind == "explicit"

        def run():
            self.signals.send(n, t, self.h, None)
            if explicit:
                self._explicit_method()
            else:
                self._try_step(t, self.h, None)

        def restore():
            for host in self.hosts:
                host.restore_state()
            self.past, self.jac, self.reuse = copy.deepcopy(saved)
            self.n = n

        try:
            self.signals.step_iterated(t, run, restore)
        except Exception:
            self.n = n  # the step failed: the run ends at T_N
            raise

    def step(self):
        if self.signals.iterations is not None:
            self._iterated_step()
        elif self.method.kind == "explicit":
            self._explicit_step()
        else:
            self._predictor_corrector_step()
        self._check_divergence()

    def set_limits(self):
        factor = self.system.divergence_factor
        self.limits = [factor * max(abs(v), 1.0) for v in self.row]
        self._check_divergence()

    def _check_divergence(self):
        for name, v, limit in zip(self.columns, self.row, self.limits):
            if not math.isfinite(v) or abs(v) > limit:
                raise RunError(f"coupling diverged at t = {self.time()}: {name} = {v:e} (limit {limit:.1e})")
        # Then the residuals (the last columns) against `residual_limit`.
        limit = self.system.residual_limit
        n = sum(1 for r in self.rows if r.residual is not None)
        if limit is None or n == 0:
            return
        for name, g in zip(self.columns[-n:], self.row[-n:]):
            if abs(g) > limit:
                raise RunError(f"constraint broken at t = {self.time()}: |{name}| = {abs(g):e} "
                               f"exceeds residual_limit = {limit:e}")


class Control:
    """Adaptive macro steps: the PI step-size controller (docs/algorithm.md)."""

    def __init__(self, system):
        c = system.step_control
        span = system.stop - system.start
        self.rtol, self.atol = c["rtol"], c["atol"]
        self.h_min = c["h_min"] if c["h_min"] is not None else 1e-10 * span
        self.h_max = c["h_max"] if c["h_max"] is not None else span / 10.0
        h0 = c["h_initial"] if c["h_initial"] is not None else system.step
        for name, v in (("h_min", self.h_min), ("h_max", self.h_max), ("h_initial", h0)):
            if not math.isfinite(v) or v <= 0:
                raise RunError(f"invalid step_control.{name} = {v}: expected a finite step size > 0")
        if self.h_max < self.h_min:
            raise RunError(f"invalid step_control.h_max = {self.h_max}: expected h_max >= h_min")
        self.order = system.order + 2.0
        self.t, self.stop = system.start, system.stop
        self.h = max(min(h0, self.h_max), self.h_min)
        self.past = [self.h, self.h]
        self.previous, self.was_rejected = 1.0, False
        self.accepted = self.rejected = 0

    def next(self, h, err):
        """The next step size after one of h with error norm err, and whether it is accepted."""
        if math.isnan(err):
            self.was_rejected = True
            return min(max(h * 0.2, self.h_min), self.h_max), False
        err = max(err, 1e-10)
        p = self.order
        accepted = err <= 1.0
        if accepted:
            f = 0.9 * err ** (-0.7 / p) * self.previous ** (0.4 / p)
            if self.was_rejected:
                f = min(f, 1.0)
            self.previous = err
        else:
            f = 0.9 * err ** (-1.0 / p)
        self.was_rejected = not accepted
        nxt = h * min(max(f, 0.2), 5.0)
        return min(max(nxt, self.h_min), self.h_max), accepted


class Reuse:
    """Jacobian reuse: perturbed runs only when due, Broyden updates between."""

    def __init__(self, max_age):
        self.max_age, self.age, self.h, self.mispredicted = max_age, None, 0.0, False

    def due(self, h, growing):
        if self.age is None:
            return True
        ratio = h / self.h
        return growing or self.mispredicted or self.age >= self.max_age or not 0.8 <= ratio <= 1.25

    def made(self, h):
        self.age, self.h = 0, h

    def check(self, jac, levels, u_p, u_c, g_p, g_c):
        """Whether the Jacobian mispredicted g^c - g^p: on some row and level
        by more than 20 % of the larger of the predicted change and |g^p|."""
        nu = len(u_p)
        self.du = [c - p for c, p in zip(u_c, u_p)]
        self.dg = [g_c[lv][r] - g_p[lv][r] for lv in levels for r in range(nu)]
        self.predicted = [0.0] * len(self.dg)
        for m in range(nu):
            column = [jac[lv][r, m] for lv in levels for r in range(nu)]
            for i, j in enumerate(column):
                self.predicted[i] += j * self.du[m]
        gp = [g_p[lv][r] for lv in levels for r in range(nu)]
        self.mispredicted = any(math.isnan(abs(d - p)) or abs(d - p) > 0.2 * max(abs(p), abs(q))
                                for d, p, q in zip(self.dg, self.predicted, gp))
        return self.mispredicted

    def accepted(self, jac, pattern, levels):
        """The step is accepted: the Jacobian ages, and unless it mispredicted
        takes the secant in by Schubert's sparse update, row by row on the
        pattern (off it the entries stay exact zeros)."""
        self.age += 1
        if self.mispredicted:
            return
        nu, du, dg, predicted = len(self.du), self.du, self.dg, self.predicted
        row_du2 = [0.0] * nu
        for m in range(nu):
            for r in range(nu):
                if pattern[r][m]:
                    row_du2[r] += du[m] * du[m]
        for m in range(nu):
            for li, lv in enumerate(levels):
                for r in range(nu):
                    i = li * nu + r
                    if pattern[r][m] and row_du2[r] > 0.0:
                        jac[lv][r, m] += (dg[i] - predicted[i]) * (du[m] / row_du2[r])
