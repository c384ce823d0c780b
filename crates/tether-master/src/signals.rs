//! Signal connections `[[connection]] from = "a.y" to = "b.u"`: an output's
//! value handed to an input at macro points, without a solve and without
//! rollback (docs/algorithm.md, "Signal connections"; adaptive steps roll
//! back a rejected try, signal-only instances included).
//!
//! Around the method's macro step: [`Signals::send`] sets every receiving
//! input for the step T_N → T_{N+1} (before `save`, so that repeated runs of
//! a constraint-coupled instance see the same signal inputs), and
//! [`Signals::receive`] reads the senders at T_{N+1} (after `correct`).
//! A Real input of an instance that declares `canInterpolateInputs` (FMI 3.0:
//! intermediate update for that input) gets the polynomial of degree k through
//! the sender's last values; every other input is held constant over the step.
//!
//! A String connection carries its values through the same machinery as a
//! number: the index of the text in the link's table of the texts it has
//! carried (each distinct text once), held over the step and compared for
//! equality in loops. After an accepted step a table of more than
//! [`TEXTS_KEPT`] texts is rebuilt from the texts the link still holds, so a
//! text that changes every step costs no memory that grows with the run.

use std::collections::HashMap;

use tether_fmi::{BaseType, Causality, ScalarVariable, ValueType};

use crate::algorithm::step::{MacroStep, StepAt};
use crate::linalg::solve::Solver;
use crate::polynomial::{extrapolate, interpolate, Taylor};
use crate::runs::{Outputs, Phase, Runs};
use crate::slave::{Run, Slave};
use crate::spec::names::{describe, find_instance, Element};
use crate::spec::{ConnectionSpec, SignalScheme, SignalSolver, StartValue, SystemSpec};
use crate::stats::{Lap, RunStats, SignalStats};
use crate::system::System;
use crate::MasterError;
use tether_fmi::{Inputs, Int};

use crate::observer::integer_value;

/// A String link's table is rebuilt from the texts it holds once it has
/// more than this many (its values at T_N, T_{N−1}, T_{N−2} and at its
/// receiver's own last three communication points: seven at most).
const TEXTS_KEPT: usize = 64;

/// The FMI type a connection carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Real,
    Integer,
    Boolean,
    /// FMI `String` (not FMI 3.0 `Binary`): carried as an index into the
    /// link's texts.
    String,
}

/// One resolved connection.
#[derive(Debug, Clone)]
struct Link {
    /// `a.y → b.u`, for messages.
    name: String,
    /// The sender's variable name.
    variable: String,
    from: usize,
    from_vr: u32,
    /// An element of an array output: its index and the array's size (the
    /// array is read whole, the element picked).
    from_element: Option<Element>,
    to: usize,
    to_vr: u32,
    /// An element of an array input (the array is set whole, its other
    /// elements at their values so far).
    to_element: Option<Element>,
    kind: Kind,
    gain: f64,
    offset: f64,
    /// The receiver takes the polynomial (Real input, `Slave::interpolates`).
    interpolate: bool,
}

/// The signal connections of a system and the senders' last values.
pub(crate) struct Signals {
    links: Vec<Link>,
    /// The direct-feedthrough loops: each a set of links (file order).
    loops: Vec<Vec<usize>>,
    /// Per link: the sender's values `[y_N, y_{N-1}, y_{N-2}]`.
    history: Vec<[f64; 3]>,
    /// Per link: the sender's value at T_{N+1}, once read.
    next: Vec<f64>,
    /// Degree k of the polynomials (`[coupling] order`).
    order: usize,
    /// Gauss–Seidel: the signal-only instances, stepped in this order.
    sequence: Vec<usize>,
    /// Gauss–Seidel's stages: runs of `sequence` in which no instance
    /// receives from another, stepped together (on worker threads where
    /// `[coupling] parallel` puts them).
    stages: Vec<std::ops::Range<usize>>,
    scheme: SignalScheme,
    /// `[signals] tolerance`: relative, on the exchanged values.
    tolerance: f64,
    /// Per instance: stepped already in the current macro step.
    fresh: Vec<bool>,
    /// Adaptive steps: the Gauss–Seidel sweep saves each instance before
    /// stepping it, so that a rejected step rolls it back with the others.
    save: bool,
    /// `[signals] iterations`: the most updates per macro step, if iterated.
    iterations: Option<usize>,
    /// `[signals] solver`.
    solver: SignalSolver,
    /// `[signals] strict`.
    strict: bool,
    /// In an iterated step's repeated runs: every receiver takes the
    /// iterate `next` as its sender's value at T_{N+1}.
    iterating: bool,
    /// The Newton updates' linear solver, reused.
    newton: Solver,
    /// Per link: the texts a String link has carried, each once (its values
    /// are indices into them; `""` is index 0); empty for other links.
    texts: Vec<Texts>,
    /// Per link: for a receiver with its own communication step n·H, the
    /// slot in `history` (after the links' own) of the sender's values at
    /// the receiver's communication points `[y_M, y_{M−n}, y_{M−2n}]`.
    coarse: Vec<Option<usize>>,
    /// T_0 and H, for the steps of instances with their own step; `None`
    /// when none has one (the macro step then skips them at no cost).
    own_steps: Option<(f64, f64)>,
}

impl Signals {
    /// The signal values carried between steps: each link's sender values
    /// `[y_N, y_{N-1}, y_{N-2}]` and its value at T_{N+1} once read.
    pub fn values(&self) -> (Vec<[f64; 3]>, Vec<f64>) {
        (self.history.clone(), self.next.clone())
    }

    /// Back to values of [`values`](Self::values).
    pub fn set_values(&mut self, (history, next): &(Vec<[f64; 3]>, Vec<f64>)) {
        self.history.clone_from(history);
        self.next.clone_from(next);
    }

    /// The texts each String link has carried (empty for other links): the
    /// meaning of its values in [`values`](Self::values).
    pub fn texts(&self) -> Vec<Vec<String>> {
        self.texts.iter().map(|t| t.all.clone()).collect()
    }

    /// Back to texts of [`texts`](Self::texts), with values of the same
    /// state.
    pub fn set_texts(&mut self, texts: &[Vec<String>]) {
        for (t, all) in self.texts.iter_mut().zip(texts) {
            *t = Texts::default();
            for text in all {
                t.index_of(text.clone());
            }
        }
    }

