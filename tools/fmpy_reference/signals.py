"""Signal connections `[[connection]] from = "a.y" to = "b.u"`: an output's
value handed to an input at macro points, without a solve (docs/algorithm.md,
"Signal connections"), the schemes `[signals] scheme = "jacobi"` and
`"gauss_seidel"`, and the direct-feedthrough loops: closed at the macro points
during the run, solved at T_0 in initialization mode (fixed-point sweeps, then
Newton on the Real connections with a finite-difference Jacobian).

Iterated steps (`[signals] iterations`, `solver`, `strict`): every instance
saved at T_N, the step run once, then v = G(v) on the senders' values at
T_{N+1}, G one repetition of the whole macro step from T_N (fixed point or
Newton, the solve the loops at T_0 use).

Where the result depends on the order of floating-point operations (the loop
solves), the operations are those of Tether's `algorithm/signals.rs` in the
same order, so that both hosts give the FMUs the same inputs bit for bit.
"""

import math
import struct
from dataclasses import dataclass

import polynomials as poly
from errors import RunError
from host import describe
from linalg import solve

# At T_0: fixed-point sweeps, then Newton steps, at most.
SWEEPS = 50
NEWTON = 20


@dataclass
class Link:
    """One resolved connection."""

    name: str  # `a.y → b.u`
    variable: str  # the sender's variable name
    frm: int  # sender's host index
    from_vr: int
    to: int  # receiver's host index
    to_vr: int
    kind: str  # "Real", "Integer" or "Boolean"
    gain: float
    offset: float
    interpolate: bool  # Real input of an instance with canInterpolateInputs


def _kind(var):
    return {"Real": "Real", "Float64": "Real", "Integer": "Integer", "Int32": "Integer",
            "Enumeration": "Integer", "Boolean": "Boolean"}.get(var.type)


def _e(x, digits=None):
    """A float as Rust's `{:e}` (shortest digits) or `{:.Ne}` prints it: 1e-10, 2.5e3."""
    if not math.isfinite(x):
        return "NaN" if x != x else ("inf" if x > 0 else "-inf")
    if digits is None:
        digits = next(n for n in range(17) if float(f"{x:.{n}e}") == x)
    mantissa, _, exponent = f"{x:.{digits}e}".partition("e")
    return f"{mantissa}e{int(exponent)}"


