//! A monolithic multibody reference for the 3D examples: rigid bodies in maximal
//! coordinates, the ground joints of the body3d FMU and the joints of `[[joint]]`
//! (docs/joints in docs/system-file.md) as constraint rows at acceleration level with
//! Baumgarte stabilisation, solved at every right-hand-side evaluation and integrated
//! with Dop853 (rtol = atol = 1e-12 by default).
//!
//! It shares no code with the master or with fmus/body3d: its own equations (world
//! angular velocities, Newton–Euler per body, constraint rows with their own
//! Jacobians and velocity terms) and its own parsing of the system file. See
//! docs/reference.md for the formulation.
//!
//! ```no_run
//! use tether_tests::multibody::System;
//! let system = System::from_file("examples/3d_revolute.toml").unwrap();
//! let samples = system.simulate(&[0.0, 0.5, 1.0]).unwrap();
//! let x = samples[2].column("body2.A.r[1]").unwrap();
//! assert!(samples[2].residual < 1e-8);
//! ```

use std::cell::RefCell;
use std::collections::BTreeMap;
use std::path::Path;
use std::rc::Rc;

use nalgebra::{DMatrix, DVector, Matrix3, Quaternion, UnitQuaternion, Vector3};
use ode_solvers::{Dop853, OutputType};

type V3 = Vector3<f64>;
/// The integrator's state vector (ode_solvers uses its own nalgebra version).
type OdeVec = ode_solvers::DVector<f64>;

/// The ground joint of a body (the body3d FMU's `joint` parameter).
#[derive(Clone, Debug, PartialEq)]
pub enum Ground {
    /// A free body.
    None,
    /// The body point `pivot` (body frame, from the CoM) is held at its initial
    /// world position.
    Spherical { pivot: V3 },
    /// Spherical, and the body axis `axis` (body frame) keeps its initial world
    /// direction.
    Revolute { pivot: V3, axis: V3 },
}

/// One rigid body, with the body3d FMU's parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct Body {
    pub name: String,
    pub m: f64,
    /// Principal moments of inertia at the CoM (body axes).
    pub inertia: V3,
    pub gravity: V3,
    /// Initial CoM position, orientation (rotation vector), CoM velocity and
    /// angular velocity, all in world coordinates.
    pub r0: V3,
    pub phi0: V3,
    pub v0: V3,
    pub w0: V3,
    pub ground: Ground,
    /// Marker name → origin in body coordinates from the CoM (marker frame = body
    /// frame).
    pub markers: BTreeMap<String, V3>,
}

impl Body {
    /// A body with the body3d FMU's default parameters and markers `A`, `B` at the CoM.
    pub fn new(name: &str) -> Body {
        Body {
            name: name.to_string(),
            m: 1.0,
            inertia: V3::new(0.1, 0.1, 0.1),
            gravity: V3::new(0.0, 0.0, -9.81),
            r0: V3::zeros(),
            phi0: V3::zeros(),
            v0: V3::zeros(),
            w0: V3::zeros(),
            ground: Ground::None,
            markers: [
                ("A".to_string(), V3::zeros()),
                ("B".to_string(), V3::zeros()),
            ]
            .into_iter()
            .collect(),
        }
    }
}

/// The joint kinds of `[[joint]]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum JointKind {
    AtPoint,
    InPlane,
    Perpendicular,
    Universal,
    Revolute,
    Cylindrical,
    Translational,
    Planar,
    Inline,
    Orientation,
}

impl JointKind {
    pub const ALL: [JointKind; 10] = [
        JointKind::AtPoint,
        JointKind::InPlane,
        JointKind::Perpendicular,
        JointKind::Universal,
        JointKind::Revolute,
        JointKind::Cylindrical,
        JointKind::Translational,
        JointKind::Planar,
        JointKind::Inline,
        JointKind::Orientation,
    ];