    /// Resolve the system file's connections against the instances (after
    /// the coupling: an input an unknown drives cannot also be a receiver).
    pub fn build(spec: &SystemSpec, slaves: &mut [Slave]) -> Result<Signals, MasterError> {
        let mut links: Vec<Link> = Vec::new();
        let mut unit_errors = Vec::new();
        for c in &spec.connections {
            let (link, units) = resolve(c, slaves)?;
            unit_errors.extend(units);
            if let Some(other) = links.iter().find(|l| {
                l.to == link.to && l.to_vr == link.to_vr && l.to_element == link.to_element
            }) {
                return Err(MasterError::Connection {
                    connection: link.name.clone(),
                    reason: format!(
                        "input {} already receives the connection {}",
                        c.to, other.name
                    ),
                });
            }
            if slaves[link.to]
                .coupled
                .inputs
                .iter()
                .any(|i| i.vr == link.to_vr)
            {
                return Err(MasterError::Connection {
                    connection: link.name,
                    reason: format!(
                        "input {} is driven by a constraint, joint or coupling variable",
                        c.to
                    ),
                });
            }
            links.push(link);
        }
        let loops = find_loops(&links, slaves);
        if let Some(e) = unit_errors.into_iter().next() {
            return Err(e);
        }
        let scheme = spec.signals.scheme();
        decimate(spec, slaves)?;
        let mut coarse = Vec::with_capacity(links.len());
        let mut slots = links.len();
        for link in &links {
            coarse.push((slaves[link.to].coupled.decimation > 1).then(|| {
                slots += 1;
                slots - 1
            }));
        }
        let mut sequence = Vec::new();
        if scheme == SignalScheme::GaussSeidel {
            for (s, slave) in slaves.iter_mut().enumerate() {
                let linked = links.iter().any(|l| l.from == s || l.to == s);
                if linked && !slave.is_coupled() {
                    slave.stepped_ahead = true;
                    sequence.push(s);
                }
            }
        }
        let stages = stages(&sequence, &links);
        Ok(Signals {
            stages,
            loops,
            history: vec![[0.0; 3]; slots],
            coarse,
            own_steps: slaves
                .iter()
                .any(|s| s.coupled.decimation > 1)
                .then_some((spec.experiment.start, spec.experiment.step)),
            next: vec![0.0; links.len()],
            order: spec.coupling.order,
            sequence,
            scheme,
            tolerance: spec.signals.tolerance(),
            fresh: vec![false; slaves.len()],
            save: false,
            iterations: spec.signals.iterations,
            solver: spec.signals.solver.unwrap_or_default(),
            strict: spec.signals.strict,
            iterating: false,
            newton: Solver::default(),
            texts: links
                .iter()
                .map(|l| {
                    let mut texts = Texts::default();
                    if l.kind == Kind::String {
                        texts.index_of(String::new());
                    }
                    texts
                })
                .collect(),
            links,
        })
    }

    /// Whether every macro step is iterated (`[signals] iterations`).
    pub fn iterated(&self) -> bool {
        self.iterations.is_some()
    }

    /// The run summary's iteration counts, zero, when iterated.
    pub fn initial_stats(&self) -> Option<SignalStats> {
        self.iterated().then(|| SignalStats {
            solver: self.solver,
            ..SignalStats::default()
        })
    }

    /// An iterated step repeats the macro step of every instance from its
    /// state at T_N: each must declare `canGetAndSetFMUstate`. The first
    /// that does not is refused by name, before the first step.
    pub fn check_rollback(&self, slaves: &[Slave]) -> Result<(), MasterError> {
        if !self.iterated() {
            return Ok(());
        }
        match slaves.iter().find(|s| !s.caps.rollback) {
            None => Ok(()),
            Some(slave) => Err(MasterError::MissingCapability {
                instance: slave.name.clone(),
                model: slave.model_name.clone(),
                capability: "canGetAndSetFMUstate",
                needed_by: "[signals] iterations (every instance repeats the macro step from \
                            its state at T_N)"
                    .into(),
            }),
        }
    }

    /// Whether link `l` passes its sender's value at T_N (closes a loop at
    /// the macro point) rather than the value at T_{N+1}: every link under
    /// Jacobi; under Gauss–Seidel a link whose sender steps after its
    /// receiver, or is stepped with the constraint-coupled block.
    fn lagged(&self, l: usize) -> bool {
        let link = &self.links[l];
        let position = |s: usize| self.sequence.iter().position(|&q| q == s);
        match (position(link.from), position(link.to)) {
            (None, _) => true,
            (Some(from), Some(to)) => to <= from,
            (Some(_), None) => false,
        }
    }

