"""The coupled run: consistent initial multipliers, the semi-implicit
predictor/corrector step (Schweizer & Lu 2015, Method 1 eq. 55-68, Method 2
eq. 71-76) and the explicit baseline, on the grid T_n = T_0 + n*H.

Written from docs/algorithm.md, independently of crates/tether-master.
"""

import math

import numpy as np

import polynomials as poly
import rows as rowkinds
from errors import RunError
from host import Host, describe
from linalg import solve


class Master:
    def __init__(self, system):
        self.system = system
        self.method = system.method
        self.k = system.order
        self.h = system.step
        self.t0 = system.start
        self.steps = system.macro_steps()
        self.hosts = []
        try:
            for spec in system.instances:
                self.hosts.append(Host(spec))
            self._wire()
            stop = self.t0 + self.steps * self.h
            for host in self.hosts:
                host.initialize(self.t0, stop, system.tolerance)
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
        self.columns = [f"{h.name}.{v.name}" for h in self.hosts for v in h.recorded]
        self.columns += [f"{u.name}.lambda" for u in self.unknowns]
        self.columns += [f"{r.name}.g" for r in self.rows]

    # -- set-up -----------------------------------------------------------------

    def _wire(self):
        """Resolve every row and unknown against the FMUs, with the checks of
        `tether run` (docs/system-file.md, "Checks before the run")."""
        self.rows, self.unknowns = [], []
        for spec in self.system.constraints:
            row, unknown = rowkinds.from_constraint(spec)
            self.rows.append(row)
            self.unknowns.append(unknown)
        self.index = {h.name: s for s, h in enumerate(self.hosts)}
        self.refs = {}  # (instance, variable) -> (host index, value reference)
        for row, unknown in zip(self.rows, self.unknowns):
            for level in row.levels:
                for inst, var, order in row.reads(level):
                    s, v = self._lookup(row.name, inst, var)
                    if v.causality != "output" or v.type != "Real":
                        raise RunError(f"{inst}.{var} is {describe(v)}, but the {level} level of "
                                       f"constraint '{row.name}' needs a Real output")
                    host = self.hosts[s]
                    if order > host.cs.maxOutputDerivativeOrder:
                        raise RunError(f"instance '{inst}' ({host.md.modelName}) lacks a large enough "
                                       f"maxOutputDerivativeOrder, which der({inst}.{var}) in constraint "
                                       f"'{row.name}' needs")
                    host.add_output(v.valueReference, order)
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
                s, v = self._lookup(unknown.name, inst, var)
                if v.causality != "input" or v.type != "Real" or order != 0:
                    raise RunError(f"{inst}.{var} is {describe(v)}, but 'drives' of constraint "
                                   f"'{unknown.name}' needs a Real input")
                self.hosts[s].add_input(v.valueReference, m, c)
        self.owners = [[s for s, h in enumerate(self.hosts) if any(m == mm for _, terms in h.inputs
                                                                    for mm, _ in terms)]
                       for m in range(len(self.unknowns))]
        for host in self.hosts:
            if not host.is_coupled():
                continue
            if self.k > 0 and not host.cs.canInterpolateInputs:
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) lacks canInterpolateInputs, "
                               f"which coupling polynomials of degree k = {self.k} need (use order = 0)")
            if self.method.kind != "explicit" and not host.cs.canGetAndSetFMUstate:
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) lacks canGetAndSetFMUstate, "
                               f"which the predictor/corrector method {self.method.kind} needs")

    def _lookup(self, constraint, inst, var):
        s = self.index.get(inst)
        if s is None:
            raise RunError(f"constraint '{constraint}' refers to unknown instance '{inst}'; "
                           f"instances are: {', '.join(self.index)}")
        v = self.hosts[s].variable(var)
        self.refs[(inst, var)] = (s, v.valueReference)
        return s, v

    def close(self):
        for host in self.hosts:
            host.close()
        self.hosts = []

    # -- evaluating rows -------------------------------------------------------------

    def _value(self, row, level, u, live=None, base=None):
        """A row's level with the latest outputs of the hosts in `live` (all if
        None) and the `base` snapshot of the others."""

        def output(inst, var, order):
            s, vr = self.refs[(inst, var)]
            source = self.hosts[s].values if live is None or s in live else base[s]
            return source[(vr, order)]

        return row.value(level, output, u)

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
        if consistent:
            for _ in range(2):  # Newton; the first step is exact for linear feedthrough
                self._feedthrough_newton(consistent, mu)
        self._apply_constant()
        self._accept()

    def _residual(self, m, mu, u, live=None, base=None):
        """g'' (+ 2 g'/mu + g/mu^2 for the explicit method) of row m."""
        row = self.rows[m]
        r = self._value(row, "acceleration", u, live, base)
        if mu is not None:
            r += 2.0 * self._value(row, "velocity", u, live, base) / mu + \
                self._value(row, "position", u, live, base) / (mu * mu)
        return r

    def _feedthrough_newton(self, unknowns, mu):
        """One Newton step on the residuals of `unknowns`, with W = d residual / du
        by finite differences of inputs read back without a step."""
        jets = self._apply_constant()
        self._read_all()
        base = self._snapshot()
        u = self._current()
        r0 = np.array([self._residual(m, mu, u) for m in unknowns])
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
            for row_i, r in enumerate(unknowns):
                w[row_i, col] = (self._residual(r, mu, up, live, base) - r0[row_i]) / delta
            for s in live:
                self.hosts[s].apply(jets, 0)
                self.hosts[s].values = dict(base[s])
        step = solve(w, r0, self.time(), "acceleration", self.system.max_condition)
        for i, m in enumerate(unknowns):
            self.past[m][0] -= float(step[i])

    def _explicit_step(self):
        t = self.time()
        for host in self.hosts:  # inputs hold u_N over the step
            host.do_step(t, self.h)
        self.n += 1
        self.past = [[p[0], p[0], p[1]] for p in self.past]
        self._feedthrough_newton(list(range(len(self.unknowns))), self.method.mu)
        self._apply_constant()
        self._accept()

    # -- the predictor/corrector step -------------------------------------------------------

    def _predictor_corrector_step(self):
        t, h, k, n = self.time(), self.h, self.k, self.n
        # Start-up: N+1 points of history exist at T_N.
        degree_pred = min(k, n)
        degree_corr = min(k, n + 1)
        nu = len(self.unknowns)

        # Predictor: extrapolated polynomials (eq. 56-58).
        jets = [poly.predictor(self.past[m], degree_pred, h) for m in range(nu)]
        u_pred = [jets[m].at(h) for m in range(nu)]
        for host in self.hosts:
            if host.is_coupled():
                host.save_state()
            host.apply(jets, k)
            host.do_step(t, h)
            host.read()
        base = self._snapshot()
        g = {lv: np.array([self._value(r, lv, u_pred) for r in self.rows]) for lv in self.levels}

        # Perturbed predictors: column m of each level's Jacobian (eq. 59-64).
        jac = {lv: np.zeros((nu, nu)) for lv in self.levels}
        eps = self.system.epsilon
        for m in range(nu):
            delta = eps * max(abs(self.past[m][0]), 1.0)
            perturbed = list(jets)
            perturbed[m] = poly.through(u_pred[m] + delta, self.past[m], degree_corr, h)
            up = list(u_pred)
            up[m] = u_pred[m] + delta
            live = set(self.owners[m])
            for s in sorted(live):
                host = self.hosts[s]
                host.restore_state()
                host.apply(perturbed, k)
                host.do_step(t, h)
                host.read()
            for lv in self.levels:
                for r, row in enumerate(self.rows):
                    jac[lv][r, m] = (self._value(row, lv, up, live, base) - g[lv][r]) / delta

        corrected = self._corrected(u_pred, g, jac)

        # Corrector: repeat the step with interpolation polynomials.
        jets = [poly.through(corrected[m], self.past[m], degree_corr, h) for m in range(nu)]
        for host in self.hosts:
            if host.is_coupled():
                host.restore_state()
                host.apply(jets, k)
                host.do_step(t, h)
        self.past = [[corrected[m], p[0], p[1]] for m, p in enumerate(self.past)]
        self.n += 1
        self._accept()

    def _corrected(self, u_pred, g, jac):
        u_pred = np.array(u_pred)
        time = self.time_at(self.n + 1)
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
        return self.time_at(self.n)

    def time_at(self, n):
        return self.t0 + n * self.h

    def _accept(self):
        for host in self.hosts:
            host.read()
            host.read_recorded()
        u = self._current()
        self.row = [x for host in self.hosts for x in host.recorded_values]
        self.row += u
        self.row += [self._value(r, "position", u) for r in self.rows]

    def step(self):
        if self.method.kind == "explicit":
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
