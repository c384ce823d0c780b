//! The paper's slider-crank (Sect. 4.3, EXAMPLES.md §3, geometry in
//! docs/slider-crank.md) in its one minimal coordinate, the crank angle φ1.
//!
//! The crank (link 1) is pinned to ground at its end A at the origin; the rocker
//! (link 2) is pinned at its end A at Q = (d, 0). The inplane joint keeps the crank
//! tip P (crank end B) on the rocker's axis line, so the rocker angle is the direction
//! of P − Q: φ2 = f(φ1). With l1 < d the crank tip never reaches Q and P − Q always
//! points to x < 0, so f is smooth: φ2 = π + atan2(−u_y, −u_x), u = P − Q. No spring,
//! no damper: the total energy is constant.

use super::{axis_and_normal, cross, integrate, G};

/// Parameters and initial state of the slider-crank.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliderCrank {
    /// Masses, moments of inertia about the centres of mass, lengths: crank, rocker.
    pub m: [f64; 2],
    pub j: [f64; 2],
    pub l: [f64; 2],
    /// x of the rocker's pivot Q = (d, 0); the crank's pivot is the origin. l1 < d.
    pub d: f64,
    pub g: f64,
    pub phi1_0: f64,
    pub omega1_0: f64,
}

/// EXAMPLES.md §3: crank length √2, mass √2, J = m l²/12, φ1(0) = π/4 (tip at
/// (1, 1)); rocker length 2, mass 2, J = m l²/12, pinned at (2, 0), φ2(0) = 3π/4;
/// at rest, g = 9.81 in −y.
pub const PAPER: SliderCrank = SliderCrank {
    m: [std::f64::consts::SQRT_2, 2.0],
    j: [std::f64::consts::SQRT_2 * 2.0 / 12.0, 2.0 * 4.0 / 12.0],
    l: [std::f64::consts::SQRT_2, 2.0],
    d: 2.0,
    g: G,
    phi1_0: std::f64::consts::FRAC_PI_4,
    omega1_0: 0.0,
};

/// The slider-crank at one time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SliderCrankState {
    pub t: f64,
    /// Crank and rocker angles from world x (axis from end A to end B), rad.
    pub phi: [f64; 2],
    pub omega: [f64; 2],
    pub alpha: [f64; 2],
    /// The inplane joint's multiplier: the crank tip receives the force λ·n2 and the
    /// rocker −λ·n2 (at the tip), n2 = (−sin φ2, cos φ2) the rocker's normal, which
    /// is the joint axis z_j of `examples/slider_crank.toml` (i = `crank.B`,
    /// j = `rocker.A`, axis_j = [0, 1, 0]).
    pub lambda: f64,
    /// The crank tip (crank end B) and its velocity.
    pub crank_tip: [f64; 2],
    pub crank_tip_velocity: [f64; 2],
    /// The rocker's pivot (rocker end A, fixed) and free end B with its velocity.
    pub rocker_pivot: [f64; 2],
    pub rocker_b: [f64; 2],
    pub rocker_b_velocity: [f64; 2],
    /// Distance of the crank tip from the rocker pivot, along the rocker axis.
    pub slide: f64,
    /// Energy of each link as `fmus/link` reports it (kinetic + gravity, zero at y = 0).
    pub link_energy: [f64; 2],
}

impl SliderCrankState {
    /// Total mechanical energy, constant in the exact solution.
    pub fn energy(&self) -> f64 {
        self.link_energy[0] + self.link_energy[1]
    }