    /// The inputs of instance `s` that connections set.
    pub fn receivers(&self, s: usize) -> impl Iterator<Item = u32> + '_ {
        self.links
            .iter()
            .filter(move |l| l.to == s)
            .map(|l| l.to_vr)
    }

    /// One line per direct-feedthrough loop for the setup's note: the
    /// instances in it, and where the macro points close it.
    pub fn loop_notes(&self, slaves: &[Slave]) -> Vec<String> {
        self.loops
            .iter()
            .map(|members| {
                let mut instances: Vec<&str> = Vec::new();
                for &l in members {
                    for s in [self.links[l].from, self.links[l].to] {
                        if !instances.contains(&slaves[s].name.as_str()) {
                            instances.push(&slaves[s].name);
                        }
                    }
                }
                if let Some(n) = self.iterations {
                    let how = match (self.solver, self.scheme) {
                        (SignalSolver::Newton, _) => format!("Newton, at most {n} updates"),
                        (_, SignalScheme::Jacobi) => {
                            format!("Jacobi fixed point, at most {n} repetitions of the step")
                        }
                        (_, SignalScheme::GaussSeidel) => {
                            format!("Gauss–Seidel fixed point, at most {n} repetitions of the step")
                        }
                    };
                    return format!(
                        "direct-feedthrough loop through {} is iterated at every macro step \
                         ({how}; -v names the connections)",
                        instances.join(", ")
                    );
                }
                // The instances whose feedthrough in the loop is assumed:
                // their outputs declare no dependencies (the ordinary case).
                let mut assumed: Vec<&str> = Vec::new();
                for &a in members {
                    for &b in members {
                        let (la, lb) = (&self.links[a], &self.links[b]);
                        if la.to == lb.from
                            && !declares_dependencies(&slaves[lb.from], lb.from_vr)
                            && !assumed.contains(&slaves[lb.from].name.as_str())
                        {
                            assumed.push(&slaves[lb.from].name);
                        }
                    }
                }
                assumed.sort_by_key(|a| instances.iter().position(|i| i == a));
                let lagged = members.iter().filter(|&&l| self.lagged(l)).count();
                let how = match self.scheme {
                    SignalScheme::Jacobi => format!(
                        "Jacobi passes each of its {} connections the sender's value at T_N",
                        members.len()
                    ),
                    SignalScheme::GaussSeidel => format!(
                        "Gauss–Seidel steps its instances in file order and {lagged} of its {} \
                         connections (those into an instance stepped before its sender) pass \
                         the value at T_N",
                        members.len()
                    ),
                };
                if assumed.is_empty() {
                    format!(
                        "direct-feedthrough loop through {} is closed only at macro points: \
                         {how} (-v names the connections)",
                        instances.join(", ")
                    )
                } else {
                    format!(
                        "the connections between {} form a loop; {} declare{} no dependencies \
                         of {} outputs, so Tether takes them to feed through, and the loop is \
                         closed at macro points as co-simulation masters do: {how} (-v names \
                         the connections)",
                        instances.join(", "),
                        assumed.join(", "),
                        if assumed.len() == 1 { "s" } else { "" },
                        if assumed.len() == 1 { "its" } else { "their" }
                    )
                }
            })
            .collect()
    }

    /// The connections of each loop, with the value each passes (for `-v`).
    pub fn loop_connections(&self) -> Vec<String> {
        self.loops
            .iter()
            .map(|members| {
                let names: Vec<String> = members
                    .iter()
                    .map(|&l| {
                        let at = if self.lagged(l) && !self.iterated() {
                            "T_N"
                        } else {
                            "T_{N+1}"
                        };
                        format!("{} (value at {at})", self.links[l].name)
                    })
                    .collect();
                names.join(", ")
            })
            .collect()
    }

    /// Adaptive steps: a rejected step restores every instance to its state
    /// at T_N (the method restores what was saved), and the retry sends
    /// again. The instances the Gauss–Seidel sweep steps before the method's
    /// save are saved here first. The histories only shift on
    /// [`receive`](Self::receive), after an accepted step.
    pub fn roll_back_with_retries(&mut self) {
        self.save = true;
    }

    /// Each connection as (sender instance, output, receiver instance, input).
    pub fn links(&self) -> impl Iterator<Item = (usize, u32, usize, u32)> + '_ {
        self.links
            .iter()
            .map(|l| (l.from, l.from_vr, l.to, l.to_vr))
    }

    /// Whether the connections make a direct-feedthrough loop.
    pub fn has_loops(&self) -> bool {
        !self.loops.is_empty()
    }

    /// Values at T_0: read the senders and set the receivers until nothing
    /// changes (as often as the longest chain of direct feedthrough needs,
    /// when there are no loops), then start every history there. A system
    /// with loops then solves them ([`solve_loops`](Self::solve_loops)).
    pub fn initialize(&mut self, slaves: &mut [Slave]) -> Result<(), MasterError> {
        for _ in 0..=self.links.len() {
            if !self.sweep(slaves)? {
                break;
            }
        }
        if self.has_loops() {
            self.solve_loops(slaves)?;
        }
        Ok(())
    }

    /// One pass over the links in file order: read the sender, set the
    /// receiver (held) and start the history there. Whether a value changed.
    fn sweep(&mut self, slaves: &mut [Slave]) -> Result<bool, MasterError> {
        let mut changed = false;
        for l in 0..self.links.len() {
            let value = self.read(slaves, l, Run::Initial)?;
            changed |= value.to_bits() != self.history[l][0].to_bits();
            self.hold(slaves, l, value)?;
        }
        Ok(changed)
    }

    /// Link `l`'s value `value` as its history and its receiver's held input.
    fn hold(&mut self, slaves: &mut [Slave], l: usize, value: f64) -> Result<(), MasterError> {
        self.history[l] = [value; 3];
        if let Some(slot) = self.coarse[l] {
            self.history[slot] = [value; 3];
        }
        let held = Taylor {
            value,
            ..Taylor::default()
        };
        self.set(slaves, l, held)
    }

    /// Consistent values of the loops at T_0, v = G(v) with G: set every
    /// receiver to its link's value, read every sender ([`solve_loop`]:
    /// up to 50 fixed-point sweeps, which converge when the loop gain is
    /// below 1, then up to 20 Newton updates; exact after one for linear
    /// feedthrough). Otherwise an error naming the first loop.
    pub fn solve_loops(&mut self, slaves: &mut [Slave]) -> Result<(), MasterError> {
        let mut v: Vec<f64> = self.history[..self.links.len()]
            .iter()
            .map(|h| h[0])
            .collect();
        let mut g = vec![0.0; v.len()];
        let kinds = (self.real_links(), self.text_links());
        let mut solver = Solver::default();
        let solved = solve_loop(
            (&mut v, &mut g),
            (&kinds.0, &kinds.1),
            (50, 20),
            self.tolerance,
            &mut solver,
            |v, g| self.apply(slaves, v, g),
        )?;
        if solved.converged {
            return self.settle(slaves, &g);
        }
        let why = if solved.singular {
            "its Jacobian is singular"
        } else {
            "fixed-point sweeps and Newton did not converge"
        };
        Err(self.unsolved(solved.residual, why))
    }

    /// The links that carry Real values (those Newton updates).
    fn real_links(&self) -> Vec<usize> {
        (0..self.links.len())
            .filter(|&l| self.links[l].kind == Kind::Real)
            .collect()
    }

    /// The links that carry String values (compared for equality).
    fn text_links(&self) -> Vec<usize> {
        (0..self.links.len())
            .filter(|&l| self.links[l].kind == Kind::String)
            .collect()
    }

    /// G(v) into `g` at T_0: every receiver set to its link's value `v`,
    /// every sender read.
    fn apply(&mut self, slaves: &mut [Slave], v: &[f64], g: &mut [f64]) -> Result<(), MasterError> {
        for (l, &value) in v.iter().enumerate() {
            let held = Taylor {
                value,
                ..Taylor::default()
            };
            self.set(slaves, l, held)?;
        }
        for (l, out) in g.iter_mut().enumerate() {
            *out = self.read(slaves, l, Run::Initial)?;
        }
        Ok(())
    }

    /// An iterated macro step T_N → T_{N+1} (`[signals] iterations`):
    /// every instance is saved at T_N and the step is run once as without
    /// iterations (the scheme's values at T_N or T_{N+1}, the method's
    /// step); its senders' values at T_{N+1} are the first iterate v. Then
    /// v = G(v) is solved by [`solve_loop`], G one repetition of the whole
    /// macro step from T_N (every instance restored, the unknowns' history
    /// and the method's state back to T_N) in which every receiver takes
    /// v as its sender's value at T_{N+1} (held, or the polynomial through
    /// it and y_N, y_{N-1}, … when it interpolates), Gauss–Seidel's later
    /// receivers the values of this repetition. Fixed point: at most
    /// `iterations` repetitions; Newton: at most `iterations` updates. The
    /// last repetition stands, converged or not; its senders' values start
    /// the next step.
    pub fn step_iterated(
        &mut self,
        (method, system): (&mut Box<dyn MacroStep>, &mut System),
        at: StepAt,
        stats: &mut RunStats,
        lap: &mut Lap,
    ) -> Result<Option<f64>, MasterError> {
        let max = self.iterations.unwrap_or(1);
        for slave in &mut system.slaves {
            slave.save_state()?;
        }
        let unknowns = system.history.clone();
        let state = method.save();
        self.send((&mut system.slaves, &mut system.runs), at)?;
        method.step(system, at, stats, lap)?;
        self.read_next(&mut system.slaves)?;
        let mut v = self.next.clone();
        let mut g = vec![0.0; v.len()];
        let kinds = (self.real_links(), self.text_links());
        let limits = match self.solver {
            SignalSolver::FixedPoint => (max - 1, 0),
            SignalSolver::Newton => (0, max),
        };
        let mut newton = std::mem::take(&mut self.newton);
        self.iterating = true;
        let tolerance = self.tolerance;
        let solved = solve_loop(
            (&mut v, &mut g),
            (&kinds.0, &kinds.1),
            limits,
            tolerance,
            &mut newton,
            |v, g| {
                for slave in &mut system.slaves {
                    slave.restore_state()?;
                }
                system.history.clone_from(&unknowns);
                method.restore(&state);
                self.next.copy_from_slice(v);
                self.send((&mut system.slaves, &mut system.runs), at)?;
                method.step(system, at, stats, lap)?;
                self.read_next(&mut system.slaves)?;
                g.copy_from_slice(&self.next);
                Ok(())
            },
        );
        self.iterating = false;
        self.newton = newton;
        let solved = solved?;
        self.shift();
        let counts = stats.signals.get_or_insert_with(SignalStats::default);
        let iterations = match self.solver {
            SignalSolver::FixedPoint => solved.runs,
            SignalSolver::Newton => solved.updates,
        } as u64;
        counts.iterations += iterations;
        counts.max_iterations = counts.max_iterations.max(iterations);
        counts.repeated_runs += solved.runs as u64;
        if !solved.converged {
            let worst = (0..v.len())
                .max_by(|&a, &b| {
                    let r = |l: usize| (v[l] - g[l]).abs() / v[l].abs().max(1.0);
                    r(a).total_cmp(&r(b))
                })
                .unwrap_or(0);
            if self.strict {
                return Err(MasterError::SignalsNotConverged {
                    time: at.t,
                    iterations: max,
                    connection: self.links[worst].name.clone(),
                    residual: solved.residual,
                    tolerance,
                });
            }
            if counts.first_not_converged.is_none() {
                counts.first_not_converged = Some(at.t);
                log::warn!(
                    "[signals] the macro step from t = {} did not converge in {max} iterations \
                     (|Δv| of connection {} is {:.1e} times the tolerance); its last run stands \
                     (the run summary counts such steps; strict = true fails the run)",
                    crate::Time(at.t),
                    self.links[worst].name,
                    solved.residual
                );
            }
            counts.not_converged += 1;
        }
        Ok(None)
    }

    /// Take the converged values `g` (read from the senders at the last
    /// inputs): set the receivers and start the histories there.
    fn settle(&mut self, slaves: &mut [Slave], g: &[f64]) -> Result<(), MasterError> {
        for (l, &value) in g.iter().enumerate() {
            self.hold(slaves, l, value)?;
        }
        Ok(())
    }

    /// The error for loops without consistent values at T_0.
    fn unsolved(&self, residual: f64, why: &str) -> MasterError {
        let members = &self.loops[0];
        let names: Vec<&str> = members
            .iter()
            .map(|&l| self.links[l].name.as_str())
            .collect();
        MasterError::Connection {
            connection: names[0].to_string(),
            reason: format!(
                "direct-feedthrough loop {} has no consistent values at T_0: {why} \
                 (largest |v − G(v)| is {residual:.1e} times the [signals] tolerance {:e})",
                names.join(", then "),
                self.tolerance
            ),
        }
    }

    /// Before the method's step T_N → T_{N+1}: set every receiving input.
    /// Gauss–Seidel first steps the signal-only instances one after another,
    /// each with the values at T_{N+1} of the senders stepped before it.
    pub fn send(
        &mut self,
        (slaves, runs): (&mut Vec<Slave>, &mut Runs),
        at: StepAt,
    ) -> Result<(), MasterError> {
        if self.links.is_empty() {
            return match self.own_steps {
                None => Ok(()),
                Some(grid) => self.step_own(slaves, at, grid),
            };
        }
        self.fresh.fill(false);
        for stage in 0..self.stages.len() {
            let stage = self.stages[stage].clone();
            for i in stage.clone() {
                let s = self.sequence[i];
                for l in 0..self.links.len() {
                    if self.links[l].to == s {
                        let poly = self.polynomial(l, at);
                        self.set(slaves, l, poly)?;
                    }
                }
                if self.save {
                    slaves[s].save_state()?;
                }
            }
            let members = &self.sequence[stage.clone()];
            let phase = Phase::step(at.t, at.h);
            runs.phase(slaves, phase, Outputs::none(), |s, _| members.contains(&s))?;
            for i in stage {
                let s = self.sequence[i];
                self.fresh[s] = true;
                for l in 0..self.links.len() {
                    if self.links[l].from == s {
                        self.next[l] = self.read(slaves, l, Run::Signal)?;
                    }
                }
            }
        }
        for l in 0..self.links.len() {
            if self.sequence.contains(&self.links[l].to) {
                continue;
            }
            let poly = match self.coarse[l] {
                None => self.polynomial(l, at),
                Some(slot) => {
                    // A receiver with its own step n·H takes its inputs at
                    // its communication points only.
                    let n = slaves[self.links[l].to].coupled.decimation;
                    if !at.n.is_multiple_of(n) {
                        continue;
                    }
                    let y = self.history[l][0];
                    let c = &mut self.history[slot];
                    *c = [y, c[0], c[1]];
                    let k = if self.links[l].interpolate {
                        self.order
                    } else {
                        0
                    };
                    let m = usize::try_from(at.n / n).unwrap_or(usize::MAX);
                    extrapolate(&self.history[slot], k.min(m), n as f64 * at.h, None)
                }
            };
            self.set(slaves, l, poly)?;
        }
        match self.own_steps {
            None => Ok(()),
            Some(grid) => self.step_own(slaves, at, grid),
        }
    }

    /// The instances with their own communication step n·H whose step
    /// ends at T_{N+1}: each steps from T_{N+1−n} over n·H (its outputs
    /// held for the others until then).
    /// Out of line: systems without own steps skip it before the call.
    #[inline(never)]
    fn step_own(
        &mut self,
        slaves: &mut [Slave],
        at: StepAt,
        (start, h): (f64, f64),
    ) -> Result<(), MasterError> {
        for slave in slaves.iter_mut().filter(|s| s.coupled.decimation > 1) {
            let n = slave.coupled.decimation;
            if (at.n + 1).is_multiple_of(n) {
                let t = start + (at.n + 1 - n) as f64 * h;
                slave.do_step(t, n as f64 * h)?;
            }
        }
        Ok(())
    }

    /// After the method's step: read the senders at T_{N+1} (those not read
    /// by the Gauss–Seidel sweep) and shift the histories.
    pub fn receive(&mut self, slaves: &mut [Slave]) -> Result<(), MasterError> {
        self.read_next(slaves)?;
        self.shift();
        Ok(())
    }

    /// Read the senders at T_{N+1} not read by the Gauss–Seidel sweep.
    fn read_next(&mut self, slaves: &mut [Slave]) -> Result<(), MasterError> {
        for l in 0..self.links.len() {
            if !self.fresh[self.links[l].from] {
                self.next[l] = self.read(slaves, l, Run::Signal)?;
            }
        }
        Ok(())
    }

    /// Start every history at the values at T_{N+1} (the step is accepted).
    fn shift(&mut self) {
        for (h, &next) in self.history.iter_mut().zip(&self.next) {
            *h = [next, h[0], h[1]];
        }
        for l in 0..self.texts.len() {
            if self.texts[l].all.len() > TEXTS_KEPT {
                self.keep_held_texts(l);
            }
        }
    }

    /// Rebuild String link `l`'s table from the texts its values still
    /// stand for (the step is accepted: no other values of the link are
    /// kept, a saved state has its own copy of the table), `""` first.
    #[cold]
    fn keep_held_texts(&mut self, l: usize) {
        let old = std::mem::take(&mut self.texts[l]);
        let mut kept = Texts::default();
        kept.index_of(String::new());
        let mut remap = |v: &mut f64| {
            let text = old.all.get(*v as usize).cloned().unwrap_or_default();
            *v = kept.index_of(text) as f64;
        };
        self.history[l].iter_mut().for_each(&mut remap);
        if let Some(slot) = self.coarse[l] {
            self.history[slot].iter_mut().for_each(&mut remap);
        }
        remap(&mut self.next[l]);
        self.texts[l] = kept;
    }

    /// The sender's polynomial over the step, as link `l`'s receiver takes
    /// it: through y_{N+1} when the sender has stepped already
    /// (Gauss–Seidel), or in an iterated step's repetitions, else
    /// extrapolated from y_N, y_{N-1}, …; degree 0 (held) for a receiver
    /// that cannot interpolate.
    fn polynomial(&self, l: usize, at: StepAt) -> Taylor {
        let link = &self.links[l];
        let n = usize::try_from(at.n).unwrap_or(usize::MAX);
        let k = if link.interpolate { self.order } else { 0 };
        let history = &self.history[l];
        if self.fresh[link.from] || self.iterating {
            interpolate(self.next[l], history, k.min(n + 1), at.h, at.past)
        } else {
            extrapolate(history, k.min(n), at.h, at.past)
        }
    }

    /// Read link `l`'s sender (Integer and Boolean as numbers, String as
    /// the index of its text).
    fn read(&mut self, slaves: &mut [Slave], l: usize, run: Run) -> Result<f64, MasterError> {
        let link = &self.links[l];
        let slave = &mut slaves[link.from];
        let value = match link.kind {
            Kind::Real => match link.from_element {
                Some(e) => {
                    let buf = &mut slave.signal_buf;
                    buf.resize(e.count, 0.0);
                    slave.backend.get_reals(&[link.from_vr], buf)?;
                    buf[e.index]
                }
                None => {
                    let mut v = [0.0];
                    slave.backend.get_reals(&[link.from_vr], &mut v)?;
                    v[0]
                }
            },
            Kind::Integer => {
                let mut v = [0];
                match link.from_element {
                    Some(e) => {
                        let mut all = vec![0; e.count];
                        slave.backend.get_integers(&[link.from_vr], &mut all)?;
                        v[0] = all[e.index];
                    }
                    None => slave.backend.get_integers(&[link.from_vr], &mut v)?,
                }
                match integer_value(v[0]) {
                    (x, true) => x,
                    (_, false) => {
                        return Err(MasterError::Connection {
                            connection: link.name.clone(),
                            reason: format!(
                                "'{}' = {} at t = {} has no exact Real value (beyond ±2^53), \
                                 and a connection carries Reals",
                                link.variable,
                                v[0],
                                crate::Time(slave.backend.time())
                            ),
                        })
                    }
                }
            }
            Kind::Boolean => {
                let mut v = [false];
                match link.from_element {
                    Some(e) => {
                        let mut all = vec![false; e.count];
                        slave.backend.get_booleans(&[link.from_vr], &mut all)?;
                        v[0] = all[e.index];
                    }
                    None => slave.backend.get_booleans(&[link.from_vr], &mut v)?,
                }
                f64::from(u8::from(v[0]))
            }
            Kind::String => return self.read_text(slaves, l),
        };
        match link.kind {
            Kind::Real => slave.counters.get_reals += 1,
            Kind::Integer => slave.counters.get_integers += 1,
            Kind::Boolean => slave.counters.get_booleans += 1,
            Kind::String => {}
        }
        if !value.is_finite() {
            return Err(slave.non_finite(link.variable.clone(), value, run));
        }
        Ok(value)
    }

    /// Set link `l`'s receiver to `gain·p + offset` (with its derivatives
    /// when it interpolates and k > 0).
    fn set(&self, slaves: &mut [Slave], l: usize, p: Taylor) -> Result<(), MasterError> {
        let link = &self.links[l];
        let slave = &mut slaves[link.to];
        let vr = [link.to_vr];
        match link.kind {
            _ if link.to_element.is_some() => {
                let e = link.to_element.expect("an element");
                let value = match link.kind {
                    Kind::Real => StartValue::Real(link.gain * p.value + link.offset),
                    // Values read from an Integer output: exact in f64 (checked by `read`).
                    Kind::Integer => StartValue::Integer(p.value as i64),
                    Kind::Boolean => StartValue::Boolean(p.value != 0.0),
                    Kind::String => StartValue::String(self.text(l, p.value).to_string()),
                };
                slave.set_array_element(link.to_vr, e, value)?;
            }
            Kind::Real => {
                let value = link.gain * p.value + link.offset;
                let orders = [1, 2];
                let d = [link.gain * p.d1, link.gain * p.d2];
                let n = if link.interpolate {
                    self.order.min(2)
                } else {
                    0
                };
                slave.backend.set_inputs(&Inputs {
                    vrs: &vr,
                    values: &[value],
                    derivative_vrs: &[vr[0]; 2][..n],
                    orders: &orders[..n],
                    derivatives: &d[..n],
                })?;
                if n > 0 {
                    slave.counters.set_input_derivatives += 1;
                }
            }
            // Values read from an Integer output: exact in f64 (checked by `read`).
            Kind::Integer => slave.backend.set_integers(&vr, &[p.value as Int])?,
            Kind::Boolean => slave.backend.set_booleans(&vr, &[p.value != 0.0])?,
            Kind::String => slave.backend.set_strings(&vr, &[self.text(l, p.value)])?,
        }
        match link.kind {
            Kind::Real => slave.counters.set_reals += 1,
            Kind::Integer => slave.counters.set_integers += 1,
            Kind::Boolean => slave.counters.set_booleans += 1,
            Kind::String => slave.counters.set_strings += 1,
        }
        Ok(())
    }

    /// The text of String link `l` that `value` stands for (an index into
    /// its texts; a value held over a step is one of them).
    fn text(&self, l: usize, value: f64) -> &str {
        let texts = &self.texts[l].all;
        texts.get(value as usize).map_or("", String::as_str)
    }

    /// Read String link `l`'s sender: the index of its text among the
    /// texts the link has carried (a new text is added). Allocates, for
    /// String links only.
    #[inline(never)]
    fn read_text(&mut self, slaves: &mut [Slave], l: usize) -> Result<f64, MasterError> {
        let link = &self.links[l];
        let slave = &mut slaves[link.from];
        let text = match link.from_element {
            Some(e) => {
                let mut all = vec![String::new(); e.count];
                slave.backend.get_strings(&[link.from_vr], &mut all)?;
                std::mem::take(&mut all[e.index])
            }
            None => {
                let mut v = [String::new()];
                slave.backend.get_strings(&[link.from_vr], &mut v)?;
                std::mem::take(&mut v[0])
            }
        };
        slave.counters.get_strings += 1;
        Ok(self.texts[l].index_of(text) as f64)
    }
}

