//! `tether`: couple FMI 2.0 co-simulation FMUs through algebraic constraints.

use clap::{Parser, Subcommand};

mod columns;
mod compare;
mod exit_guard;
mod fmu;
mod host;
mod info;
mod interrupt;
mod isolation;
mod new;
mod output;
mod plot;
mod progress;
mod run;
mod settings;
mod simulate;
mod ssp;
mod study;
mod sweep;
mod watchdog;

/// Tether couples FMI 2.0 co-simulation FMUs through algebraic constraints
/// (rigid joints) with the predictor/corrector methods of Schweizer & Lu (2015).
#[derive(Parser)]
#[command(name = "tether", version, about, long_about = None)]
struct Cli {
    /// Log FMU messages and Tether's own (repeat for more: -v info, -vv debug).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Switch the FMUs' debug logging on (loggingOn, fmi2SetDebugLogging) and
    /// show their messages, prefixed with the instance: every category, or
    /// those given (--fmu-log=logEvents,logStatusError). -v does the same
    /// for every category.
    #[arg(
        long,
        global = true,
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = "",
        value_name = "CATEGORIES"
    )]
    fmu_log: Option<String>,
    /// Messages shown per FMU instance and category in one second (the rest
    /// are counted and reported as suppressed), or `off` for every message.
    #[arg(long, global = true, value_name = "N|off", default_value = "20", value_parser = log_limit)]
    fmu_log_limit: LogLimit,
    #[command(subcommand)]
    command: Command,
}

/// `--fmu-log-limit`: messages per instance, category and second; `None` for all.
#[derive(Clone, Copy)]
struct LogLimit(Option<u32>);

fn log_limit(text: &str) -> Result<LogLimit, String> {
    tether_fmi::parse_rate_limit(text).map(LogLimit)
}

#[derive(Subcommand)]
enum Command {
    /// Print an FMU's identity, capabilities and variables.
    Info(info::Args),
    /// Run one FMU at a fixed communication step and write its outputs to CSV.
    Simulate(simulate::Args),
    /// Write a starter system file for FMUs: instances, parameters, interface.
    New(new::Args),
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
    /// FMU: export a system file as one FMI 2.0 co-simulation FMU.
    Fmu(fmu::Args),
    /// Serve FMU instances to masters on other machines over TCP.
    Host(host::Args),
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

/// A results or input file that is not there, said with the resolved path,
/// the folder it was resolved against and a name that differs only in case;
/// `None` when it is there (the reader reports other failures).
pub fn missing(path: &std::path::Path) -> Option<anyhow::Error> {
    match std::fs::metadata(path) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            let place = tether_fmi::paths::Missing::new(path, None);
            Some(anyhow::anyhow!(
                "cannot access {}: {e}{}",
                place.located(),
                place.hint()
            ))
        }
        _ => None,
    }
}

/// The hidden first argument that makes `tether` the host process of an
/// isolated FMU instance (docs/reliability.md).
const FMI_HOST: &str = "__fmi-host";
/// The error and its causes on one line, `context: error: cause`; a cause
/// whose text the line already holds (errors that print their source
/// themselves) is not repeated.
fn one_line(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line.replace('\n', " ")
}

/// Runs the command, then ends the process with its exit code
/// ([`tether_fmi::exit_hook::leave`]: once the command has returned, every
/// instance is freed, every file closed and every extraction folder removed;
/// what the FMU libraries still loaded would do at process exit is skipped).
fn main() {
    let code = command();
    tether_fmi::exit_hook::leave(code)
}

/// The command line's command; its exit code.
fn command() -> u8 {
    // A file size limit (`ulimit -f`) reached is a write error (EFBIG) like a
    // full disk, handled by the writer (whole rows, trailer, cleanup), not a
    // signal that kills the process mid-row.
    // SAFETY: sets the disposition of SIGXFSZ to "ignore", before any thread.
    unsafe { libc::signal(libc::SIGXFSZ, libc::SIG_IGN) };
    // `tether __fmi-host`, or `tether` under the host program's name (as an
    // exported FMU may carry it, docs/fmu-export.md): a host process.
    let called = std::env::args_os().next().map(std::path::PathBuf::from);
    let as_host = called
        .as_deref()
        .and_then(std::path::Path::file_name)
        .is_some_and(|n| n == tether_fmi::remote::HOST_NAME);
    if as_host || std::env::args_os().nth(1).is_some_and(|a| a == FMI_HOST) {
        tether_fmi_host::serve_stdin();
    }
    // Isolated instances run in `tether __fmi-host`: one file to install.
    if let Ok(exe) = std::env::current_exe() {
        tether_fmi::remote::set_host(tether_fmi::remote::HostCommand {
            program: exe,
            args: vec![FMI_HOST.into()],
        });
    }
    let cli = Cli::parse();
    let level = match cli.verbose {
        0 => log::LevelFilter::Warn,
        1 => log::LevelFilter::Info,
        2 => log::LevelFilter::Debug,
        _ => log::LevelFilter::Trace,
    };
    let mut logger = env_logger::Builder::new();
    logger.filter_level(level);
    if cli.fmu_log.is_some() {
        // FMU messages are logged with the target `fmu::<instance>`; those
        // of status fmi2OK at the level info.
        logger.filter_module("fmu", log::LevelFilter::Trace);
    } else if matches!(&cli.command, Command::Run(args) if args.quiet) {
        logger.filter_module("fmu", log::LevelFilter::Error);
    }
    if cli.fmu_log.is_some() || cli.verbose > 0 {
        let categories = cli.fmu_log.as_deref().unwrap_or("");
        tether_fmi::set_debug_logging(Some(
            categories
                .split(',')
                .map(str::trim)
                .filter(|c| !c.is_empty())
                .map(str::to_string)
                .collect(),
        ));
    }
    tether_fmi::set_rate_limit(cli.fmu_log_limit.0);
    logger
        .parse_env("TETHER_LOG")
        .format(tether_fmi_host::log_line)
        .init();
    let result = match cli.command {
        Command::Info(args) => info::main(args),
        Command::Simulate(args) => simulate::main(args),
        Command::New(args) => new::main(args),
        Command::Run(args) => run::main(args),
        Command::Compare(args) => compare::main(args),
        Command::Plot(args) => plot::main(args),
        Command::Sweep(args) => sweep::main(args),
        Command::Study(args) => study::main(args),
        Command::Ssp(args) => ssp::main(args),
        Command::Fmu(args) => fmu::main(args),
        Command::Host(args) => host::main(args),
    };
    match result {
        Ok(()) => 0,
        Err(e) => {
            let message = one_line(&e);
            say!("error: {message}");
            let interrupted = e.chain().any(|cause| {
                matches!(
                    cause.downcast_ref::<tether_master::MasterError>(),
                    Some(tether_master::MasterError::Interrupted { .. })
                )
            });
            if interrupted {
                interrupt::EXIT_CODE
            } else {
                1
            }
        }
    }
}
