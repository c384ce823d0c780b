//! The systems of the `scale` benchmark, written with array blocks
//! (`count = N`, docs/system-file.md): an oscillator chain, a planar
//! pendulum chain and a binary tree of links, each of `n` instances.

use tether_master::SystemSpec;

use crate::workspace_root;

/// A family of systems that grows with the number of instances.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Family {
    /// N exact-mode oscillators in a row, N − 1 rigid links `x_{i+1} − x_i = 0`.
    OscillatorChain,
    /// N `link` bars hanging from a pivot, each end B hinged to the next one's end A.
    PendulumChain,
    /// N `link` bars as a binary tree: bar k carries bars 2k + 1 and 2k + 2 at its end B.
    Tree,
}

impl Family {
    pub fn name(self) -> &'static str {
        match self {
            Family::OscillatorChain => "oscillator chain",
            Family::PendulumChain => "pendulum chain",
            Family::Tree => "tree",
        }
    }

    /// The system file text for `n ≥ 2` instances: Method 1 on index 2
    /// (β = 2e-3), H = 1e-3, `steps` macro steps.
    pub fn toml(self, n: usize, steps: u64) -> String {
        let fmus = workspace_root().join("target/fmus");
        let stop = steps as f64 * 1e-3;
        let head = format!(
            "name = \"{name}, N = {n}\"\n\
             [experiment]\nstop = {stop:?}\nstep = 1e-3\n\
             [method]\nkind = \"baumgarte\"\nbeta = 2e-3\n\
             [coupling]\nparallel = \"off\"\n",
            name = self.name()
        );
        // Bars at −45°: end A of a bar at depth d is at d·(cos, sin)(−45°).
        let diagonal = std::f64::consts::FRAC_1_SQRT_2;
        let bar =
            "m = 1.0, J = 0.08333333333333333, l = 1.0, xP = -0.5, phi0 = -0.7853981633974483";
        match self {
            Family::OscillatorChain => {
                let fmu = fmus.join("oscillator.fmu");
                format!(
                    r#"{head}
[[instance]]
name = "mass{{i}}"
count = {n}
fmu = "{fmu}"
parameters = {{ m = 1.0, c = 1000.0, d = 10.0, x0 = 0.0, v0 = 100.0, exact = true }}

[[constraint]]
name = "link{{i}}"
count = {links}
position = "mass{{i + 1}}.x - mass{{i}}.x"
velocity = "mass{{i + 1}}.v - mass{{i}}.v"
acceleration = "mass{{i + 1}}.a - mass{{i}}.a"
drives = "mass{{i}}.F - mass{{i + 1}}.F"
"#,
                    fmu = fmu.display(),
                    links = n - 1
                )
            }
            Family::PendulumChain | Family::Tree => {
                let fmu = fmus.join("link.fmu");
                // Depth of bar i + 1: i + 1 in a chain, log2(i + 2) in the tree.
                let (depth, parent) = match self {
                    Family::PendulumChain => ("i + 1", "i"),
                    _ => ("log2(i + 2)", "i / 2"),
                };
                format!(
                    r#"{head}
[[instance]]
name = "bar0"
fmu = "{fmu}"
parameters = {{ {bar}, pinned = true, x0 = 0.0, y0 = 0.0 }}

[[instance]]
name = "bar{{i + 1}}"
count = {links}
fmu = "{fmu}"
parameters = {{ {bar}, x0 = "{{{diagonal:?} * ({depth})}}", y0 = "{{-{diagonal:?} * ({depth})}}" }}

[[joint]]
name = "hinge{{i}}"
count = {links}
kind = "atpoint"
plane = "xy"
i = "bar{{{parent}}}.B"
j = "bar{{i + 1}}.A"
"#,
                    fmu = fmu.display(),
                    links = n - 1
                )
            }
        }
    }

    /// The system, its FMU packaged first.
    pub fn spec(self, n: usize, steps: u64) -> SystemSpec {
        let fmu = match self {
            Family::OscillatorChain => "oscillator",
            _ => "link",
        };
        tether_fmu_build::workspace_fmu(fmu).expect("package the FMU");
        SystemSpec::from_toml(&self.toml(n, steps)).expect("a valid system")
    }
}
