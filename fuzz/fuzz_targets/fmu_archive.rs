//! Fuzzes FMU archive opening (zip parsing, entry validation, extraction limits,
//! modelDescription.xml, binary lookup): any bytes must be refused with a one-line
//! error or opened, never a panic, and nothing may be written outside the private
//! extraction directory, which is removed again.
#![no_main]

use std::path::PathBuf;
use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use tether_fmi::{ExtractLimits, Fmu, OpenOptions};

/// One scratch directory per process: the archive file and (via TMPDIR) the
/// extraction directories live in it.
fn scratch() -> &'static PathBuf {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("tether-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(dir.join("tmp")).expect("create the scratch directory");
        // Set before the first Fmu::open; libFuzzer calls the target from one thread.
        std::env::set_var("TMPDIR", dir.join("tmp"));
        dir
    })
}

fuzz_target!(|data: &[u8]| {
    let dir = scratch();
    let path = dir.join("input.fmu");
    std::fs::write(&path, data).expect("write the input archive");
    let options = OpenOptions {
        limits: ExtractLimits {
            max_total_bytes: 8 << 20,
            max_entries: 1000,
            ..ExtractLimits::default()
        },
    };
    match Fmu::open_with(&path, &options) {
        Ok(_) => {}
        Err(e) => {
            let message = e.to_string();
            assert!(!message.contains('\n'), "multi-line message: {message:?}");
        }
    }
    // Every extraction directory is gone once the Fmu (or the error) is dropped.
    let left = std::fs::read_dir(dir.join("tmp"))
        .expect("read the scratch tmp")
        .count();
    assert_eq!(left, 0, "an extraction directory was left behind");
    // Nothing escaped next to the input (a zip-slip entry would land here or above).
    let beside = std::fs::read_dir(dir)
        .expect("read the scratch directory")
        .count();
    assert_eq!(beside, 2, "something was written next to the archive");
});