    /// The system-file spelling (`kind = "..."`).
    pub fn name(self) -> &'static str {
        match self {
            JointKind::AtPoint => "atpoint",
            JointKind::InPlane => "inplane",
            JointKind::Perpendicular => "perpendicular",
            JointKind::Universal => "universal",
            JointKind::Revolute => "revolute",
            JointKind::Cylindrical => "cylindrical",
            JointKind::Translational => "translational",
            JointKind::Planar => "planar",
            JointKind::Inline => "inline",
            JointKind::Orientation => "orientation",
        }
    }

    pub fn from_name(name: &str) -> Option<JointKind> {
        JointKind::ALL.into_iter().find(|k| k.name() == name)
    }

    /// Number of scalar conditions.
    pub fn rows(self) -> usize {
        match self {
            JointKind::AtPoint => 3,
            JointKind::InPlane | JointKind::Perpendicular => 1,
            JointKind::Universal => 4,
            JointKind::Revolute => 5,
            JointKind::Cylindrical => 4,
            JointKind::Translational => 5,
            JointKind::Planar => 3,
            JointKind::Inline => 2,
            JointKind::Orientation => 3,
        }
    }
}

/// One side of a joint: a body's marker with the joint frame on it.
#[derive(Clone, Debug, PartialEq)]
pub struct JointSide {
    /// Index into [`System::bodies`].
    pub body: usize,
    pub marker: String,
    /// Joint-frame z and x axes in marker coordinates (x is orthonormalised against
    /// z), and the attachment point in marker coordinates.
    pub axis: V3,
    pub reference: V3,
    pub offset: V3,
}

/// A joint between two body markers.
#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    pub name: String,
    pub kind: JointKind,
    pub i: JointSide,
    pub j: JointSide,
}

/// The whole system.
#[derive(Clone, Debug, PartialEq)]
pub struct System {
    pub bodies: Vec<Body>,
    pub joints: Vec<Joint>,
    /// Experiment start time (`[experiment] start`, default 0) and stop time.
    pub start: f64,
    pub stop: Option<f64>,
    /// Baumgarte stabilisation g̈ + 2a ġ + b² g = 0: (a, b) in 1/s. Default (20, 20).
    pub baumgarte: (f64, f64),
    /// Dop853's rtol = atol. Default 1e-12.
    pub tolerance: f64,
}

/// Kinematics of one marker (world frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MarkerState {
    pub r: V3,
    /// Rotation marker → world (= body → world).
    pub rot: Matrix3<f64>,
    pub v: V3,
    pub w: V3,
    pub a: V3,
    pub alpha: V3,
}

/// The reference solution at one time.
#[derive(Clone, Debug, PartialEq)]
pub struct Sample {
    pub t: f64,
    /// `"<body>.<marker>"` → marker kinematics.
    pub markers: BTreeMap<String, MarkerState>,
    /// Largest |g| over every constraint row (ground joints and `[[joint]]`s).
    pub residual: f64,
    /// Largest |ġ| over every row.
    pub velocity_residual: f64,
    /// Joint name → largest |g| of its rows.
    pub joint_residuals: BTreeMap<String, f64>,
    /// Joint name → its multipliers, in the row order of the joint definitions
    /// (force +λe on side i, see docs/reference.md).
    pub multipliers: BTreeMap<String, Vec<f64>>,
    /// Total kinetic plus potential energy (zero potential at the world origin).
    pub energy: f64,
}

impl Sample {
    /// A value by CSV column name: `<body>.<marker>.r[k]`, `.R[i,j]`, `.v[k]`,
    /// `.w[k]`, `.a[k]`, `.alpha[k]` (1-based), or `<joint>.lambda[k]`.
    pub fn column(&self, name: &str) -> Option<f64> {
        let open = name.rfind('[')?;
        let inner = name[open + 1..].strip_suffix(']')?;
        let (path, quantity) = name[..open].rsplit_once('.')?;
        let index = |s: &str| {
            s.trim()
                .parse::<usize>()
                .ok()
                .filter(|k| (1..=3).contains(k))
        };
        if quantity == "lambda" {
            let k: usize = inner.trim().parse().ok()?;
            return self.multipliers.get(path)?.get(k.checked_sub(1)?).copied();
        }
        let m = self.markers.get(path)?;
        if quantity == "R" {
            let (i, j) = inner.split_once(',')?;
            return Some(m.rot[(index(i)? - 1, index(j)? - 1)]);
        }
        let k = index(inner)? - 1;
        let v = match quantity {
            "r" => m.r,
            "v" => m.v,
            "w" => m.w,
            "a" => m.a,
            "alpha" => m.alpha,
            _ => return None,
        };
        Some(v[k])
    }
}

// ---------------------------------------------------------------------------
// Parsing the system file.

