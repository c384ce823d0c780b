//! The outputs an instance records at accepted points: the Real outputs,
//! then the Integer (and Enumeration) ones, then the Boolean ones, then the
//! String ones, each in the order of the model description, an array one
//! column per element.

use tether_fmi::{BaseType, Causality, Int, ModelDescription, ValueType};

use super::{Run, Slave};
use crate::observer::integer_value;
use crate::{Arrays, MasterError};

/// The recorded outputs and their buffers.
#[derive(Debug, Default)]
pub(super) struct Recorded {
    /// Column names (`inst.y`, `inst.y[1]`).
    pub names: Vec<String>,
    /// The Real outputs.
    pub vrs: Vec<u32>,
    /// The number of values `vrs` reads (arrays: one per element).
    pub reals: usize,
    /// Integer and Enumeration outputs, recorded after the Real ones.
    pub ints: Vec<u32>,
    pub int_buf: Vec<Int>,
    /// Boolean outputs, recorded after the Integer ones (as 0 and 1).
    pub bools: Vec<u32>,
    pub bool_buf: Vec<bool>,
    /// String outputs, recorded after the Boolean ones (0 in `values`, the
    /// text in `strings`).
    pub strs: Vec<u32>,
    /// The String outputs after the latest read, by index in `values`
    /// (empty, and never touched, without String outputs).
    pub strings: Vec<(usize, String)>,
    /// The buffer `strs` is read into.
    pub str_buf: Vec<String>,
    /// Whether there are Integer, Boolean or String outputs (read after the
    /// Real ones, out of line).
    pub others: bool,
    /// Recorded outputs after the latest read.
    pub values: Vec<f64>,
    /// The integers among them that a float rounds, exactly (by index).
    pub exact: Vec<(usize, Int)>,
}

impl Recorded {
    /// The recorded outputs of instance `instance` of `md` and their columns:
    /// the Real outputs, then the Integer (and Enumeration) ones, then the
    /// Boolean ones, then the String ones, each in the order of the model
    /// description, an array one column per element (`inst.y[1]`, sized as
    /// `arrays` makes it).
    pub(super) fn new(
        md: &ModelDescription,
        arrays: &Arrays,
        instance: &str,
    ) -> Result<Recorded, MasterError> {
        let mut recorded = Recorded::default();
        let (mut ints, mut bools, mut strs) = (0, 0, 0);
        let kinds = [
            BaseType::Real,
            BaseType::Integer,
            BaseType::Boolean,
            BaseType::String,
        ];
        for kind in kinds {
            for v in &md.model_variables {
                let base = match v.base_type() {
                    BaseType::Enumeration => BaseType::Integer,
                    other => other,
                };
                // FMI 3.0 Binary outputs are not recorded.
                let binary = base == BaseType::String && v.value_type != ValueType::String;
                if v.causality != Causality::Output || base != kind || binary {
                    continue;
                }
                let names = arrays.element_names(md, v)?;
                let n = names.len();
                recorded
                    .names
                    .extend(names.into_iter().map(|e| format!("{instance}.{e}")));
                match kind {
                    BaseType::Real => {
                        recorded.vrs.push(v.value_reference);
                        recorded.reals += n;
                    }
                    BaseType::Integer => {
                        recorded.ints.push(v.value_reference);
                        ints += n;
                    }
                    BaseType::Boolean => {
                        recorded.bools.push(v.value_reference);
                        bools += n;
                    }
                    _ => {
                        recorded.strs.push(v.value_reference);
                        strs += n;
                    }
                }
            }
        }
        recorded.int_buf = vec![0; ints];
        recorded.bool_buf = vec![false; bools];
        recorded.values = vec![0.0; recorded.names.len()];
        let first = recorded.names.len() - strs;
        recorded.strings = (first..recorded.names.len())
            .map(|k| (k, String::new()))
            .collect();
        recorded.str_buf = vec![String::new(); strs];
        recorded.others = ints + bools + strs > 0;
        Ok(recorded)
    }
}

impl Slave {
    /// The recorded outputs and their columns ([`Recorded::new`]).
    pub(super) fn record_columns(&mut self, instance: &str) -> Result<(), MasterError> {
        self.recorded = Recorded::new(self.fmu.model_description(), &self.arrays, instance)?;
        Ok(())
    }

    /// The recorded Real outputs `reals` as read, and the Integer and
    /// Boolean ones read now, into `recorded_values`. Every Real value must be
    /// finite, as in [`read_coupled`](Self::read_coupled).
    pub(super) fn take_recorded(&mut self, reals: &[f64], run: Run) -> Result<(), MasterError> {
        self.recorded.values[..reals.len()].copy_from_slice(reals);
        let reals = reals.len();
        if self.recorded.others {
            self.take_others(reals)?;
        }
        match self.recorded.values[..reals]
            .iter()
            .position(|v| !v.is_finite())
        {
            None => Ok(()),
            Some(i) => {
                let column = &self.recorded.names[i];
                // `<instance>.<variable>`: the instance's name is the prefix.
                let variable = column[column.find('.').map_or(0, |d| d + 1)..].to_string();
                Err(self.non_finite(variable, self.recorded.values[i], run))
            }
        }
    }

