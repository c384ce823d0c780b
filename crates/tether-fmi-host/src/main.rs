//! `tether-fmi-host`: runs one FMU instance for a master in another process,
//! which started it with pipes as standard input and output
//! (docs/reliability.md).

fn main() {
    tether_fmi_host::serve_stdin()
}