fn number(value: &toml::Value, what: &str) -> Result<f64, String> {
    match value {
        toml::Value::Float(x) => Ok(*x),
        toml::Value::Integer(i) => Ok(*i as f64),
        other => Err(format!("{what} must be a number, got {other}")),
    }
}

fn vector(value: &toml::Value, what: &str) -> Result<V3, String> {
    let items = value
        .as_array()
        .filter(|a| a.len() == 3)
        .ok_or_else(|| format!("{what} must be a list of 3 numbers"))?;
    Ok(V3::new(
        number(&items[0], what)?,
        number(&items[1], what)?,
        number(&items[2], what)?,
    ))
}

fn body_from_parameters(name: &str, parameters: Option<&toml::Value>) -> Result<Body, String> {
    let mut body = Body::new(name);
    let (mut joint, mut pivot, mut axis) = (0i64, V3::zeros(), V3::z());
    let (mut offset_a, mut offset_b) = (V3::zeros(), V3::zeros());
    let empty = toml::Table::new();
    let table = match parameters {
        None => &empty,
        Some(p) => p
            .as_table()
            .ok_or_else(|| format!("instance {name:?}: parameters must be a table"))?,
    };
    for (key, value) in table {
        let what = format!("instance {name:?}: parameter {key:?}");
        if key == "joint" {
            joint = value
                .as_integer()
                .ok_or_else(|| format!("{what} must be an integer"))?;
            continue;
        }
        let x = number(value, &what)?;
        let component = |prefix: &str| -> Option<usize> {
            let rest = key.strip_prefix(prefix)?.strip_prefix('[')?;
            let k: usize = rest.strip_suffix(']')?.parse().ok()?;
            (1..=3).contains(&k).then_some(k - 1)
        };
        match key.as_str() {
            "m" => body.m = x,
            "Jxx" => body.inertia.x = x,
            "Jyy" => body.inertia.y = x,
            "Jzz" => body.inertia.z = x,
            "gx" => body.gravity.x = x,
            "gy" => body.gravity.y = x,
            "gz" => body.gravity.z = x,
            "tolerance" => {}
            _ => {
                let targets: [(&str, &mut V3); 8] = [
                    ("r0", &mut body.r0),
                    ("phi0", &mut body.phi0),
                    ("v0", &mut body.v0),
                    ("w0", &mut body.w0),
                    ("pivot", &mut pivot),
                    ("axis", &mut axis),
                    ("A.offset", &mut offset_a),
                    ("B.offset", &mut offset_b),
                ];
                let mut found = false;
                for (prefix, target) in targets {
                    if let Some(k) = component(prefix) {
                        target[k] = x;
                        found = true;
                    }
                }
                if !found {
                    return Err(format!("{what} is not a body3d parameter"));
                }
            }
        }
    }
    body.markers = [("A".to_string(), offset_a), ("B".to_string(), offset_b)]
        .into_iter()
        .collect();
    body.ground = match joint {
        0 => Ground::None,
        1 => Ground::Spherical { pivot },
        2 => Ground::Revolute { pivot, axis },
        other => {
            return Err(format!(
                "instance {name:?}: joint must be 0, 1 or 2, got {other}"
            ))
        }
    };
    Ok(body)
}

fn side(joint: &toml::Table, name: &str, key: &str, bodies: &[Body]) -> Result<JointSide, String> {
    let what = format!("joint {name:?}: {key}");
    let port = joint
        .get(key)
        .and_then(toml::Value::as_str)
        .ok_or_else(|| format!("{what} must be a string \"<instance>.<marker>\""))?;
    let (instance, marker) = port
        .split_once('.')
        .ok_or_else(|| format!("{what} = {port:?} is not \"<instance>.<marker>\""))?;
    let body = bodies
        .iter()
        .position(|b| b.name == instance)
        .ok_or_else(|| format!("{what}: no instance {instance:?}"))?;
    if !bodies[body].markers.contains_key(marker) {
        return Err(format!(
            "{what}: instance {instance:?} has no marker {marker:?}"
        ));
    }
    let get = |field: &str, default: V3| -> Result<V3, String> {
        let full = format!("{field}_{key}");
        match joint.get(&full) {
            None => Ok(default),
            Some(v) => vector(v, &format!("joint {name:?}: {full}")),
        }
    };
    Ok(JointSide {
        body,
        marker: marker.to_string(),
        axis: get("axis", V3::z())?,
        reference: get("ref", V3::x())?,
        offset: get("offset", V3::zeros())?,
    })
}

