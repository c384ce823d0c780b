//! Compiles the C shim for the variadic FMI logger callback.

fn main() {
    println!("cargo:rerun-if-changed=c/logger.c");
    cc::Build::new()
        .file("c/logger.c")
        .warnings(true)
        .compile("tether_fmi_logger");
}