/// The texts a String link has carried, each once, and where each is.
#[derive(Debug, Default)]
struct Texts {
    all: Vec<String>,
    index: HashMap<String, usize>,
}

impl Texts {
    /// The index of `text`, added if new.
    fn index_of(&mut self, text: String) -> usize {
        if let Some(&i) = self.index.get(&text) {
            return i;
        }
        self.all.push(text.clone());
        self.index.insert(text, self.all.len() - 1);
        self.all.len() - 1
    }
}

/// What [`solve_loop`] did.
struct Solved {
    converged: bool,
    /// Newton stopped on a singular Jacobian.
    singular: bool,
    /// Updates of v: fixed-point sweeps and Newton updates.
    updates: usize,
    /// Runs of G.
    runs: usize,
    /// max over the links of |v − G(v)| / (tolerance·max(1, |v|)) at the
    /// last run: ≤ 1 is converged.
    residual: f64,
}

/// Solve v = G(v), a loop's values (one per link) against G, one run that
/// sets every receiver from v and reads every sender (`apply(v, g)` puts
/// G(v) into g). First G(v); then up to `sweeps` fixed-point updates
/// v ← G(v), each followed by a run; then up to `newton` Newton updates on
/// the Real links `real` of r(v) = v − G(v), ∂r/∂v = I − ∂G/∂v from one run
/// per Real link with v_j increased by 1e-7·max(1, |v_j|) (the other links
/// take G's value), each followed by a run at the new v. Converged, and
/// stopped, as soon as a run gives |v_l − G(v)_l| ≤ tolerance·max(1, |v_l|)
/// for every link l, and equal texts on the String links `text` (a text
/// that differs counts as 1/tolerance, at least 2). On return `g` holds
/// G(v) of the last run, which was at `v` (after a singular Jacobian G(v)
/// is run once more).
fn solve_loop(
    (v, g): (&mut [f64], &mut [f64]),
    (real, text): (&[usize], &[usize]),
    (sweeps, newton): (usize, usize),
    tolerance: f64,
    solver: &mut Solver,
    mut apply: impl FnMut(&[f64], &mut [f64]) -> Result<(), MasterError>,
) -> Result<Solved, MasterError> {
    let residual = |v: &[f64], g: &[f64]| {
        let numbers = v.iter().zip(g.iter()).fold(0.0_f64, |worst, (&v, &g)| {
            worst.max((v - g).abs() / (tolerance * v.abs().max(1.0)))
        });
        // String links: an index is its text, equal or not.
        let differs = text.iter().any(|&l| v[l] != g[l]);
        if differs {
            numbers.max((1.0 / tolerance).max(2.0))
        } else {
            numbers
        }
    };
    let n = v.len();
    apply(v, g)?;
    let mut solved = Solved {
        converged: false,
        singular: false,
        updates: 0,
        runs: 1,
        residual: residual(v, g),
    };
    for _ in 0..sweeps {
        if solved.residual <= 1.0 {
            break;
        }
        v.copy_from_slice(g);
        apply(v, g)?;
        solved.updates += 1;
        solved.runs += 1;
        solved.residual = residual(v, g);
    }
    let mut bumped = vec![0.0; n];
    let mut gb = vec![0.0; n];
    for _ in 0..newton {
        if solved.residual <= 1.0 {
            break;
        }
        // Non-Real links take G's value; the Real ones a Newton step on
        // r(v) = v − G(v), ∂r/∂v = I − ∂G/∂v.
        let is_real = |l: &usize| real.contains(l);
        for l in (0..n).filter(|l| !is_real(l)) {
            v[l] = g[l];
        }
        let k = real.len();
        let mut w = vec![0.0; k * k];
        for (j, &lj) in real.iter().enumerate() {
            let delta = 1e-7 * v[lj].abs().max(1.0);
            bumped.copy_from_slice(v);
            bumped[lj] += delta;
            apply(&bumped, &mut gb)?;
            solved.runs += 1;
            for (i, &li) in real.iter().enumerate() {
                let identity = if i == j { 1.0 } else { 0.0 };
                w[i + j * k] = identity - (gb[li] - g[li]) / delta;
            }
        }
        let (a, b) = solver.system(k);
        a.copy_from_slice(&w);
        for (i, &li) in real.iter().enumerate() {
            b[i] = v[li] - g[li];
        }
        let Ok(step) = solver.solve(0.0, "signal loop", 1e14) else {
            solved.singular = true;
            apply(v, g)?;
            solved.runs += 1;
            solved.residual = residual(v, g);
            return Ok(solved);
        };
        for (&li, s) in real.iter().zip(step) {
            v[li] -= s;
        }
        apply(v, g)?;
        solved.updates += 1;
        solved.runs += 1;
        solved.residual = residual(v, g);
    }
    solved.converged = solved.residual <= 1.0;
    Ok(solved)
}

