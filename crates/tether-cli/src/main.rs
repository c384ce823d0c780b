//! `tether`: couple FMI 2.0 co-simulation FMUs through algebraic constraints.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod compare;
mod exit_guard;
mod info;
mod interrupt;
mod output;
mod plot;
mod run;
mod settings;
mod simulate;
mod ssp;
mod study;
mod sweep;

/// Tether couples FMI 2.0 co-simulation FMUs through algebraic constraints
/// (rigid joints) with the predictor/corrector methods of Schweizer & Lu (2015).
#[derive(Parser)]
#[command(name = "tether", version, about, long_about = None)]
struct Cli {
    /// Log FMU messages and Tether's own (repeat for more: -v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Print an FMU's identity, capabilities and variables.
    Info(info::Args),
    /// Run one FMU at a fixed communication step and write its outputs to CSV.
    Simulate(simulate::Args),
    /// Run a coupled system (a system file, or SSP: .ssp, .ssd or a folder) and write CSV.
    Run(run::Args),
    /// Report the largest deviation per column between two result files.
    Compare(compare::Args),
    /// Plot results files over time as SVG or PNG.
    Plot(plot::Args),
    /// A convergence or stability sweep of a system file, set up by flags.
    Sweep(sweep::Args),
    /// Run study files: convergence, stability maps, time series; with plots.
    Study(study::Args),
    /// SSP: export a system file as .ssp, import an .ssp as a system file.
    Ssp(ssp::Args),
}

/// `eprintln!` that never panics: a closed or full stderr (`2>/dev/full`) is no
/// reason to fail a run, nor to panic.
#[macro_export]
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stderr(), $($arg)*);
    }};
}

/// Writes to stdout; a broken pipe (`tether info x.fmu | true`) is an error
/// (exit code 1), not a panic.
pub fn stdout(text: std::fmt::Arguments<'_>) -> anyhow::Result<()> {
    use std::io::Write as _;
    let mut out = std::io::stdout().lock();
    out.write_fmt(text)
        .and_then(|()| out.flush())
        .map_err(|e| anyhow::anyhow!("cannot write to stdout: {e}"))
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let level = match cli.verbose {
        0 => log::LevelFilter::Warn,
        1 => log::LevelFilter::Info,
        2 => log::LevelFilter::Debug,
        _ => log::LevelFilter::Trace,
    };
    let mut logger = env_logger::Builder::new();
    logger.filter_level(level);
    if matches!(&cli.command, Command::Run(args) if args.quiet) {
        // FMU messages are logged with the target `fmu::<instance>`.
        logger.filter_module("fmu", log::LevelFilter::Error);
    }
    logger.parse_env("TETHER_LOG").format_timestamp(None).init();
    let result = match cli.command {
        Command::Info(args) => info::main(args),
        Command::Simulate(args) => simulate::main(args),
        Command::Run(args) => run::main(args),
        Command::Compare(args) => compare::main(args),
        Command::Plot(args) => plot::main(args),
        Command::Sweep(args) => sweep::main(args),
        Command::Study(args) => study::main(args),
        Command::Ssp(args) => ssp::main(args),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            let message = format!("{e:#}").replace('\n', " ");
            say!("error: {message}");
            let interrupted = e.chain().any(|cause| {
                matches!(
                    cause.downcast_ref::<tether_master::MasterError>(),
                    Some(tether_master::MasterError::Interrupted { .. })
                )
            });
            if interrupted {
                ExitCode::from(interrupt::EXIT_CODE)
            } else {
                ExitCode::FAILURE
            }
        }
    }
}
