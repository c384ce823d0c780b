//! Compiles the C shim that hands a model's own log messages to an FMI 3.0 importer.

fn main() {
    println!("cargo:rerun-if-changed=c/fmi3_logger.c");
    cc::Build::new()
        .file("c/fmi3_logger.c")
        .warnings(true)
        .compile("tether_fmu_kit_fmi3_logger");
}