/// `inst.variable` split at the first dot.
/// Gauss–Seidel's stages: `sequence` cut into runs of consecutive
/// instances, each cut before an instance that receives from one already
/// in its run.
fn stages(sequence: &[usize], links: &[Link]) -> Vec<std::ops::Range<usize>> {
    let mut stages = Vec::new();
    let mut begin = 0;
    for (i, &s) in sequence.iter().enumerate() {
        let stage = &sequence[begin..i];
        if links.iter().any(|l| l.to == s && stage.contains(&l.from)) {
            stages.push(begin..i);
            begin = i;
        }
    }
    if begin < sequence.len() {
        stages.push(begin..sequence.len());
    }
    stages
}

fn split<'a>(name: &str, text: &'a str) -> Result<(&'a str, &'a str), MasterError> {
    text.split_once('.').ok_or_else(|| MasterError::Connection {
        connection: name.to_string(),
        reason: format!("'{text}' is not <instance>.<variable>"),
    })
}

fn kind_of(var: &ScalarVariable) -> Option<Kind> {
    match var.base_type() {
        BaseType::Real => Some(Kind::Real),
        BaseType::Integer | BaseType::Enumeration => Some(Kind::Integer),
        BaseType::Boolean => Some(Kind::Boolean),
        // FMI 3.0 Binary values are not connected.
        BaseType::String if var.value_type == ValueType::String => Some(Kind::String),
        BaseType::String => None,
    }
}

