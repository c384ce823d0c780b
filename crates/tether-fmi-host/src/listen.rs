//! `tether host --listen`: serves FMU instances to masters on other machines
//! over TCP ([`tether_fmi::remote::tcp`]). Each connection is authenticated
//! here, gets its FMU unpacked here, and is then served by a host process of
//! its own (the same one as for isolated instances, with the connection as
//! its standard input and output): an FMU that crashes ends that process
//! only. The process and the unpacked FMU go when the connection ends, also
//! when the master vanished; the processes end with the listener.

use std::io::{BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::os::fd::OwnedFd;
use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use tether_fmi::remote::protocol::{self, In, Out};
use tether_fmi::remote::tcp::{self, FMU_CHUNK, FMU_END, FMU_PATH, MAX_CHUNK, MAX_OPENING_FRAME};
use tether_fmi::{Fmu, OpenOptions};

/// [`crate::GAVE_UP`] as `ExitStatus::code` gives it.
const GAVE_UP_CODE: i32 = crate::GAVE_UP as i32;

/// The most connections in their opening (not yet authenticated and given
/// their FMU) at once; more are closed at once.
const MAX_OPENING: usize = 64;

/// What `tether host` is told.
#[derive(Debug, Clone)]
pub struct ListenOptions {
    /// `ADDR:PORT` to listen on.
    pub address: String,
    /// The file holding the shared token.
    pub token_file: PathBuf,
    /// The largest FMU archive a master may send, in bytes.
    pub max_fmu_bytes: u64,
    /// The largest request frame a master may send once its FMU is ready
    /// (a serialized FMU state is the largest the protocol has), in bytes.
    pub max_frame_bytes: u64,
}

/// Listens and serves until killed; `Err` with one line if it cannot start.
pub fn listen(options: &ListenOptions) -> Result<(), String> {
    let token = tcp::read_token(&options.token_file)?;
    let listener = TcpListener::bind(&options.address)
        .map_err(|e| format!("cannot listen on {}: {e}", options.address))?;
    let local = listener
        .local_addr()
        .map_err(|e| format!("cannot listen on {}: {e}", options.address))?;
    let reach = if local.ip().is_loopback() {
        "this machine only; --listen 0.0.0.0:PORT for others"
    } else {
        "reachable from other machines: whoever holds the token can run any FMU here"
    };
    eprintln!("tether host: listening on {local} ({reach})");
    let opening = Arc::new(AtomicUsize::new(0));
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        let peer = stream
            .peer_addr()
            .map_or_else(|_| "a master".to_string(), |a| a.to_string());
        if opening.fetch_add(1, Ordering::AcqRel) >= MAX_OPENING {
            opening.fetch_sub(1, Ordering::AcqRel);
            eprintln!(
                "tether host: {peer}: refused: {MAX_OPENING} connections are opening already"
            );
            continue;
        }
        let (token, max, frame) = (
            token.clone(),
            options.max_fmu_bytes,
            options.max_frame_bytes,
        );
        let opening = Arc::clone(&opening);
        std::thread::spawn(move || {
            if let Err(line) = serve_connection(stream, &token, max, frame, &opening) {
                eprintln!("tether host: {peer}: {line}");
            }
        });
    }
    Ok(())
}

/// One master: the opening, then its host process until the connection ends.
fn serve_connection(
    stream: TcpStream,
    token: &[u8],
    max_fmu: u64,
    max_frame: u64,
    opening: &AtomicUsize,
) -> Result<(), String> {
    // Counted among the openings until its host process starts.
    struct Opened<'a>(&'a AtomicUsize);
    impl Drop for Opened<'_> {
        fn drop(&mut self) {
            self.0.fetch_sub(1, Ordering::AcqRel);
        }
    }
    let opened = Opened(opening);
    let io_error = |e: std::io::Error| format!("the connection failed ({e})");
    stream.set_nodelay(true).map_err(io_error)?;
    stream
        .set_read_timeout(Some(tcp::OPENING_TIMEOUT))
        .map_err(io_error)?;
    let mut reader = BufReader::new(stream.try_clone().map_err(io_error)?);
    let mut writer = stream.try_clone().map_err(io_error)?;
    authenticate(&mut reader, &mut writer, token)?;
    let fmu = receive_fmu(&mut reader, &mut writer, max_fmu)?;
    if !reader.buffer().is_empty() {
        return Err("the master sent requests before the FMU was ready".into());
    }
    stream.set_read_timeout(None).map_err(io_error)?;
    let command = tether_fmi::remote::host_command()?;
    let socket = |s: &TcpStream| s.try_clone().map(|s| Stdio::from(OwnedFd::from(s)));
    let mut host = Command::new(&command.program);
    host.args(&command.args)
        .env(crate::MAX_REQUEST_ENV, max_frame.to_string())
        .stdin(socket(&stream).map_err(io_error)?)
        .stdout(socket(&stream).map_err(io_error)?)
        .process_group(0);
    // SAFETY: prctl between fork and exec, async-signal-safe: the host
    // process ends with this thread's process, the listener.
    unsafe {
        host.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            Ok(())
        });
    }
    let mut child = host
        .spawn()
        .map_err(|e| format!("cannot start {}: {e}", command.program.display()))?;
    drop((reader, opened));
    let status = child.wait().map_err(io_error)?;
    if !status.success() {
        log::info!("host process {}", tether_fmi::remote::describe_exit(status));
    }
    if status.signal().is_some() || !matches!(status.code(), Some(0) | Some(GAVE_UP_CODE)) {
        // The master waits for a reply: it learns how the host process ended
        // (an FMU that crashed it or exited) instead of only that the
        // connection closed.
        let how = tether_fmi::remote::describe_exit(status);
        let _ = Out::default()
            .start(protocol::ENDED)
            .str(&how)
            .send(&mut writer);
    }
    drop((writer, stream));
    drop(fmu); // and its unpacked directory
    Ok(())
}

