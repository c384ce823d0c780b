//! The paper's planar double pendulum (Sect. 4.2, EXAMPLES.md §2) in minimal
//! coordinates: Lagrange's equations in the link angles φ1, φ2.
//!
//! Link 1 is pinned to ground at its end A, at the origin, with a torsional spring
//! c_φ (stress-free at φ_ref) and damper d_φ; link 2 hangs at link 1's end B by its
//! end A. Angles are measured from world x to the link axis (A → B); gravity acts in
//! −y. These are the conventions of `fmus/link` and `examples/double_pendulum.toml`
//! (instances `link1`, `link2`), so [`DoublePendulumState::column`] answers to the
//! co-simulation's column names.

use super::{axis_and_normal, integrate, G};

/// Parameters and initial angles of the double pendulum.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DoublePendulum {
    pub m: [f64; 2],
    pub j: [f64; 2],
    pub l: [f64; 2],
    pub c_phi: f64,
    pub d_phi: f64,
    pub phi_ref: f64,
    pub g: f64,
    pub phi0: [f64; 2],
    pub omega0: [f64; 2],
}

/// The paper's parameters: m = 1, J = 1/12, l = 1 for both links, c_φ = 500,
/// d_φ = 50, φ_ref = π/4; φ1(0) = π/4, φ2(0) = −π/4, at rest.
pub const PAPER: DoublePendulum = DoublePendulum {
    m: [1.0, 1.0],
    j: [1.0 / 12.0, 1.0 / 12.0],
    l: [1.0, 1.0],
    c_phi: 500.0,
    d_phi: 50.0,
    phi_ref: std::f64::consts::FRAC_PI_4,
    g: G,
    phi0: [std::f64::consts::FRAC_PI_4, -std::f64::consts::FRAC_PI_4],
    omega0: [0.0, 0.0],
};

/// The double pendulum at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DoublePendulumState {
    pub t: f64,
    /// Link angles φ1, φ2 from world x, rad.
    pub phi: [f64; 2],
    /// Angular velocities, rad/s.
    pub omega: [f64; 2],
    /// Angular accelerations, rad/s².
    pub alpha: [f64; 2],
    /// Joint force on link 1 at its end B (world x, y), N: the planar atpoint joint's
    /// multipliers (λx, λy) with i = `link1.B`, j = `link2.A`. Link 2 feels −λ.
    pub lambda: [f64; 2],
    /// World positions of the markers: link 1's A (the pivot, at the origin) and B
    /// (= link 2's A), link 2's B.
    pub link1_a: [f64; 2],
    pub link1_b: [f64; 2],
    pub link2_b: [f64; 2],
    /// Velocities of link 1's B (= link 2's A) and link 2's B.
    pub link1_b_velocity: [f64; 2],
    pub link2_b_velocity: [f64; 2],
    /// Energy of each link as `fmus/link` reports it (`E`: kinetic + gravity with zero
    /// at y = 0 + spring); their sum is the total, which only the damper lowers.
    pub link_energy: [f64; 2],
}

impl DoublePendulumState {
    /// Total mechanical energy (both links, spring included).
    pub fn energy(&self) -> f64 {
        self.link_energy[0] + self.link_energy[1]
    }

    /// The value of a co-simulation output column of `examples/double_pendulum.toml`:
    /// `link1.phi`, `link2.omega`, `link1.E`, `link2.B.r[1]`, `link1.B.v[2]`,
    /// `link2.A.r[1]` (= `link1.B.r[1]`), … (x, y components; `[3]` is 0).
    /// `None` for a name it does not know.
    pub fn column(&self, name: &str) -> Option<f64> {
        let (link, rest) = name.split_once('.')?;
        let k = match link {
            "link1" => 0,
            "link2" => 1,
            _ => return None,
        };
        match rest {
            "phi" => return Some(self.phi[k]),
            "omega" => return Some(self.omega[k]),
            "E" => return Some(self.link_energy[k]),
            _ => {}
        }
        let (marker, quantity) = rest.split_once('.')?;
        let (quantity, component) = quantity.strip_suffix(']')?.split_once('[')?;
        let component: usize = component.parse().ok()?;
        let (position, velocity) = match (k, marker) {
            (0, "A") => (self.link1_a, [0.0, 0.0]),
            (0, "B") | (1, "A") => (self.link1_b, self.link1_b_velocity),
            (1, "B") => (self.link2_b, self.link2_b_velocity),
            _ => return None,
        };
        let vector = match quantity {
            "r" => position,
            "v" => velocity,
            _ => return None,
        };
        match component {
            1 | 2 => Some(vector[component - 1]),
            3 => Some(0.0),
            _ => None,
        }
    }
}

/// The paper's double pendulum ([`PAPER`]) at `times` (sorted, ≥ 0).
pub fn reference(times: &[f64]) -> Vec<DoublePendulumState> {
    PAPER.solve(times)
}