impl System {
    /// Reads a system file: every `[[instance]]` must be a body3d FMU; `[[joint]]`s
    /// as in docs/system-file.md (`plane` is not supported: 3D only).
    pub fn from_file(path: impl AsRef<Path>) -> Result<System, String> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        System::from_toml(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// Like [`System::from_file`], from the file's text.
    pub fn from_toml(text: &str) -> Result<System, String> {
        let doc: toml::Table = text.parse().map_err(|e| format!("invalid TOML: {e}"))?;
        let mut bodies = Vec::new();
        let instances = doc
            .get("instance")
            .and_then(toml::Value::as_array)
            .ok_or("no [[instance]]")?;
        for inst in instances {
            let name = inst
                .get("name")
                .and_then(toml::Value::as_str)
                .ok_or("an [[instance]] has no name")?;
            let fmu = inst.get("fmu").and_then(toml::Value::as_str).unwrap_or("");
            if !fmu.ends_with("body3d.fmu") {
                return Err(format!(
                    "instance {name:?}: the reference models body3d FMUs only, not {fmu:?}"
                ));
            }
            bodies.push(body_from_parameters(name, inst.get("parameters"))?);
        }
        let mut joints = Vec::new();
        let empty = Vec::new();
        let tables = match doc.get("joint") {
            None => &empty,
            Some(v) => v
                .as_array()
                .ok_or("joint must be an array of tables [[joint]]")?,
        };
        for table in tables {
            let table = table.as_table().ok_or("a [[joint]] is not a table")?;
            let name = table
                .get("name")
                .and_then(toml::Value::as_str)
                .ok_or("a [[joint]] has no name")?;
            if table.contains_key("plane") {
                return Err(format!(
                    "joint {name:?}: plane is not supported by the 3D reference"
                ));
            }
            let kind_name = table
                .get("kind")
                .and_then(toml::Value::as_str)
                .ok_or_else(|| format!("joint {name:?} has no kind"))?;
            let kind = JointKind::from_name(kind_name)
                .ok_or_else(|| format!("joint {name:?}: unknown kind {kind_name:?}"))?;
            joints.push(Joint {
                name: name.to_string(),
                kind,
                i: side(table, name, "i", &bodies)?,
                j: side(table, name, "j", &bodies)?,
            });
        }
        let experiment = doc.get("experiment");
        let field = |key: &str| -> Result<Option<f64>, String> {
            experiment
                .and_then(|e| e.get(key))
                .map(|v| number(v, &format!("experiment.{key}")))
                .transpose()
        };
        let system = System {
            bodies,
            joints,
            start: field("start")?.unwrap_or(0.0),
            stop: field("stop")?,
            baumgarte: (20.0, 20.0),
            tolerance: 1e-12,
        };
        system.check()?;
        Ok(system)
    }

    fn check(&self) -> Result<(), String> {
        for b in &self.bodies {
            let ok = b.m > 0.0 && b.inertia.iter().all(|&j| j > 0.0);
            if !ok {
                return Err(format!("instance {:?}: m and J must be > 0", b.name));
            }
        }
        for j in &self.joints {
            for s in [&j.i, &j.j] {
                frame(s).map_err(|e| format!("joint {:?}: {e}", j.name))?;
            }
            if j.i.body == j.j.body {
                return Err(format!("joint {:?} joins a body to itself", j.name));
            }
        }
        Ok(())
    }

    /// Integrates from `start` and returns the solution at every time in `times`
    /// (non-decreasing, ≥ start). Fails if the initial state violates a constraint
    /// by more than 1e-8 (position or velocity), or if the constraint rows become
    /// singular.
    pub fn simulate(&self, times: &[f64]) -> Result<Vec<Sample>, String> {
        let model = Model::new(self)?;
        let mut y = model.initial_state();
        let mut t = self.start;
        let first = model.sample(t, &y)?;
        if first.residual > 1e-8 || first.velocity_residual > 1e-8 {
            return Err(format!(
                "the initial state violates the joints: |g| = {:e}, |dg/dt| = {:e}",
                first.residual, first.velocity_residual
            ));
        }
        let mut out = Vec::with_capacity(times.len());
        for &target in times {
            if target < t {
                return Err(format!(
                    "times must be non-decreasing and >= {}",
                    self.start
                ));
            }
            if target > t {
                let failure = Rc::new(RefCell::new(None));
                let rhs = Rhs {
                    model: &model,
                    failure: Rc::clone(&failure),
                };
                let mut solver = Dop853::new(
                    rhs,
                    t,
                    target,
                    target - t,
                    y.clone(),
                    self.tolerance,
                    self.tolerance,
                );
                solver.set_output(OutputType::Sparse);
                let result = solver.integrate();
                if let Some(e) = failure.borrow_mut().take() {
                    return Err(format!("at t in [{t}, {target}]: {e}"));
                }
                result.map_err(|e| format!("Dop853 failed between t = {t} and {target}: {e}"))?;
                y = solver
                    .y_out()
                    .last()
                    .ok_or("Dop853 returned nothing")?
                    .clone();
                t = target;
            }
            out.push(model.sample(t, &y)?);
        }
        Ok(out)
    }
}

// ---------------------------------------------------------------------------
// The equations.

/// Joint-frame (x, y, z) in marker coordinates of one side.
fn frame(s: &JointSide) -> Result<(V3, V3, V3), String> {
    let z = s.axis.try_normalize(1e-12).ok_or("the axis is zero")?;
    let x = (s.reference - z * z.dot(&s.reference))
        .try_normalize(1e-12)
        .ok_or("ref is parallel to the axis")?;
    Ok((x, z.cross(&x), z))
}

/// A vector fixed in a body (body coordinates) or in the world (`body = None`).
#[derive(Clone, Copy, Debug)]
struct Dir {
    body: Option<usize>,
    e: V3,
}

/// A point fixed in a body (body coordinates from the CoM) or in the world.
#[derive(Clone, Copy, Debug)]
struct Point {
    body: Option<usize>,
    p: V3,
}

/// One scalar condition.
#[derive(Clone, Copy, Debug)]
enum Row {
    /// (C_i − C_j)·e.
    Distance { i: Point, j: Point, e: Dir },
    /// a·b.
    Perpendicular { a: Dir, b: Dir },
}

/// Per-body kinematics in a state.
struct Kin {
    r: Vec<V3>,
    rot: Vec<Matrix3<f64>>,
    v: Vec<V3>,
    w: Vec<V3>,
}

const STATE_PER_BODY: usize = 13; // r 3, q 4, v 3, ω (world) 3

impl Kin {
    fn new(y: &OdeVec, n: usize) -> Kin {
        let mut k = Kin {
            r: Vec::with_capacity(n),
            rot: Vec::with_capacity(n),
            v: Vec::with_capacity(n),
            w: Vec::with_capacity(n),
        };
        for b in 0..n {
            let s = &y.as_slice()[b * STATE_PER_BODY..(b + 1) * STATE_PER_BODY];
            k.r.push(V3::new(s[0], s[1], s[2]));
            let q = UnitQuaternion::from_quaternion(Quaternion::new(s[3], s[4], s[5], s[6]));
            k.rot.push(q.to_rotation_matrix().into_inner());
            k.v.push(V3::new(s[7], s[8], s[9]));
            k.w.push(V3::new(s[10], s[11], s[12]));
        }
        k
    }

