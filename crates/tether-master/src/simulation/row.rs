//! The recorded row: every column's value at the current point, the
//! columns the observers receive (`[output] variables`), and the last
//! accepted point held back when it is off the output grid.

use tether_fmi::Int;

use crate::observer::{Observer, Sample};
use crate::system::System;
use crate::MasterError;

/// The values of the current point and what is recorded of them.
pub(crate) struct Row {
    /// Every column, recorded or not.
    all_columns: Vec<String>,
    /// The values of every column at the current point.
    values: Vec<f64>,
    /// The integers among them that a float rounds, exactly (by index).
    exact: Vec<(usize, Int)>,
    /// The String values among them (String outputs), by index …
    strings: Vec<(usize, String)>,
    /// … if any instance records String outputs.
    texts: bool,
    /// The columns the observers receive …
    columns: Vec<String>,
    /// … their indices in `values`, when not all of them …
    keep: Option<Vec<usize>>,
    /// … and their values at the current point …
    selected: Vec<f64>,
    /// … and exact integers (by index in `selected`) …
    selected_exact: Vec<(usize, Int)>,
    /// … and String values (by index in `selected`).
    selected_strings: Vec<(usize, String)>,
    /// The last accepted point when it was not recorded (off the output
    /// grid): its step, time, values and exact integers, written at the end
    /// of the run.
    held: Option<Held>,
    /// Time of the last point handed to the observers.
    last_recorded: Option<f64>,
}

/// A point kept back from the observers.
struct Held {
    step: u64,
    time: f64,
    values: Vec<f64>,
    exact: Vec<(usize, Int)>,
    strings: Vec<(usize, String)>,
}

impl Row {
    /// A row of `columns`, of which the observers receive those at `keep`;
    /// `texts`: some of them are String outputs.
    pub(crate) fn new(columns: Vec<String>, keep: Vec<usize>, texts: bool) -> Row {
        let keep = (keep.len() < columns.len()).then_some(keep);
        let selected: Vec<String> = match &keep {
            Some(keep) => keep.iter().map(|&i| columns[i].clone()).collect(),
            None => columns.clone(),
        };
        Row {
            values: vec![0.0; columns.len()],
            exact: Vec::new(),
            strings: Vec::new(),
            texts,
            selected: vec![0.0; selected.len()],
            selected_exact: Vec::new(),
            selected_strings: Vec::new(),
            columns: selected,
            all_columns: columns,
            keep,
            held: None,
            last_recorded: None,
        }
    }

    /// Every column's name.
    pub(crate) fn all_columns(&self) -> &[String] {
        &self.all_columns
    }

    /// Every column's value at the current point.
    pub(crate) fn all_values(&self) -> &[f64] {
        &self.values
    }

    /// The recorded columns.
    pub(crate) fn columns(&self) -> &[String] {
        &self.columns
    }

    /// The recorded values of the current point.
    pub(crate) fn values(&self) -> &[f64] {
        match self.keep {
            Some(_) => &self.selected,
            None => &self.values,
        }
    }

    /// The exact integers among the recorded values (by index).
    fn exact(&self) -> &[(usize, Int)] {
        match self.keep {
            Some(_) => &self.selected_exact,
            None => &self.exact,
        }
    }

    /// The String values among the recorded values (by index).
    pub(crate) fn strings(&self) -> &[(usize, String)] {
        match self.keep {
            Some(_) => &self.selected_strings,
            None => &self.strings,
        }
    }

    /// The time of the last point handed to the observers.
    pub(crate) fn last_recorded(&self) -> Option<f64> {
        self.last_recorded
    }

    /// The current point's values: every instance's recorded outputs, the
    /// unknowns, the residuals (the values from `first_residual` on).
    pub(crate) fn fill(&mut self, system: &System) {
        let mut i = 0;
        self.exact.clear();
        for slave in &system.slaves {
            let values = slave.recorded_values();
            self.values[i..i + values.len()].copy_from_slice(values);
            let exact = slave.recorded_exact().iter().map(|&(k, x)| (i + k, x));
            self.exact.extend(exact);
            i += values.len();
        }
        if self.texts {
            self.fill_strings(system);
        }
        for h in &system.history {
            self.values[i] = h[0];
            i += 1;
        }
        for residual in system.coupling.residuals(&system.outputs) {
            self.values[i] = residual;
            i += 1;
        }
        if let Some(keep) = &self.keep {
            for (value, &k) in self.selected.iter_mut().zip(keep) {
                *value = self.values[k];
            }
            self.selected_exact.clear();
            if !self.exact.is_empty() {
                for (j, &k) in keep.iter().enumerate() {
                    if let Some(&(_, x)) = self.exact.iter().find(|(i, _)| *i == k) {
                        self.selected_exact.push((j, x));
                    }
                }
            }
            if !self.strings.is_empty() {
                self.selected_strings.clear();
                for (j, &k) in keep.iter().enumerate() {
                    if let Some((_, text)) = self.strings.iter().find(|(i, _)| *i == k) {
                        self.selected_strings.push((j, text.clone()));
                    }
                }
            }
        }
    }

    /// The String outputs' texts of the current point (out of line:
    /// systems without them skip it before the call).
    #[inline(never)]
    fn fill_strings(&mut self, system: &System) {
        let (mut i, mut texts) = (0, 0);
        for slave in &system.slaves {
            for (k, text) in slave.recorded_strings() {
                // The slots are reused: no allocation once the texts fit.
                match self.strings.get_mut(texts) {
                    Some(slot) => {
                        slot.0 = i + k;
                        slot.1.clone_from(text);
                    }
                    None => self.strings.push((i + k, text.clone())),
                }
                texts += 1;
            }
            i += slave.recorded_values().len();
        }
        self.strings.truncate(texts);
    }

    /// Hand the current point (`step`, `time`) to the observers.
    pub(crate) fn notify(
        &mut self,
        observers: &mut [&mut dyn Observer],
        step: u64,
        time: f64,
    ) -> Result<(), MasterError> {
        let sample = Sample {
            step,
            time,
            values: self.values(),
            exact: self.exact(),
            strings: self.strings(),
        };
        for o in observers.iter_mut() {
            o.sample(sample)?;
        }
        self.last_recorded = Some(time);
        self.held = None;
        Ok(())
    }

    /// Keep the current point, not on the output grid, for the end.
    pub(crate) fn hold(&mut self, step: u64, time: f64) {
        let mut held = self.held.take().unwrap_or_else(|| Held {
            step,
            time,
            values: Vec::with_capacity(self.columns.len()),
            exact: Vec::new(),
            strings: Vec::new(),
        });
        held.step = step;
        held.time = time;
        held.values.clear();
        held.values.extend_from_slice(self.values());
        held.exact.clear();
        held.exact.extend_from_slice(self.exact());
        if self.texts {
            held.strings.clear();
            held.strings.extend_from_slice(self.strings());
        }
        self.held = Some(held);
    }

    /// Record the held point, if it is the last accepted one not yet recorded.
    pub(crate) fn release_held(
        &mut self,
        observers: &mut [&mut dyn Observer],
    ) -> Result<(), MasterError> {
        let Some(held) = self.held.take() else {
            return Ok(());
        };
        let sample = Sample {
            step: held.step,
            time: held.time,
            values: &held.values,
            exact: &held.exact,
            strings: &held.strings,
        };
        for o in observers.iter_mut() {
            o.sample(sample)?;
        }
        self.last_recorded = Some(held.time);
        Ok(())
    }
}