    /// The recorded Integer, Boolean and String outputs, read now, after
    /// the `reals` Real ones (out of line: systems with Real outputs only
    /// skip it before the call).
    #[inline(never)]
    fn take_others(&mut self, reals: usize) -> Result<(), MasterError> {
        if !self.recorded.ints.is_empty() {
            self.backend
                .get_integers(&self.recorded.ints, &mut self.recorded.int_buf)?;
            self.counters.get_integers += 1;
            self.recorded.exact.clear();
            for (k, &x) in self.recorded.int_buf.iter().enumerate() {
                let (v, exact) = integer_value(x);
                self.recorded.values[reals + k] = v;
                if !exact {
                    self.recorded.exact.push((reals + k, x));
                }
            }
        }
        if !self.recorded.bools.is_empty() {
            self.backend
                .get_booleans(&self.recorded.bools, &mut self.recorded.bool_buf)?;
            self.counters.get_booleans += 1;
            let first = reals + self.recorded.int_buf.len();
            for (slot, &v) in self.recorded.values[first..]
                .iter_mut()
                .zip(&self.recorded.bool_buf)
            {
                *slot = if v { 1.0 } else { 0.0 };
            }
        }
        if !self.recorded.strs.is_empty() {
            self.read_recorded_strings()?;
        }
        Ok(())
    }

    /// The recorded String outputs, read now.
    fn read_recorded_strings(&mut self) -> Result<(), MasterError> {
        let r = &mut self.recorded;
        self.backend.get_strings(&r.strs, &mut r.str_buf)?;
        self.counters.get_strings += 1;
        for ((_, slot), text) in r.strings.iter_mut().zip(&r.str_buf) {
            slot.clone_from(text);
        }
        Ok(())
    }

    /// The recorded String outputs after the latest read, by index in
    /// [`recorded_values`](Self::recorded_values).
    pub fn recorded_strings(&self) -> &[(usize, String)] {
        &self.recorded.strings
    }

    /// Back to recorded String outputs read earlier (a master state restored).
    pub(crate) fn set_recorded_strings(&mut self, strings: &[(usize, String)]) {
        self.recorded.strings.clone_from_slice(strings);
    }

    /// Back to recorded outputs read earlier (a master state restored).
    pub(crate) fn set_recorded_values(&mut self, values: &[f64]) {
        self.recorded.values.copy_from_slice(values);
    }

    /// Column names of the recorded outputs.
    pub fn recorded_names(&self) -> &[String] {
        &self.recorded.names
    }

    /// Recorded outputs after the latest read.
    pub fn recorded_values(&self) -> &[f64] {
        &self.recorded.values
    }

    /// The integers among the recorded outputs that a float rounds, exactly,
    /// by index in [`recorded_values`](Self::recorded_values).
    pub fn recorded_exact(&self) -> &[(usize, Int)] {
        &self.recorded.exact
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reals first, then Integers and Enumerations, then Booleans, then
    /// Strings, each in the description's order; inputs and parameters are
    /// not recorded.
    #[test]
    fn columns_are_reals_then_integers_then_booleans_then_strings() {
        let md = ModelDescription::from_xml(
            r#"<?xml version="1.0"?>
<fmiModelDescription fmiVersion="2.0" modelName="m" guid="{g}">
  <CoSimulation modelIdentifier="m"/>
  <TypeDefinitions>
    <SimpleType name="Mode"><Enumeration><Item name="a" value="1"/></Enumeration></SimpleType>
  </TypeDefinitions>
  <ModelVariables>
    <ScalarVariable name="on" valueReference="0" causality="output" variability="discrete"><Boolean/></ScalarVariable>
    <ScalarVariable name="n" valueReference="1" causality="output" variability="discrete"><Integer/></ScalarVariable>
    <ScalarVariable name="x" valueReference="2" causality="output"><Real/></ScalarVariable>
    <ScalarVariable name="u" valueReference="3" causality="input"><Real start="0"/></ScalarVariable>
    <ScalarVariable name="mode" valueReference="4" causality="output" variability="discrete"><Enumeration declaredType="Mode"/></ScalarVariable>
    <ScalarVariable name="y" valueReference="5" causality="output"><Real/></ScalarVariable>
    <ScalarVariable name="s" valueReference="6" causality="output" variability="discrete"><String/></ScalarVariable>
  </ModelVariables>
  <ModelStructure>
    <Outputs><Unknown index="1"/><Unknown index="2"/><Unknown index="3"/><Unknown index="5"/><Unknown index="6"/><Unknown index="7"/></Outputs>
  </ModelStructure>
</fmiModelDescription>"#,
        )
        .unwrap();
        let r = Recorded::new(&md, &Arrays::default(), "i").unwrap();
        assert_eq!(r.names, ["i.x", "i.y", "i.n", "i.mode", "i.on", "i.s"]);
        assert_eq!((r.vrs.as_slice(), r.reals), (&[2, 5][..], 2));
        assert_eq!((r.ints.as_slice(), r.int_buf.len()), (&[1, 4][..], 2));
        assert_eq!((r.bools.as_slice(), r.bool_buf.len()), (&[0][..], 1));
        assert_eq!((r.strs.as_slice(), r.str_buf.len()), (&[6][..], 1));
        assert_eq!(r.strings, [(5, String::new())]);
        assert_eq!(r.values.len(), 6);
    }
}