impl DoublePendulum {
    /// The state at each of `times` (sorted, ≥ 0), integrated from t = 0.
    pub fn solve(&self, times: &[f64]) -> Vec<DoublePendulumState> {
        let y0 = [self.phi0[0], self.phi0[1], self.omega0[0], self.omega0[1]];
        let p = *self;
        let rhs = move |y: &[f64; 4]| {
            let alpha = p.accelerations(y);
            [y[2], y[3], alpha[0], alpha[1]]
        };
        integrate(rhs, y0, times)
            .iter()
            .zip(times)
            .map(|(y, &t)| self.state_at(t, y))
            .collect()
    }

    /// φ̈1, φ̈2 from Lagrange's equations M(φ) φ̈ = Q(φ, φ̇):
    ///
    /// M11 = J1 + m1 l1²/4 + m2 l1², M12 = m2 l1 (l2/2) cos(φ1 − φ2),
    /// M22 = J2 + m2 l2²/4;
    /// Q1 = −m2 l1 (l2/2) sin(φ1 − φ2) φ̇2² − (m1/2 + m2) g l1 cos φ1
    ///      − c_φ (φ1 − φ_ref) − d_φ φ̇1,
    /// Q2 = +m2 l1 (l2/2) sin(φ1 − φ2) φ̇1² − m2 g (l2/2) cos φ2.
    pub fn accelerations(&self, y: &[f64; 4]) -> [f64; 2] {
        let [m1, m2] = self.m;
        let [j1, j2] = self.j;
        let [l1, l2] = self.l;
        let (phi1, phi2, w1, w2) = (y[0], y[1], y[2], y[3]);
        let (s12, c12) = (phi1 - phi2).sin_cos();
        let coupling = m2 * l1 * 0.5 * l2;
        let m11 = j1 + m1 * l1 * l1 / 4.0 + m2 * l1 * l1;
        let m12 = coupling * c12;
        let m22 = j2 + m2 * l2 * l2 / 4.0;
        let q1 = -coupling * s12 * w2 * w2
            - (0.5 * m1 + m2) * self.g * l1 * phi1.cos()
            - self.c_phi * (phi1 - self.phi_ref)
            - self.d_phi * w1;
        let q2 = coupling * s12 * w1 * w1 - m2 * self.g * 0.5 * l2 * phi2.cos();
        let det = m11 * m22 - m12 * m12;
        [(m22 * q1 - m12 * q2) / det, (m11 * q2 - m12 * q1) / det]
    }

    /// Everything at y = (φ1, φ2, φ̇1, φ̇2).
    pub fn state_at(&self, t: f64, y: &[f64; 4]) -> DoublePendulumState {
        let [m1, m2] = self.m;
        let [j1, j2] = self.j;
        let [l1, l2] = self.l;
        let (phi, omega) = ([y[0], y[1]], [y[2], y[3]]);
        let alpha = self.accelerations(y);
        let (e1, n1) = axis_and_normal(phi[0]);
        let (e2, n2) = axis_and_normal(phi[1]);
        // Centre of mass of link 2 and its acceleration; λ = m2 (g⃗ − a2) is the force
        // link 2 exerts on link 1 (Newton for link 2: m2 a2 = −λ + m2 g⃗).
        let a2: Vec<f64> = (0..2)
            .map(|i| {
                l1 * (alpha[0] * n1[i] - omega[0] * omega[0] * e1[i])
                    + 0.5 * l2 * (alpha[1] * n2[i] - omega[1] * omega[1] * e2[i])
            })
            .collect();
        let lambda = [-m2 * a2[0], m2 * (-self.g - a2[1])];
        let b1 = [l1 * e1[0], l1 * e1[1]];
        let vb1 = [l1 * omega[0] * n1[0], l1 * omega[0] * n1[1]];
        let vc2 = [
            vb1[0] + 0.5 * l2 * omega[1] * n2[0],
            vb1[1] + 0.5 * l2 * omega[1] * n2[1],
        ];
        let spring = 0.5 * self.c_phi * (phi[0] - self.phi_ref).powi(2);
        let energy1 = 0.5 * m1 * (0.5 * l1 * omega[0]).powi(2)
            + 0.5 * j1 * omega[0] * omega[0]
            + m1 * self.g * 0.5 * l1 * e1[1]
            + spring;
        let energy2 = 0.5 * m2 * (vc2[0] * vc2[0] + vc2[1] * vc2[1])
            + 0.5 * j2 * omega[1] * omega[1]
            + m2 * self.g * (b1[1] + 0.5 * l2 * e2[1]);
        DoublePendulumState {
            t,
            phi,
            omega,
            alpha,
            lambda,
            link1_a: [0.0, 0.0],
            link1_b: b1,
            link2_b: [b1[0] + l2 * e2[0], b1[1] + l2 * e2[1]],
            link1_b_velocity: vb1,
            link2_b_velocity: [
                vb1[0] + l2 * omega[1] * n2[0],
                vb1[1] + l2 * omega[1] * n2[1],
            ],
            link_energy: [energy1, energy2],
        }
    }
}
