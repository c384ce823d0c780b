//! The runs of a macro step handed to an instance as one batch
//! ([`FmuInstance::run_batch`](tether_fmi::FmuInstance::run_batch)): one
//! request, one reply, two round trips a step for an isolated instance.

use tether_fmi::RunRequest;

use super::coupled::combine_inputs;
use super::coupled::InputBuffers;
use super::{Run, Slave, SAVED};
use crate::polynomial::Taylor;
use crate::MasterError;

/// A batch's buffers, kept between steps (emptied; see [`recycle`]).
#[derive(Default)]
pub(super) struct Runs {
    /// The coupled inputs for each run of a batch.
    pub inputs: Vec<InputBuffers>,
    /// The outputs of a batch of runs, run after run.
    pub batch_buf: Vec<f64>,
    /// The allocations of a batch's plan and requests.
    pub planned_buf: Vec<Planned<'static>>,
    pub request_buf: Vec<RunRequest<'static>>,
    /// A batch sent ([`Batch::Send`]) awaits its reply.
    pub awaiting: bool,
}

/// One run of an instance as a macro step plans it ([`Slave::runs`]).
pub(super) struct Planned<'a> {
    /// The inputs' polynomials and the step `(t, h)`; `None`: no step, a read.
    pub step: Option<(&'a [Taylor], f64, f64)>,
    /// From the saved state.
    pub restore: bool,
    /// Where the coupled outputs go, if read.
    pub out: Option<&'a mut [f64]>,
    /// Read the recorded outputs too (an accepted point).
    pub record: bool,
    /// What the outputs are read after, for messages.
    pub run: Run,
}

/// How a batch goes to the instance.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Batch {
    /// Made whole: requested and its reply read.
    Whole,
    /// An instance in a host process: the request sent, its reply awaited
    /// later (after the requests to the other hosts went out).
    Send,
    /// The reply to the request of [`Batch::Send`] with the same runs.
    Receive,
}

/// An empty vector with `v`'s allocation, for items of another lifetime, so
/// that a step's plan and requests allocate nothing after the first step
/// (collecting the emptied vector's own iterator reuses its allocation).
pub(super) fn recycle<T, U>(mut v: Vec<T>) -> Vec<U> {
    v.clear();
    v.into_iter()
        .map(|_| -> U { unreachable!("the vector was emptied") })
        .collect()
}

impl Slave {
    /// Runs handed to the instance as one unit ([`FmuInstance::run_batch`]),
    /// in order: each from the saved state when `restore`, with the inputs
    /// from its polynomials over its step, its coupled outputs read into its
    /// `out` (checked as read after its `run`) and, with `record`, the
    /// recorded outputs. `how` splits the batch of an instance in a host
    /// process into its request and its reply; returns whether a reply is
    /// awaited after [`Batch::Send`].
    pub(super) fn runs(
        &mut self,
        planned: &mut [Planned<'_>],
        how: Batch,
    ) -> Result<bool, MasterError> {
        if how != Batch::Receive {
            self.prepare(planned);
        }
        let driven = !self.coupled.inputs.is_empty();
        let mut requests = recycle(std::mem::take(&mut self.runs.request_buf));
        // At an accepted point one call reads the coupled and the recorded
        // outputs, unless output derivatives are read between them.
        let joined = self.coupled.derivative_reads.is_empty();
        requests.extend(planned.iter().zip(&self.runs.inputs).map(|(p, input)| {
            let out = p.out.is_some();
            let (outputs, output_values, recorded, recorded_values) = match p.record {
                true if out && joined => (
                    &self.coupled.accepted_vrs[..],
                    self.coupled.accepted_count,
                    &[][..],
                    None,
                ),
                record => (
                    if out {
                        &self.coupled.value_vrs[..]
                    } else {
                        &[]
                    },
                    if out { self.coupled.value_count } else { None },
                    if record { &self.recorded.vrs[..] } else { &[] },
                    record.then_some(self.recorded.reals),
                ),
            };
            RunRequest {
                restore: p.restore.then_some(SAVED),
                inputs: (driven && p.step.is_some()).then(|| input.as_inputs()),
                step: p.step.map(|(_, t, h)| (t, h)),
                outputs,
                output_values,
                output_derivatives: if out {
                    &self.coupled.derivative_reads
                } else {
                    &[]
                },
                recorded,
                recorded_values,
                save: None,
            }
        }));
        let reads: u64 = requests
            .iter()
            .map(|r| u64::from(!r.outputs.is_empty()) + u64::from(!r.recorded.is_empty()))
            .sum();
        let ran = match how {
            Batch::Whole => self.backend.run_batch(&requests, &mut self.runs.batch_buf),
            Batch::Send => self.backend.send_batch(&requests).map(|sent| {
                self.runs.awaiting = sent;
            }),
            Batch::Receive => {
                self.runs.awaiting = false;
                self.backend
                    .receive_batch(&requests, &mut self.runs.batch_buf)
            }
        };
        self.runs.request_buf = recycle(requests);
        ran?;
        if how == Batch::Send {
            return Ok(self.runs.awaiting);
        }
        self.counters.get_reals += reads;
        let batch = std::mem::take(&mut self.runs.batch_buf);
        let mut values = batch.as_slice();
        let taken = planned.iter_mut().try_for_each(|p| {
            if let Some(out) = p.out.as_deref_mut() {
                let (coupled, rest) = values.split_at(self.coupled.slots.len());
                values = rest;
                self.take_coupled(coupled, out, p.run)?;
            }
            if p.record {
                let (recorded, rest) = values.split_at(self.recorded.reals);
                values = rest;
                self.take_recorded(recorded, p.run)?;
            }
            Ok(())
        });
        self.runs.batch_buf = batch;
        taken.map(|()| false)
    }

    /// A batch's inputs from its runs' polynomials, the length of its
    /// outputs, and its calls counted (whether or not the runs succeed).
    fn prepare(&mut self, planned: &[Planned<'_>]) {
        let driven = !self.coupled.inputs.is_empty();
        if self.runs.inputs.len() < planned.len() {
            self.runs
                .inputs
                .resize(planned.len(), self.coupled.input.clone());
        }
        let mut len = 0;
        for (p, input) in planned.iter().zip(&mut self.runs.inputs) {
            if p.restore {
                self.counters.state_sets += 1;
            }
            if let Some((polys, _, _)) = p.step {
                self.counters.do_steps += 1;
                if driven {
                    combine_inputs(
                        &self.coupled.inputs,
                        &self.coupled.input_positions,
                        polys,
                        &mut input.values,
                        &mut input.derivatives,
                    );
                    self.counters.set_reals += 1;
                    if !self.coupled.input.derivative_vrs.is_empty() {
                        self.counters.set_input_derivatives += 1;
                    }
                }
            }
            if p.out.is_some() {
                len += self.coupled.slots.len();
            }
            if p.record {
                len += self.recorded.reals;
            }
        }
        self.runs.batch_buf.resize(len, 0.0);
    }
}

#[cfg(test)]
mod tests {
    use super::recycle;

    #[test]
    fn a_recycled_vector_keeps_its_allocation() {
        // Items borrowed for a step, recycled for items of another lifetime.
        let step = String::from("a step's data");
        let mut v: Vec<&str> = Vec::with_capacity(8);
        v.extend([step.as_str(), step.as_str()]);
        let ptr = v.as_ptr() as usize;
        let w: Vec<&'static str> = recycle(v);
        assert!(w.is_empty() && w.capacity() >= 8);
        assert_eq!(w.as_ptr() as usize, ptr);
    }
}
