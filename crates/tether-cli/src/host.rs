//! `tether host`: serves FMU instances to masters on other machines over TCP
//! (docs/remote.md).

use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Address and port to listen on: 127.0.0.1:PORT serves this machine
    /// only, 0.0.0.0:PORT every network (port 0: any free port, printed).
    #[arg(long, value_name = "ADDR:PORT")]
    listen: String,
    /// The file holding the token masters must prove they have (mode 600).
    #[arg(long, value_name = "FILE")]
    token_file: PathBuf,
    /// The largest FMU archive a master may send, in MiB.
    #[arg(long, value_name = "MIB", default_value_t = 1024)]
    max_fmu_mib: u64,
    /// The largest request a master may send once its FMU is ready, in MiB
    /// (a serialized FMU state is the largest there is).
    #[arg(long, value_name = "MIB", default_value_t = 256)]
    max_frame_mib: u64,
}

pub fn main(args: Args) -> anyhow::Result<()> {
    tether_fmi_host::listen::listen(&tether_fmi_host::listen::ListenOptions {
        address: args.listen,
        token_file: args.token_file,
        max_fmu_bytes: args.max_fmu_mib.saturating_mul(1 << 20),
        max_frame_bytes: args.max_frame_mib.saturating_mul(1 << 20),
    })
    .map_err(anyhow::Error::msg)
}