    fn omega(&self, body: Option<usize>) -> V3 {
        body.map_or(V3::zeros(), |b| self.w[b])
    }

    /// World vector of a direction.
    fn dir(&self, d: Dir) -> V3 {
        d.body.map_or(d.e, |b| self.rot[b] * d.e)
    }

    /// (position, lever arm from the CoM, velocity) of a point.
    fn point(&self, p: Point) -> (V3, V3, V3) {
        match p.body {
            None => (p.p, V3::zeros(), V3::zeros()),
            Some(b) => {
                let u = self.rot[b] * p.p;
                (self.r[b] + u, u, self.v[b] + self.w[b].cross(&u))
            }
        }
    }
}

/// Value g, Jacobian row (over [v_b, ω_b] per body) and γ = g̈ − G ν̇ of one row.
fn evaluate(row: &Row, k: &Kin, jac: &mut [f64]) -> (f64, f64) {
    let mut add = |body: Option<usize>, lin: V3, ang: V3| {
        if let Some(b) = body {
            for c in 0..3 {
                jac[6 * b + c] += lin[c];
                jac[6 * b + 3 + c] += ang[c];
            }
        }
    };
    match *row {
        Row::Distance { i, j, e } => {
            let (ci, ui, vi) = k.point(i);
            let (cj, uj, vj) = k.point(j);
            let ev = k.dir(e);
            let (wi, wj, we) = (k.omega(i.body), k.omega(j.body), k.omega(e.body));
            let d = ci - cj;
            let d_dot = vi - vj;
            let e_dot = we.cross(&ev);
            add(i.body, ev, ui.cross(&ev));
            add(j.body, -ev, -uj.cross(&ev));
            add(e.body, V3::zeros(), ev.cross(&d));
            let centripetal = wi.cross(&wi.cross(&ui)) - wj.cross(&wj.cross(&uj));
            let gamma = centripetal.dot(&ev) + 2.0 * d_dot.dot(&e_dot) + d.dot(&we.cross(&e_dot));
            (d.dot(&ev), gamma)
        }
        Row::Perpendicular { a, b } => {
            let (av, bv) = (k.dir(a), k.dir(b));
            let (wa, wb) = (k.omega(a.body), k.omega(b.body));
            let axb = av.cross(&bv);
            add(a.body, V3::zeros(), axb);
            add(b.body, V3::zeros(), -axb);
            let (a_dot, b_dot) = (wa.cross(&av), wb.cross(&bv));
            let gamma =
                wa.cross(&a_dot).dot(&bv) + 2.0 * a_dot.dot(&b_dot) + av.dot(&wb.cross(&b_dot));
            (av.dot(&bv), gamma)
        }
    }
}

struct Model<'a> {
    system: &'a System,
    rows: Vec<Row>,
    /// Joint name → row range (ground rows come first and have no name).
    ranges: Vec<(String, std::ops::Range<usize>)>,
}