class Signals:
    """The signal connections of a system and the senders' last values."""

    def __init__(self, system, hosts):
        self.hosts = hosts
        self.links = []
        index = {h.name: s for s, h in enumerate(hosts)}
        unit_errors = []
        for c in system.connections:
            link, units = self._resolve(c, index)
            if units is not None:
                unit_errors.append(units)
            for other in self.links:
                if other.to == link.to and other.to_vr == link.to_vr:
                    raise RunError(f"connection {link.name}: input {c.to} already receives the "
                                   f"connection {other.name}")
            if any(entry[0] == link.to_vr for entry in hosts[link.to].inputs):
                raise RunError(f"connection {link.name}: input {c.to} is driven by a constraint, joint "
                               f"or coupling variable")
            self.links.append(link)
        self.loops = self._find_loops()
        if unit_errors:
            raise unit_errors[0]
        self.scheme = system.scheme
        self.tolerance = system.signal_tolerance
        self.order = system.order
        # Gauss-Seidel: the signal-only instances, stepped in file order.
        self.sequence = []
        if self.scheme == "gauss_seidel":
            for s, host in enumerate(hosts):
                linked = any(l.frm == s or l.to == s for l in self.links)
                if linked and not host.is_coupled():
                    host.stepped_ahead = True
                    self.sequence.append(s)
        n = len(self.links)
        self.history = [[0.0, 0.0, 0.0] for _ in range(n)]  # [y_N, y_{N-1}, y_{N-2}]
        self.next = [0.0] * n  # y_{N+1}, once read
        self.fresh = [False] * len(hosts)  # stepped already in this macro step
        self.save = False  # adaptive steps: the sweep saves each instance first
        self.iterations = system.signal_iterations  # None: each step runs once
        self.solver = system.signal_solver
        self.strict = system.signal_strict
        # In an iterated step's repetitions every receiver takes the iterate
        # `next` as its sender's value at T_{N+1}.
        self.iterating = False
        # The run summary's counts of iterated steps.
        self.counts = {"iterations": 0, "max_iterations": 0, "repeated_runs": 0, "not_converged": 0}

    def check_rollback(self):
        """An iterated step repeats the macro step of every instance from its
        state at T_N: the first instance without canGetAndSetFMUstate is refused."""
        if self.iterations is None:
            return
        for host in self.hosts:
            if not host.cs.canGetAndSetFMUstate:
                raise RunError(f"instance '{host.name}' ({host.md.modelName}) does not declare "
                               f"canGetAndSetFMUstate, which [signals] iterations (every instance repeats "
                               f"the macro step from its state at T_N) needs")

    # -- set-up ---------------------------------------------------------------

    def _resolve(self, c, index):
        name = f"{c.frm} → {c.to}"
        owner = f"connection {name}"

        def end(text, causality, role):
            instance, dot, variable = text.partition(".")
            if not dot:
                raise RunError(f"connection {name}: '{text}' is not <instance>.<variable>")
            s = index.get(instance)
            if s is None:
                raise RunError(f"{owner} refers to unknown instance '{instance}'; "
                               f"instances are: {', '.join(index)}")
            host = self.hosts[s]
            var = host.variables.get(variable)
            if var is None:
                raise RunError(f"{owner}, {role}: {host.md.modelName} has no variable '{variable}' "
                               f"(instance '{instance}')")
            if var.causality != causality or _kind(var) is None:
                raise RunError(f"{instance}.{variable} is {describe(var)}, but '{role}' of {owner} needs "
                               f"a Real, Integer or Boolean {causality}")
            return s, var

        frm, out = end(c.frm, "output", "from")
        to, inp = end(c.to, "input", "to")
        kind = _kind(out)
        if kind != _kind(inp):
            raise RunError(f"connection {name}: {c.frm} is {describe(out)} and {c.to} is {describe(inp)}: "
                           f"a connection joins variables of one type")
        if kind != "Real" and (c.gain is not None or c.offset is not None):
            raise RunError(f"connection {name}: gain and offset apply to Real connections only")
        units = None
        a, b = getattr(out, "unit", None), getattr(inp, "unit", None)
        if c.gain is None and c.offset is None and a and b and a != b:
            units = RunError(f"connection {name}: {c.frm} is in '{a}' and {c.to} in '{b}': units differ; "
                             f"set gain (and offset) on the connection to convert "
                             f"(to = gain·from + offset)")
        link = Link(name, out.name, frm, out.valueReference, to, inp.valueReference, kind,
                    1.0 if c.gain is None else c.gain, 0.0 if c.offset is None else c.offset,
                    kind == "Real" and self.hosts[to].interpolates(inp.valueReference))
        return link, units

    def _feeds_through(self, s, input_vr, output_vr):
        """Whether output `output_vr` of host `s` depends directly on input
        `input_vr` (ModelStructure/Outputs; an output listed without
        dependencies depends on every input)."""
        md = self.hosts[s].md

        def variable(vr, causality):
            for v in md.modelVariables:
                if v.valueReference == vr and v.causality == causality:
                    return v
            return None

        i, o = variable(input_vr, "input"), variable(output_vr, "output")
        if i is None or o is None:
            return True
        for unknown in md.outputs:
            if unknown.variable is o:
                return unknown.dependencies is None or any(d is i for d in unknown.dependencies)
        return True  # not listed: no structure information, assume the worst

    def _find_loops(self):
        """The direct-feedthrough loops: sets of links each reachable from
        every other (link a feeds b when b's sender output depends directly on
        a's receiver input), links in file order, loops by their first link."""
        links, n = self.links, len(self.links)

        def feeds(a, b):
            return a.to == b.frm and self._feeds_through(a.to, a.to_vr, b.from_vr)

        reach = [[False] * n for _ in range(n)]
        for start in range(n):
            row, stack = reach[start], [start]
            while stack:
                l = stack.pop()
                for nxt in range(n):
                    if not row[nxt] and feeds(links[l], links[nxt]):
                        row[nxt] = True
                        stack.append(nxt)
        placed, loops = [False] * n, []
        for l in range(n):
            if placed[l] or not reach[l][l]:
                continue
            members = [m for m in range(l, n) if reach[l][m] and reach[m][l]]
            for m in members:
                placed[m] = True
            loops.append(members)
        return loops

    def lagged(self, l):
        """Whether link `l` passes its sender's value at T_N (closes a loop at
        the macro point) rather than the value at T_{N+1}."""
        link = self.links[l]
        seq = self.sequence
        frm = seq.index(link.frm) if link.frm in seq else None
        to = seq.index(link.to) if link.to in seq else None
        if frm is None:
            return True
        return to is not None and to <= frm

    def loop_notes(self):
        """One line per direct-feedthrough loop: its instances and connections,
        with the value each passes."""
        notes = []
        for members in self.loops:
            instances = []
            for l in members:
                for s in (self.links[l].frm, self.links[l].to):
                    if self.hosts[s].name not in instances:
                        instances.append(self.hosts[s].name)
            if self.iterations is not None:
                how = f"Newton, at most {self.iterations} updates" if self.solver == "newton" else \
                    f"{self.scheme} fixed point, at most {self.iterations} repetitions of the step"
                names = ", ".join(self.links[l].name for l in members)
                notes.append(f"direct-feedthrough loop through {', '.join(instances)} is iterated at every "
                             f"macro step ({how}): {names} (value at T_{{N+1}})")
                continue
            passes = ", ".join(f"{self.links[l].name} (value at {'T_N' if self.lagged(l) else 'T_{N+1}'})"
                               for l in members)
            notes.append(f"direct-feedthrough loop through {', '.join(instances)} is closed only at macro "
                         f"points ({self.scheme}): {passes}")
        return notes

    # -- values at T_0 --------------------------------------------------------------

    def initialize(self):
        """Read the senders and set the receivers until nothing changes, then
        start every history there; a system with loops then solves them."""
        for _ in range(len(self.links) + 1):
            if not self._sweep():
                break
        if self.loops:
            self._solve_loops()

    def _sweep(self):
        changed = False
        for l in range(len(self.links)):
            value = self._read(l, "at T_0")
            changed |= not _same_bits(value, self.history[l][0])
            self._hold(l, value)
        return changed

    def _hold(self, l, value):
        self.history[l] = [value, value, value]
        self._set(l, poly.Jet(value))

    def _real_links(self):
        return [l for l in range(len(self.links)) if self.links[l].kind == "Real"]

    def _solve_loops(self):
        """v = G(v) with G: set every receiver to its link's value, read every
        sender (solve_loop: up to 50 fixed-point sweeps, then up to 20 Newton
        updates); the converged values start the histories."""
        v = [h[0] for h in self.history]
        g = [0.0] * len(v)
        solved = solve_loop(v, g, self._real_links(), (SWEEPS, NEWTON), self.tolerance, self._apply)
        if solved.converged:
            return self._settle(g)
        why = "its Jacobian is singular" if solved.singular else \
            "fixed-point sweeps and Newton did not converge"
        raise self._unsolved(solved.residual, why)

    def _apply(self, v, g):
        """G(v) into g at T_0: every receiver set to v, every sender read."""
        for l, value in enumerate(v):
            self._set(l, poly.Jet(value))
        for l in range(len(g)):
            g[l] = self._read(l, "at T_0")

    def _settle(self, g):
        for l, value in enumerate(g):
            self._hold(l, value)

    def _unsolved(self, residual, why):
        names = [self.links[l].name for l in self.loops[0]]
        return RunError(f"connection {names[0]}: direct-feedthrough loop {', then '.join(names)} has no "
                        f"consistent values at T_0: {why} (largest |v − G(v)| is {_e(residual, 1)} times "
                        f"the [signals] tolerance {_e(self.tolerance)})")

    # -- around the method's macro step ---------------------------------------------------

    def send(self, n, t, h, steps):
        """Before the method's step T_N -> T_{N+1}: set every receiving input.
        Gauss-Seidel first steps the signal-only instances one after another,
        each with the values at T_{N+1} of the senders stepped before it."""
        if not self.links:
            return
        self.fresh = [False] * len(self.hosts)
        for s in self.sequence:
            for l, link in enumerate(self.links):
                if link.to == s:
                    self._set(l, self._polynomial(l, n, h, steps))
            host = self.hosts[s]
            if self.save:
                host.save_state()
            host.do_step(t, h)
            self.fresh[s] = True
            for l, link in enumerate(self.links):
                if link.frm == s:
                    self.next[l] = self._read(l, f"after fmi2DoStep at t = {t}")
        for l, link in enumerate(self.links):
            if link.to not in self.sequence:
                self._set(l, self._polynomial(l, n, h, steps))

    def receive(self, t):
        """After an accepted step: read the senders at T_{N+1} (those the
        Gauss-Seidel sweep did not) and shift the histories."""
        self._read_next(t)
        self._shift()

    def _read_next(self, t):
        for l, link in enumerate(self.links):
            if not self.fresh[link.frm]:
                self.next[l] = self._read(l, f"after the step to t = {t}")

    def _shift(self):
        for l, h in enumerate(self.history):
            self.history[l] = [self.next[l], h[0], h[1]]

    def step_iterated(self, t, run, restore):
        """An iterated macro step from T_N = t: the caller saved every instance
        and the method's state at T_N; `run()` sends and makes the method's
        step, `restore()` goes back to T_N. The first run's senders' values at
        T_{N+1} are the first iterate v; G(v) restores, sets `next` = v (every
        receiver takes it as its sender's value at T_{N+1}; Gauss-Seidel's
        later receivers this repetition's values), runs and reads the senders.
        Fixed point: at most `iterations` repetitions; Newton: at most
        `iterations` updates. The last repetition stands."""
        n_max = self.iterations
        run()
        self._read_next(t)
        v = list(self.next)
        g = [0.0] * len(v)
        limits = (n_max - 1, 0) if self.solver == "fixed_point" else (0, n_max)

        def apply(v, g):
            restore()
            self.next = list(v)
            run()
            self._read_next(t)
            g[:] = self.next

        self.iterating = True
        try:
            solved = solve_loop(v, g, self._real_links(), limits, self.tolerance, apply)
        finally:
            self.iterating = False
        self._shift()
        c = self.counts
        iterations = solved.runs if self.solver == "fixed_point" else solved.updates
        c["iterations"] += iterations
        c["max_iterations"] = max(c["max_iterations"], iterations)
        c["repeated_runs"] += solved.runs
        if not solved.converged:
            worst, largest = 0, None
            for l in range(len(v)):
                r = abs(v[l] - g[l]) / max(abs(v[l]), 1.0)
                if largest is None or r >= largest:
                    worst, largest = l, r
            if self.strict:
                raise RunError(f"[signals] strict: the macro step from t = {t} did not converge in {n_max} "
                               f"iterations: |Δv| of connection {self.links[worst].name} is "
                               f"{_e(solved.residual, 1)} times the tolerance {_e(self.tolerance)} (raise "
                               f"iterations, loosen tolerance, or try solver = \"newton\")")
            c["not_converged"] += 1

    def _polynomial(self, l, n, h, steps):
        """The sender's polynomial over the step as link l's receiver takes it:
        through y_{N+1} when the sender has stepped already, else extrapolated;
        degree 0 for a receiver that cannot interpolate."""
        link = self.links[l]
        k = self.order if link.interpolate else 0
        history = self.history[l]
        if self.fresh[link.frm] or self.iterating:
            return poly.through(self.next[l], history, min(k, n + 1), h, steps)
        return poly.predictor(history, min(k, n), h, steps)

    def _read(self, l, when):
        link = self.links[l]
        fmu = self.hosts[link.frm].fmu
        if link.kind == "Real":
            value = fmu.getReal([link.from_vr])[0]
        elif link.kind == "Integer":
            value = float(fmu.getInteger([link.from_vr])[0])
        else:
            value = 1.0 if fmu.getBoolean([link.from_vr])[0] else 0.0
        if not math.isfinite(value):
            raise RunError(f"instance '{self.hosts[link.frm].name}': output '{link.variable}' = {value} "
                           f"{when} (the FMU computed a non-finite value)")
        return value

    def _set(self, l, jet):
        """Link l's receiver to gain*p + offset, with the derivatives when it
        interpolates and k > 0."""
        link = self.links[l]
        fmu = self.hosts[link.to].fmu
        vr = [link.to_vr]
        if link.kind == "Real":
            fmu.setReal(vr, [link.gain * jet.value + link.offset])
            n = min(self.order, 2) if link.interpolate else 0
            if n > 0:
                d = [link.gain * jet.d1, link.gain * jet.d2][:n]
                fmu.setRealInputDerivatives(vr * n, [1, 2][:n], d)
        elif link.kind == "Integer":
            fmu.setInteger(vr, [int(jet.value)])
        else:
            fmu.setBoolean(vr, [jet.value != 0.0])