    /// The value of a co-simulation output column of `examples/slider_crank.toml`:
    /// `crank.phi`, `rocker.omega`, `crank.E`, `crank.B.r[1]`, `rocker.B.v[2]`, …
    /// (x, y components; `[3]` is 0). `None` for a name it does not know.
    pub fn column(&self, name: &str) -> Option<f64> {
        let (link, rest) = name.split_once('.')?;
        let k = match link {
            "crank" => 0,
            "rocker" => 1,
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
            (0, "A") => ([0.0, 0.0], [0.0, 0.0]),
            (0, "B") => (self.crank_tip, self.crank_tip_velocity),
            (1, "A") => (self.rocker_pivot, [0.0, 0.0]),
            (1, "B") => (self.rocker_b, self.rocker_b_velocity),
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

/// The paper's slider-crank ([`PAPER`]) at `times` (sorted, ≥ 0).
pub fn reference(times: &[f64]) -> Vec<SliderCrankState> {
    PAPER.solve(times)
}

/// The rocker angle and its first two derivatives with respect to φ1.
struct RockerAngle {
    phi2: f64,
    /// |P − Q|.
    distance: f64,
    d1: f64,
    d2: f64,
}

impl SliderCrank {
    /// Moments of inertia about the pivots (both links are pinned at an end).
    fn pivot_inertia(&self) -> [f64; 2] {
        [0, 1].map(|k| self.j[k] + self.m[k] * self.l[k] * self.l[k] / 4.0)
    }

    /// φ2 = f(φ1), f′ = (u × u′)/|u|², f″ = (u × u″)/|u|² − 2 (u × u′)(u · u′)/|u|⁴
    /// with u = P − Q, u′ = du/dφ1, u″ = d²u/dφ1².
    fn rocker_angle(&self, phi1: f64) -> RockerAngle {
        let l1 = self.l[0];
        let (e1, n1) = axis_and_normal(phi1);
        let u = [l1 * e1[0] - self.d, l1 * e1[1]];
        let du = [l1 * n1[0], l1 * n1[1]];
        let ddu = [-l1 * e1[0], -l1 * e1[1]];
        let uu = u[0] * u[0] + u[1] * u[1];
        let u_x_du = cross(u, du);
        let u_dot_du = u[0] * du[0] + u[1] * du[1];
        RockerAngle {
            phi2: std::f64::consts::PI + (-u[1]).atan2(-u[0]),
            distance: uu.sqrt(),
            d1: u_x_du / uu,
            d2: cross(u, ddu) / uu - 2.0 * u_x_du * u_dot_du / (uu * uu),
        }
    }

    /// φ̈1 from (J1 + J2 f′²) φ̈1 + J2 f′ f″ φ̇1² = −m1 g (l1/2) cos φ1
    /// − m2 g (l2/2) cos φ2 · f′ (J about the pivots).
    pub fn acceleration(&self, phi1: f64, omega1: f64) -> f64 {
        let [j1, j2] = self.pivot_inertia();
        let f = self.rocker_angle(phi1);
        let generalized_force = -self.m[0] * self.g * 0.5 * self.l[0] * phi1.cos()
            - self.m[1] * self.g * 0.5 * self.l[1] * f.phi2.cos() * f.d1;
        (generalized_force - j2 * f.d1 * f.d2 * omega1 * omega1) / (j1 + j2 * f.d1 * f.d1)
    }

    /// The state at each of `times` (sorted, ≥ 0), integrated from t = 0.
    ///
    /// # Panics
    /// If the crank is not shorter than the pivot distance (l1 < d).
    pub fn solve(&self, times: &[f64]) -> Vec<SliderCrankState> {
        assert!(
            self.l[0] < self.d,
            "the slider-crank reference needs l1 < d, got l1 = {}, d = {}",
            self.l[0],
            self.d
        );
        let p = *self;
        let rhs = move |y: &[f64; 2]| [y[1], p.acceleration(y[0], y[1])];
        integrate(rhs, [self.phi1_0, self.omega1_0], times)
            .iter()
            .zip(times)
            .map(|(y, &t)| self.state_at(t, y[0], y[1]))
            .collect()
    }

    /// Everything at (φ1, φ̇1). λ from the rocker's moment about Q:
    /// J2 φ̈2 = −m2 g (l2/2) cos φ2 − λ |P − Q|.
    pub fn state_at(&self, t: f64, phi1: f64, omega1: f64) -> SliderCrankState {
        let [j1, j2] = self.pivot_inertia();
        let [l1, l2] = self.l;
        let f = self.rocker_angle(phi1);
        let alpha1 = self.acceleration(phi1, omega1);
        let omega2 = f.d1 * omega1;
        let alpha2 = f.d1 * alpha1 + f.d2 * omega1 * omega1;
        let lambda = (-self.m[1] * self.g * 0.5 * l2 * f.phi2.cos() - j2 * alpha2) / f.distance;
        let (e1, n1) = axis_and_normal(phi1);
        let (e2, n2) = axis_and_normal(f.phi2);
        let energy = [
            0.5 * j1 * omega1 * omega1 + self.m[0] * self.g * 0.5 * l1 * e1[1],
            0.5 * j2 * omega2 * omega2 + self.m[1] * self.g * 0.5 * l2 * e2[1],
        ];
        SliderCrankState {
            t,
            phi: [phi1, f.phi2],
            omega: [omega1, omega2],
            alpha: [alpha1, alpha2],
            lambda,
            crank_tip: [l1 * e1[0], l1 * e1[1]],
            crank_tip_velocity: [l1 * omega1 * n1[0], l1 * omega1 * n1[1]],
            rocker_pivot: [self.d, 0.0],
            rocker_b: [self.d + l2 * e2[0], l2 * e2[1]],
            rocker_b_velocity: [l2 * omega2 * n2[0], l2 * omega2 * n2[1]],
            slide: f.distance,
            link_energy: energy,
        }
    }
}
