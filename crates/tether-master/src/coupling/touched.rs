//! Which rows a perturbation touches: the sparsity of the interface Jacobian,
//! known at setup from which instances each unknown drives and which
//! instances (and unknowns) each row reads.
//!
//! Column m of ∂g/∂u can be non-zero only in the rows that read an instance
//! m drives, read m itself, or sum a force law that changes with m (a
//! force-port row). A finite-difference column evaluates only those rows:
//! O(rows touched) instead of O(all rows), so a step's Jacobian costs
//! O(non-zeros), not O(N²). Every other row would evaluate to exactly its
//! unperturbed value, so its entry is an exact zero either way.

use crate::coupling::rows::{RowLevel, View};
use crate::coupling::{Coupling, Row};

/// The most entries the interface Jacobian's pattern may have (docs/system-file.md,
/// "Limits"): each costs about 100 bytes at setup (its row index, its values of
/// every level, the dense matrix of a system with few zeros), so the limit bounds
/// the interface system's memory near 1 GB. The largest systems of the tests and
/// benchmarks have a few thousand.
pub const MAX_INTERFACE_ENTRIES: usize = 10_000_000;

/// The rows (and joints) each unknown's perturbation touches, compressed by
/// column; the rows of a column are sorted.
#[derive(Debug, Clone, Default)]
pub(crate) struct Touched {
    /// Column m's rows are `rows[row_ptr[m]..row_ptr[m + 1]]`.
    pub row_ptr: Vec<usize>,
    pub rows: Vec<usize>,
    /// Column m's joints (to evaluate once each), in joint order.
    joint_ptr: Vec<usize>,
    joints: Vec<usize>,
}

impl Touched {
    /// The structure from the coupling rows and `owners` (per unknown, the
    /// instances it drives), in time linear in the number of non-zeros; `None`,
    /// before it is stored, if it has more than [`MAX_INTERFACE_ENTRIES`].
    pub fn new(coupling: &Coupling, owners: &[Vec<usize>], instances: usize) -> Option<Touched> {
        let n = coupling.len();
        // Per instance: the constraint and variable rows, and the joints, reading it.
        let mut instance_rows = vec![Vec::new(); instances];
        let mut instance_joints = vec![Vec::new(); instances];
        // Per unknown: the rows reading it directly (variables, ports, and the
        // force-port rows its multiplier loads); per port row, its joints.
        let mut unknown_rows = vec![Vec::new(); n];
        let mut port_joints = vec![Vec::new(); n];
        let push = |list: &mut Vec<usize>, x: usize| {
            if list.last() != Some(&x) {
                list.push(x);
            }
        };
        for (r, unknown) in coupling.unknowns.iter().enumerate() {
            match unknown.row {
                Row::Constraint(c) => {
                    let con = &coupling.constraints[c];
                    let levels = [
                        Some(&con.position),
                        con.velocity.as_ref(),
                        con.acceleration.as_ref(),
                    ];
                    for level in levels.into_iter().flatten() {
                        for &(s, _, _) in &level.terms {
                            push(&mut instance_rows[s], r);
                        }
                    }
                }
                Row::Variable(v) => {
                    let var = &coupling.variables[v];
                    unknown_rows[var.unknown].push(r);
                    for &(s, _, _) in &var.value.terms {
                        push(&mut instance_rows[s], r);
                    }
                }
                Row::Port(p) => unknown_rows[coupling.ports[p].unknown].push(r),
                Row::Joint { .. } => {}
            }
        }
        for (j, joint) in coupling.joints.iter().enumerate() {
            for side in &joint.sides {
                push(&mut instance_joints[side.slave], j);
            }
            for &(c, _, row) in &joint.targets {
                unknown_rows[joint.first_unknown + c].push(row);
                push(&mut port_joints[row], j);
            }
        }
        let is_port = |r: usize| matches!(coupling.unknowns[r].row, Row::Port(_));
        let mut touched = Touched {
            row_ptr: vec![0],
            joint_ptr: vec![0],
            ..Touched::default()
        };
        // `mark[x] == m + 1`: x is already in column m's list.
        let mut row_mark = vec![0; n];
        let mut joint_mark = vec![0; coupling.joints.len()];
        let (mut rows, mut joints) = (Vec::new(), Vec::new());
        for (m, own) in owners.iter().enumerate() {
            let stamp = m + 1;
            rows.clear();
            joints.clear();
            let mut add_row = |rows: &mut Vec<usize>, r: usize| {
                if row_mark[r] != stamp {
                    row_mark[r] = stamp;
                    rows.push(r);
                }
            };
            let mut add_joint = |joints: &mut Vec<usize>, j: usize| {
                if joint_mark[j] != stamp {
                    joint_mark[j] = stamp;
                    joints.push(j);
                }
            };
            for &s in own {
                instance_rows[s].iter().for_each(|&r| add_row(&mut rows, r));
                instance_joints[s]
                    .iter()
                    .for_each(|&j| add_joint(&mut joints, j));
            }
            unknown_rows[m].iter().for_each(|&r| add_row(&mut rows, r));
            // The force laws of the joints reading a perturbed instance change
            // the port rows they load.
            for &j in &joints {
                for &(_, _, row) in &coupling.joints[j].targets {
                    add_row(&mut rows, row);
                }
            }
            // A port row sums every joint loading it: all of them are evaluated.
            for i in 0..rows.len() {
                if is_port(rows[i]) {
                    port_joints[rows[i]]
                        .iter()
                        .for_each(|&j| add_joint(&mut joints, j));
                }
            }
            for &j in &joints {
                let joint = &coupling.joints[j];
                for c in 0..joint.conditions.len() {
                    add_row(&mut rows, joint.first_unknown + c);
                }
            }
            if touched.rows.len() + rows.len() > MAX_INTERFACE_ENTRIES {
                return None;
            }
            rows.sort_unstable();
            joints.sort_unstable();
            touched.rows.extend_from_slice(&rows);
            touched.row_ptr.push(touched.rows.len());
            touched.joints.extend_from_slice(&joints);
            touched.joint_ptr.push(touched.joints.len());
        }
        Some(touched)
    }

    /// The rows column `m` may change, sorted.
    #[inline]
    pub fn column(&self, m: usize) -> &[usize] {
        &self.rows[self.row_ptr[m]..self.row_ptr[m + 1]]
    }

    /// Number of structural non-zeros of the Jacobian.
    pub fn nnz(&self) -> usize {
        self.rows.len()
    }

    /// Evaluate the rows of column `m` at `level` into `out` (indexed by
    /// row; other entries are left unspecified), with the same arithmetic
    /// as [`Coupling::eval`]: each port row sums its joints in joint order.
    pub fn eval(
        &self,
        coupling: &Coupling,
        m: usize,
        level: RowLevel,
        view: &View,
        out: &mut [f64],
    ) {
        let rows = self.column(m);
        for &r in rows {
            if let Some(value) = coupling.eval_row(r, level, view) {
                out[r] = value;
            }
        }
        for &j in &self.joints[self.joint_ptr[m]..self.joint_ptr[m + 1]] {
            coupling.eval_joint(&coupling.joints[j], level, view, out);
        }
        for &r in rows {
            if matches!(coupling.unknowns[r].row, Row::Port(_)) {
                out[r] = view.unknown(r) - out[r];
            }
        }
    }
}