fn unit_of(var: &ScalarVariable) -> Option<&str> {
    var.real().and_then(|r| r.attributes.unit.as_deref())
}

/// One connection checked against the FMUs: an output to an input of the
/// same type; with the error to report if the units differ (after the
/// loops, which say more about the system).
fn resolve(
    c: &ConnectionSpec,
    slaves: &[Slave],
) -> Result<(Link, Option<MasterError>), MasterError> {
    let name = format!("{} → {}", c.from, c.to);
    let owner = format!("connection {name}");
    let names = slaves.iter().map(|s| s.name.as_str());
    let end = |text: &str, causality: Causality, role: &str| {
        let (instance, variable) = split(&name, text)?;
        let s = find_instance(&owner, instance, names.clone())?;
        let slave = &slaves[s];
        let place = format!("{owner}, {role}");
        let md = slave.fmu.model_description();
        let (var, element) = crate::spec::names::element(
            md,
            &slave.arrays,
            &place,
            &slave.name,
            || crate::spec::names::fmu_file(slave.fmu.path()),
            variable,
        )?;
        let refuse = |reason: &str| MasterError::ArrayElement {
            place: place.clone(),
            instance: slave.name.clone(),
            name: variable.to_string(),
            reason: reason.to_string(),
        };
        if element.is_none() && var.is_array() {
            return Err(refuse(
                "it is an array; a signal connection joins one value: name an element",
            ));
        }
        let var = var.clone();
        let kind = kind_of(&var);
        if var.causality != causality || kind.is_none() {
            return Err(MasterError::WrongVariable {
                instance: instance.to_string(),
                variable: variable.to_string(),
                found: describe(&var),
                role: format!("'{role}' of {owner}"),
                expected: format!(
                    "a Real, Integer, Boolean or String {}",
                    if causality == Causality::Output {
                        "output"
                    } else {
                        "input"
                    }
                ),
            });
        }
        Ok((s, var, element, kind.unwrap_or(Kind::Real)))
    };
    let (from, out, from_element, kind) = end(&c.from, Causality::Output, "from")?;
    let (to, input, to_element, to_kind) = end(&c.to, Causality::Input, "to")?;
    let fail = |reason: String| MasterError::Connection {
        connection: name.clone(),
        reason,
    };
    if kind != to_kind {
        return Err(fail(format!(
            "{} is {} and {} is {}: a connection joins variables of one type",
            c.from,
            describe(&out),
            c.to,
            describe(&input)
        )));
    }
    if kind != Kind::Real && (c.gain.is_some() || c.offset.is_some()) {
        return Err(fail(
            "gain and offset apply to Real connections only".to_string(),
        ));
    }
    let units = match (unit_of(&out), unit_of(&input)) {
        // A gain or offset is the user's conversion.
        _ if c.gain.is_some() || c.offset.is_some() => None,
        (Some(a), Some(b)) if a != b => {
            let dimension = |s: usize, var: &ScalarVariable| {
                crate::units::unit_of(slaves[s].fmu.model_description(), var).and_then(|u| u.1)
            };
            let convert = match (dimension(from, &out), dimension(to, &input)) {
                // Two names of one unit (`N.m`, `J`): nothing to convert.
                (Some(da), Some(db)) if da.same(&db) => Ok(()),
                (Some(da), Some(db)) => Err(crate::units::Dimension::conversion(&da, &db)),
                _ => Err(None),
            };
            convert.err().map(|conversion| {
                let how = match conversion {
                    Some((gain, 0.0)) => format!("gain = {gain} on the connection converts"),
                    Some((gain, offset)) => {
                        format!("gain = {gain}, offset = {offset} on the connection convert")
                    }
                    None => "set gain (and offset) on the connection to convert".into(),
                };
                fail(format!(
                    "{} is in '{a}' and {} in '{b}': units differ; {how} \
                     (to = gain·from + offset)",
                    c.from, c.to
                ))
            })
        }
        _ => None,
    };
    let link = Link {
        name,
        variable: c
            .from
            .split_once('.')
            .map_or_else(|| out.name.clone(), |(_, v)| v.to_string()),
        from,
        from_vr: out.value_reference,
        from_element,
        to,
        to_vr: input.value_reference,
        to_element,
        kind,
        gain: c.gain.unwrap_or(1.0),
        offset: c.offset.unwrap_or(0.0),
        interpolate: kind == Kind::Real
            && to_element.is_none()
            && slaves[to].interpolates(input.value_reference),
    };
    Ok((link, units))
}

