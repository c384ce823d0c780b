//! Fuzzes the modelDescription.xml parser: any bytes must give a model description or
//! an error whose message is one line, never a panic, a hang or unbounded memory.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tether_fmi::ModelDescription;

fuzz_target!(|data: &[u8]| {
    match ModelDescription::from_bytes(data) {
        Ok(md) => {
            // Every variable can be found by its own name and by its FMI index.
            for (i, v) in md.model_variables.iter().enumerate() {
                let found = md
                    .variable(&v.name)
                    .expect("a parsed variable is found by name");
                assert_eq!(found.value_reference, v.value_reference);
                assert!(md.variable_by_index(i + 1).is_some());
            }
        }
        Err(e) => {
            let message = e.to_string();
            assert!(!message.contains('\n'), "multi-line message: {message:?}");
        }
    }
});