/// The handshake and the proofs of [`tcp`], host side.
fn authenticate(
    reader: &mut impl Read,
    writer: &mut impl Write,
    token: &[u8],
) -> Result<(), String> {
    let io_error = |e: std::io::Error| format!("the opening failed ({e})");
    let mut frame = Vec::new();
    tcp::receive_at_most(reader, &mut frame, MAX_OPENING_FRAME).map_err(io_error)?;
    let mut hello = In::new(&frame);
    let mut read = || -> std::io::Result<(u8, String, u32, Vec<u8>)> {
        Ok((
            hello.u8()?,
            hello.str()?.to_string(),
            hello.u32()?,
            hello.bytes()?.to_vec(),
        ))
    };
    let (tag, magic, version, master) = read().unwrap_or_default();
    if tag != protocol::OK || magic != tcp::MAGIC || master.len() < 16 {
        return Err("not a Tether master; connection closed".into());
    }
    if version != protocol::VERSION {
        let line = format!(
            "this host speaks protocol version {}, the master {version}; run the same Tether version on both sides",
            protocol::VERSION
        );
        let _ = tcp::refuse(writer, &line);
        return Err(line);
    }
    let host = tcp::nonce().map_err(io_error)?;
    Out::default()
        .start(protocol::OK)
        .u32(protocol::VERSION)
        .bytes(&host)
        .bytes(&tcp::proof(token, "host", &master, &host))
        .send(writer)
        .map_err(io_error)?;
    tcp::receive_at_most(reader, &mut frame, MAX_OPENING_FRAME).map_err(io_error)?;
    let mut answer = In::new(&frame);
    match answer.u8() {
        Ok(protocol::OK) => {}
        Ok(protocol::ERR) => {
            return Err(format!(
                "wrong token: the master holds another one (it says: {})",
                answer.str().unwrap_or("no reason")
            ))
        }
        _ => return Err("not a Tether master; connection closed".into()),
    }
    let proof = answer.bytes().unwrap_or_default();
    if !tcp::verify(token, "master", &master, &host, proof) {
        let _ = tcp::refuse(writer, "wrong token");
        return Err("refused a master with a wrong token".into());
    }
    Out::default()
        .start(protocol::OK)
        .send(writer)
        .map_err(io_error)
}

/// The FMU of the master: an archive it sends in chunks, or a path here;
/// answered with its unpacked directory or one line.
fn receive_fmu(
    reader: &mut impl Read,
    writer: &mut impl Write,
    max_fmu: u64,
) -> Result<Fmu, String> {
    let io_error = |e: std::io::Error| format!("the FMU transfer failed ({e})");
    let mut frame = Vec::new();
    let mut archive: Option<(tempfile::NamedTempFile, u64)> = None;
    let path = loop {
        tcp::receive_at_most(reader, &mut frame, MAX_CHUNK + 16).map_err(io_error)?;
        let mut input = In::new(&frame[1..]);
        match frame[0] {
            FMU_PATH if archive.is_none() => {
                break PathBuf::from(input.str().map_err(io_error)?);
            }
            FMU_CHUNK => {
                let bytes = input.bytes().map_err(io_error)?;
                if archive.is_none() {
                    let file = tempfile::Builder::new()
                        .prefix("tether-host-")
                        .suffix(".fmu")
                        .tempfile()
                        .map_err(io_error)?;
                    archive = Some((file, 0));
                }
                let (file, size) = archive.as_mut().expect("made above");
                *size += bytes.len() as u64;
                if *size > max_fmu {
                    let line = format!(
                        "the FMU archive is larger than this host's limit of {max_fmu} bytes (--max-fmu-mib)"
                    );
                    let _ = tcp::refuse(writer, &line);
                    return Err(line);
                }
                file.write_all(bytes).map_err(io_error)?;
            }
            FMU_END if archive.is_some() => {
                break archive.as_ref().expect("checked").0.path().to_path_buf();
            }
            _ => return Err("a frame that is not part of an FMU transfer".into()),
        }
    };
    let opened = Fmu::open_unloaded(&path, &OpenOptions::default()).and_then(|fmu| {
        fmu.directory()
            .to_str()
            .map(str::to_string)
            .map(|dir| (fmu.clone(), dir))
            .ok_or_else(|| tether_fmi::Error::Io {
                path: fmu.directory().to_path_buf(),
                source: std::io::Error::other("not UTF-8"),
            })
    });
    drop(archive); // unpacked now, or refused
    match opened {
        Ok((fmu, dir)) => {
            Out::default()
                .start(protocol::OK)
                .str(&dir)
                .send(writer)
                .map_err(io_error)?;
            Ok(fmu)
        }
        Err(e) => {
            let line = format!("cannot open the FMU: {e}");
            let _ = tcp::refuse(writer, &line);
            Err(line)
        }
    }
}