/// Whether instance `slave`'s model description says which inputs its output
/// `output` depends on (a `dependencies` list in ModelStructure/Outputs), so
/// that [`feeds_through`] knows rather than assumes.
fn declares_dependencies(slave: &Slave, output: u32) -> bool {
    let md = slave.fmu.model_description();
    let Some(o) = md
        .model_variables
        .iter()
        .position(|v| v.value_reference == output && v.causality == Causality::Output)
        .map(|i| i + 1)
    else {
        return false;
    };
    md.model_structure
        .outputs
        .iter()
        .any(|u| u.index == o && u.dependencies.is_some())
}

/// Whether output `output` of instance `slave` depends directly on input
/// `input` (ModelStructure/Outputs; an output listed without dependencies
/// depends on every input).
pub(crate) fn feeds_through(slave: &Slave, input: u32, output: u32) -> bool {
    let md = slave.fmu.model_description();
    let variable = |vr: u32, causality: Causality| {
        md.model_variables
            .iter()
            .position(|v| v.value_reference == vr && v.causality == causality)
            .map(|i| i + 1)
    };
    let (Some(i), Some(o)) = (
        variable(input, Causality::Input),
        variable(output, Causality::Output),
    ) else {
        return true;
    };
    match md.model_structure.outputs.iter().find(|u| u.index == o) {
        // Not listed: no structure information, assume the worst.
        None => true,
        Some(u) => u.dependencies.as_ref().is_none_or(|d| d.contains(&i)),
    }
}