impl<'a> Model<'a> {
    fn new(system: &'a System) -> Result<Model<'a>, String> {
        let mut rows = Vec::new();
        let world = |e: V3| Dir { body: None, e };
        let axes = [V3::x(), V3::y(), V3::z()];
        for (b, body) in system.bodies.iter().enumerate() {
            let rot0 = UnitQuaternion::from_scaled_axis(body.phi0);
            let (pivot, axis) = match &body.ground {
                Ground::None => continue,
                Ground::Spherical { pivot } => (*pivot, None),
                Ground::Revolute { pivot, axis } => (*pivot, Some(*axis)),
            };
            let at = body.r0 + rot0 * pivot;
            for e in axes {
                rows.push(Row::Distance {
                    i: Point {
                        body: Some(b),
                        p: pivot,
                    },
                    j: Point { body: None, p: at },
                    e: world(e),
                });
            }
            if let Some(axis) = axis {
                let n = axis
                    .try_normalize(1e-12)
                    .ok_or_else(|| format!("instance {:?}: axis is zero", body.name))?;
                let nw = rot0 * n;
                let e1 = if nw.x.abs() < 0.9 { V3::x() } else { V3::y() };
                let e1 = (e1 - nw * nw.dot(&e1)).normalize();
                let e2 = nw.cross(&e1);
                for e in [e1, e2] {
                    rows.push(Row::Perpendicular {
                        a: Dir {
                            body: Some(b),
                            e: n,
                        },
                        b: world(e),
                    });
                }
            }
        }
        let mut ranges = Vec::new();
        for joint in &system.joints {
            let start = rows.len();
            let (xi, yi, zi) = frame(&joint.i)?;
            let (xj, yj, zj) = frame(&joint.j)?;
            let (bi, bj) = (Some(joint.i.body), Some(joint.j.body));
            let attach = |s: &JointSide| Point {
                body: Some(s.body),
                p: system.bodies[s.body].markers[&s.marker] + s.offset,
            };
            let (ci, cj) = (attach(&joint.i), attach(&joint.j));
            let on_i = |e: V3| Dir { body: bi, e };
            let on_j = |e: V3| Dir { body: bj, e };
            let dist = |e: Dir| Row::Distance { i: ci, j: cj, e };
            let perp = |a: V3, b: V3| Row::Perpendicular {
                a: on_i(a),
                b: on_j(b),
            };
            let atpoint = [
                dist(world(axes[0])),
                dist(world(axes[1])),
                dist(world(axes[2])),
            ];
            let mut add = |r: &[Row]| rows.extend_from_slice(r);
            match joint.kind {
                JointKind::AtPoint => add(&atpoint),
                JointKind::InPlane => add(&[dist(on_j(zj))]),
                JointKind::Perpendicular => add(&[perp(zi, zj)]),
                JointKind::Universal => {
                    add(&atpoint);
                    add(&[perp(xi, yj)]);
                }
                JointKind::Revolute => {
                    add(&atpoint);
                    add(&[perp(xi, zj), perp(yi, zj)]);
                }
                JointKind::Cylindrical => {
                    add(&[perp(xi, zj), perp(yi, zj), dist(on_j(xj)), dist(on_j(yj))])
                }
                JointKind::Translational => add(&[
                    perp(xi, zj),
                    perp(yi, zj),
                    perp(xi, yj),
                    dist(on_j(xj)),
                    dist(on_j(yj)),
                ]),
                JointKind::Planar => add(&[perp(xi, zj), perp(yi, zj), dist(on_j(zj))]),
                JointKind::Inline => add(&[dist(on_j(xj)), dist(on_j(yj))]),
                JointKind::Orientation => add(&[perp(xi, zj), perp(yi, zj), perp(xi, yj)]),
            }
            debug_assert_eq!(rows.len() - start, joint.kind.rows());
            ranges.push((joint.name.clone(), start..rows.len()));
        }
        Ok(Model {
            system,
            rows,
            ranges,
        })
    }

    fn initial_state(&self) -> OdeVec {
        let n = self.system.bodies.len();
        let mut y = OdeVec::zeros(n * STATE_PER_BODY);
        for (b, body) in self.system.bodies.iter().enumerate() {
            let q = UnitQuaternion::from_scaled_axis(body.phi0);
            let s = &mut y.as_mut_slice()[b * STATE_PER_BODY..(b + 1) * STATE_PER_BODY];
            s[0..3].copy_from_slice(body.r0.as_slice());
            s[3..7].copy_from_slice(&[q.w, q.i, q.j, q.k]);
            s[7..10].copy_from_slice(body.v0.as_slice());
            s[10..13].copy_from_slice(body.w0.as_slice());
        }
        y
    }

    /// Accelerations [v̇_b, ω̇_b] per body, multipliers, g and ġ.
    #[allow(clippy::type_complexity)]
    fn accelerations(
        &self,
        k: &Kin,
    ) -> Result<(DVector<f64>, DVector<f64>, DVector<f64>, DVector<f64>), String> {
        let n = self.system.bodies.len();
        let rows = self.rows.len();
        let mut jac = DMatrix::zeros(rows, 6 * n);
        let (mut g, mut gamma) = (DVector::zeros(rows), DVector::zeros(rows));
        let mut row = vec![0.0; 6 * n];
        for (r, c) in self.rows.iter().enumerate() {
            row.iter_mut().for_each(|x| *x = 0.0);
            let (value, gam) = evaluate(c, k, &mut row);
            g[r] = value;
            gamma[r] = gam;
            for (col, x) in row.iter().enumerate() {
                jac[(r, col)] = *x;
            }
        }
        // M⁻¹ and the applied forces (gravity, gyroscopic) per body.
        let mut minv = DMatrix::zeros(6 * n, 6 * n);
        let mut force = DVector::zeros(6 * n);
        let mut nu = DVector::zeros(6 * n);
        for (b, body) in self.system.bodies.iter().enumerate() {
            let rot = k.rot[b];
            let jw = rot * Matrix3::from_diagonal(&body.inertia) * rot.transpose();
            let jw_inv =
                rot * Matrix3::from_diagonal(&body.inertia.map(|j| 1.0 / j)) * rot.transpose();
            let w = k.w[b];
            let gyro = -w.cross(&(jw * w));
            for c in 0..3 {
                minv[(6 * b + c, 6 * b + c)] = 1.0 / body.m;
                force[6 * b + c] = body.m * body.gravity[c];
                force[6 * b + 3 + c] = gyro[c];
                nu[6 * b + c] = k.v[b][c];
                nu[6 * b + 3 + c] = w[c];
                for d in 0..3 {
                    minv[(6 * b + 3 + c, 6 * b + 3 + d)] = jw_inv[(c, d)];
                }
            }
        }
        let g_dot = &jac * &nu;
        let free = &minv * &force;
        let (a, b) = self.system.baumgarte;
        let lambda = if rows == 0 {
            DVector::zeros(0)
        } else {
            let schur = &jac * &minv * jac.transpose();
            let rhs = -(&gamma + &jac * &free + &g_dot * (2.0 * a) + &g * (b * b));
            schur
                .clone()
                .lu()
                .solve(&rhs)
                .filter(|l| l.iter().all(|x| x.is_finite()))
                .ok_or("the constraint rows are singular (redundant or degenerate joints)")?
        };
        let acc = &minv * (&force + jac.transpose() * &lambda);
        Ok((acc, lambda, g, g_dot))
    }

    fn rhs(&self, y: &OdeVec, dy: &mut OdeVec) -> Result<(), String> {
        let n = self.system.bodies.len();
        let k = Kin::new(y, n);
        let (acc, ..) = self.accelerations(&k)?;
        for b in 0..n {
            let s = &y.as_slice()[b * STATE_PER_BODY..(b + 1) * STATE_PER_BODY];
            let q = Quaternion::new(s[3], s[4], s[5], s[6]);
            let w = k.w[b];
            // q̇ = ½ (0, ω_world) ⊗ q, and a pull of |q| towards 1.
            let q_dot = Quaternion::new(0.0, w.x, w.y, w.z) * q * 0.5
                - q * (10.0 * (q.norm_squared() - 1.0));
            let d = &mut dy.as_mut_slice()[b * STATE_PER_BODY..(b + 1) * STATE_PER_BODY];
            d[0..3].copy_from_slice(k.v[b].as_slice());
            d[3..7].copy_from_slice(&[q_dot.w, q_dot.i, q_dot.j, q_dot.k]);
            for c in 0..3 {
                d[7 + c] = acc[6 * b + c];
                d[10 + c] = acc[6 * b + 3 + c];
            }
        }
        Ok(())
    }

    fn sample(&self, t: f64, y: &OdeVec) -> Result<Sample, String> {
        let n = self.system.bodies.len();
        let k = Kin::new(y, n);
        let (acc, lambda, g, g_dot) = self.accelerations(&k)?;
        let mut markers = BTreeMap::new();
        let mut energy = 0.0;
        for (b, body) in self.system.bodies.iter().enumerate() {
            let rot = k.rot[b];
            let (w, v) = (k.w[b], k.v[b]);
            let a_com = V3::new(acc[6 * b], acc[6 * b + 1], acc[6 * b + 2]);
            let alpha = V3::new(acc[6 * b + 3], acc[6 * b + 4], acc[6 * b + 5]);
            let jw = rot * Matrix3::from_diagonal(&body.inertia) * rot.transpose();
            energy += 0.5 * body.m * v.norm_squared() + 0.5 * w.dot(&(jw * w))
                - body.m * body.gravity.dot(&k.r[b]);
            for (name, offset) in &body.markers {
                let s = rot * offset;
                markers.insert(
                    format!("{}.{name}", body.name),
                    MarkerState {
                        r: k.r[b] + s,
                        rot,
                        v: v + w.cross(&s),
                        w,
                        a: a_com + alpha.cross(&s) + w.cross(&w.cross(&s)),
                        alpha,
                    },
                );
            }
        }
        let max_abs = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let mut joint_residuals = BTreeMap::new();
        let mut multipliers = BTreeMap::new();
        for (name, range) in &self.ranges {
            joint_residuals.insert(name.clone(), max_abs(&g.as_slice()[range.clone()]));
            multipliers.insert(name.clone(), lambda.as_slice()[range.clone()].to_vec());
        }
        Ok(Sample {
            t,
            markers,
            residual: max_abs(g.as_slice()),
            velocity_residual: max_abs(g_dot.as_slice()),
            joint_residuals,
            multipliers,
            energy,
        })
    }
}

/// The autonomous right-hand side for Dop853 (no explicit time: see the note on
/// ode_solvers 0.6.2 in docs/fmu-kit.md). A failure of the constraint solve is kept
/// and the derivative set to NaN, so the integrator stops.
struct Rhs<'m, 'a> {
    model: &'m Model<'a>,
    failure: Rc<RefCell<Option<String>>>,
}

impl ode_solvers::System<f64, OdeVec> for Rhs<'_, '_> {
    fn system(&self, _t: f64, y: &OdeVec, dy: &mut OdeVec) {
        if let Err(e) = self.model.rhs(y, dy) {
            dy.fill(f64::NAN);
            self.failure.borrow_mut().get_or_insert(e);
        }
    }
}
