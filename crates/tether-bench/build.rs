//! Builds the C floor (the FMI calls of one macro step and nothing else) and
//! the host-state probe.

fn main() {
    println!("cargo:rerun-if-changed=c/floor.c");
    println!("cargo:rerun-if-changed=c/probe.c");
    println!("cargo:rerun-if-changed=c/transport.c");
    cc::Build::new()
        .file("c/floor.c")
        .file("c/probe.c")
        .file("c/transport.c")
        .opt_level(2)
        .warnings(true)
        .compile("tether_floor");
    // dlopen/dlsym live in libdl on older glibc and in libc on newer ones.
    println!("cargo:rustc-link-lib=dl");
}