/// The direct-feedthrough loops among the connections: link a feeds link b
/// when b's sender output depends directly on a's receiver input; a loop is
/// a set of links each reachable from every other (a strongly connected
/// part with a cycle), its links in file order. Loops are in the order of
/// their first link.
fn find_loops(links: &[Link], slaves: &[Slave]) -> Vec<Vec<usize>> {
    let n = links.len();
    let feeds =
        |a: &Link, b: &Link| a.to == b.from && feeds_through(&slaves[a.to], a.to_vr, b.from_vr);
    // reach[a][b]: b is reachable from a in one or more links.
    let mut reach = vec![vec![false; n]; n];
    for (start, row) in reach.iter_mut().enumerate() {
        let mut stack = vec![start];
        while let Some(l) = stack.pop() {
            for next in 0..n {
                if !row[next] && feeds(&links[l], &links[next]) {
                    row[next] = true;
                    stack.push(next);
                }
            }
        }
    }
    let mut placed = vec![false; n];
    let mut loops = Vec::new();
    for l in 0..n {
        if placed[l] || !reach[l][l] {
            continue;
        }
        let members: Vec<usize> = (l..n).filter(|&m| reach[l][m] && reach[m][l]).collect();
        for &m in &members {
            placed[m] = true;
        }
        loops.push(members);
    }
    loops
}

/// The instances' own communication steps (`step` of an `[[instance]]`):
/// each a whole multiple n·H of the macro step, for instances coupled by
/// signals only, with the Jacobi scheme, without adaptive steps or iterated
/// signals (which close loops at every macro step). Sets each slave's
/// `decimation` n; an instance with n > 1 is stepped by the signals, not by
/// the method.
fn decimate(spec: &SystemSpec, slaves: &mut [Slave]) -> Result<(), MasterError> {
    let h = spec.experiment.step;
    let refuse = |instance: &str, reason: String| MasterError::SystemFile {
        path: spec.source_name(),
        reason: format!("instance '{instance}': {reason}"),
    };
    for (inst, slave) in spec.instances.iter().zip(slaves.iter_mut()) {
        let Some(step) = inst.step else { continue };
        let ratio = step / h;
        let n = ratio.round();
        if !(step.is_finite() && n >= 1.0 && (ratio - n).abs() <= 1e-9 * ratio) {
            return Err(refuse(
                &inst.name,
                format!("step = {step} is not a whole multiple of the system's macro step H = {h}"),
            ));
        }
        let n = n as u64;
        if n == 1 {
            continue;
        }
        let why = if slave.is_coupled() || slave.coupled_len() > 0 {
            Some("it is in a constraint, joint or coupling variable, which every macro step solves")
        } else if spec.step_control.is_some() {
            Some("the system has adaptive macro steps ([step_control])")
        } else if spec.signals.iterations.is_some() {
            Some("the system iterates its signals at every macro step ([signals] iterations)")
        } else if spec.signals.scheme() != SignalScheme::Jacobi {
            Some("its signals use the Gauss-Seidel scheme; per-instance steps run with Jacobi")
        } else {
            None
        };
        if let Some(why) = why {
            return Err(refuse(
                &inst.name,
                format!("step = {step} ({n}·H) is refused: {why}"),
            ));
        }
        slave.coupled.decimation = n;
        slave.stepped_ahead = true;
    }
    Ok(())
}