@dataclass
class Solved:
    """What solve_loop did."""

    converged: bool = False
    singular: bool = False  # Newton stopped on a singular Jacobian
    updates: int = 0  # fixed-point sweeps and Newton updates
    runs: int = 0  # runs of G
    residual: float = 0.0  # max |v - G(v)| / (tolerance*max(1, |v|)) at the last run


def solve_loop(v, g, real, limits, tolerance, apply):
    """Solve v = G(v), one value per link, `apply(v, g)` putting G(v) into g:
    first G(v); then up to `sweeps` fixed-point updates v <- G(v), each
    followed by a run; then up to `newton` Newton updates of the Real links
    `real` on r(v) = v - G(v), dr/dv = I - dG/dv from one run per Real link
    with v_j increased by 1e-7*max(1, |v_j|) (the other links take G's
    value), each followed by a run at the new v. Stopped as soon as a run
    gives |v_l - G(v)_l| <= tolerance*max(1, |v_l|) for every l. v and g are
    updated in place; g holds G(v) of the last run (after a singular
    Jacobian G(v) is run once more). Tether's `solve_loop`, operation for
    operation."""
    sweeps, newton = limits

    def residual(v, g):
        worst = 0.0
        for a, b in zip(v, g):
            worst = max(worst, abs(a - b) / (tolerance * max(abs(a), 1.0)))
        return worst

    n = len(v)
    apply(v, g)
    solved = Solved(runs=1, residual=residual(v, g))
    for _ in range(sweeps):
        if solved.residual <= 1.0:
            break
        v[:] = g
        apply(v, g)
        solved.updates += 1
        solved.runs += 1
        solved.residual = residual(v, g)
    gb = [0.0] * n
    for _ in range(newton):
        if solved.residual <= 1.0:
            break
        for l in range(n):
            if l not in real:
                v[l] = g[l]
        k = len(real)
        w = [[0.0] * k for _ in range(k)]
        for j, lj in enumerate(real):
            delta = 1e-7 * max(abs(v[lj]), 1.0)
            bumped = list(v)
            bumped[lj] += delta
            apply(bumped, gb)
            solved.runs += 1
            for i, li in enumerate(real):
                identity = 1.0 if i == j else 0.0
                w[i][j] = identity - (gb[li] - g[li]) / delta
        b = [v[li] - g[li] for li in real]
        try:
            step = solve(w, b, 0.0, "signal loop", 1e14)
        except RunError:
            solved.singular = True
            apply(v, g)
            solved.runs += 1
            solved.residual = residual(v, g)
            return solved
        for li, s in zip(real, step):
            v[li] -= s
        apply(v, g)
        solved.updates += 1
        solved.runs += 1
        solved.residual = residual(v, g)
    solved.converged = solved.residual <= 1.0
    return solved


def _same_bits(a, b):
    return struct.pack("<d", a) == struct.pack("<d", b)
