//! Hosts on other machines: the same requests as over the pipes
//! ([`super::protocol`]), over a TCP connection to `tether host`, after a
//! version handshake, a mutual challenge–response authentication with a
//! shared token and the transfer of the FMU.
//!
//! The opening, frame by frame (the frames of [`super::protocol`]):
//!
//! 1. master → host: [`MAGIC`], the protocol version, a random nonce `m`;
//! 2. host → master: `OK`, its version, a random nonce `h` and
//!    HMAC-SHA256(token, `"host"`, m, h) — or `ERR` and one line;
//! 3. master → host: HMAC-SHA256(token, `"master"`, m, h), once it checked the
//!    host's proof (a host without the token learns nothing and gets no FMU);
//! 4. host → master: `OK`, or `ERR` and one line;
//! 5. master → host: the FMU, as [`FMU_PATH`] (a path on the host) or as
//!    [`FMU_CHUNK`] frames of at most [`MAX_CHUNK`] bytes and [`FMU_END`];
//! 6. host → master: `OK` and the FMU's unpacked directory on the host, or
//!    `ERR` and one line.
//!
//! The token never crosses; proofs are compared in constant time. From there
//! on a host process of its own serves the connection as it serves pipes.

use std::io::{self, BufReader, Read, Write};
use std::net::{TcpStream, ToSocketAddrs};
use std::path::{Path, PathBuf};
use std::time::Duration;

use hmac::{Hmac, Mac};
use sha2::Sha256;

use super::protocol::{self, In, Out};

/// The first bytes a master sends: what it speaks.
pub const MAGIC: &str = "tether-remote";
/// The FMU is the file or directory at this path on the host.
pub const FMU_PATH: u8 = 1;
/// A piece of the FMU archive.
pub const FMU_CHUNK: u8 = 2;
/// The archive is complete.
pub const FMU_END: u8 = 3;
/// The largest piece of an FMU archive in one frame.
pub const MAX_CHUNK: usize = 1 << 20;
/// The largest frame of the opening (before the FMU): a hostile client
/// cannot make the host allocate more before it proved the token.
pub const MAX_OPENING_FRAME: usize = 4096;
/// Random bytes of a nonce.
const NONCE: usize = 32;
/// The longest the opening may take on either side.
pub const OPENING_TIMEOUT: Duration = Duration::from_secs(30);

/// Where an instance's host runs, from its `host`, `token_file` and
/// `fmu_on_host`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RemoteHost {
    /// `ADDR:PORT` (the `tcp://` taken off).
    pub address: String,
    /// The file holding the shared token.
    pub token_file: PathBuf,
    /// The FMU already on the host, instead of sending the archive.
    pub fmu_on_host: Option<PathBuf>,
}

impl RemoteHost {
    /// Parses `tcp://ADDR:PORT`; the error says what is expected.
    pub fn parse_address(url: &str) -> Result<String, String> {
        let address = url
            .strip_prefix("tcp://")
            .ok_or_else(|| format!("'{url}' is not a host address: expected tcp://ADDR:PORT"))?;
        match address.rsplit_once(':') {
            Some((a, p)) if !a.is_empty() && p.parse::<u16>().is_ok() => Ok(address.to_string()),
            _ => Err(format!(
                "'{url}' is not a host address: expected tcp://ADDR:PORT"
            )),
        }
    }
}

/// The token in `path`: its content without surrounding white space. A file
/// that its group or others may read or write is refused, as is an empty one.
pub fn read_token(path: &Path) -> Result<Vec<u8>, String> {
    use std::os::unix::fs::PermissionsExt;
    let shown = path.display();
    let metadata = std::fs::metadata(path).map_err(|e| format!("token file {shown}: {e}"))?;
    let mode = metadata.permissions().mode();
    if mode & 0o077 != 0 {
        return Err(format!(
            "token file {shown} is accessible to others (mode {:o}); run chmod 600 {shown}",
            mode & 0o777
        ));
    }
    let text = std::fs::read(path).map_err(|e| format!("token file {shown}: {e}"))?;
    let token = text.trim_ascii().to_vec();
    if token.len() < 16 {
        return Err(format!(
            "token file {shown} holds fewer than 16 characters; make one with: head -c 32 /dev/urandom | base64 > {shown}"
        ));
    }
    Ok(token)
}

/// A random nonce.
pub fn nonce() -> io::Result<[u8; NONCE]> {
    let mut n = [0u8; NONCE];
    getrandom::fill(&mut n).map_err(|e| io::Error::other(e.to_string()))?;
    Ok(n)
}

/// The proof of `role` (`host` or `master`) that it holds `token`, for the
/// nonces of both sides.
fn mac(token: &[u8], role: &str, master: &[u8], host: &[u8]) -> Hmac<Sha256> {
    let mut mac = Hmac::<Sha256>::new_from_slice(token).expect("HMAC takes keys of any length");
    mac.update(role.as_bytes());
    mac.update(master);
    mac.update(host);
    mac
}

/// The proof of `role` over the nonces.
pub fn proof(token: &[u8], role: &str, master: &[u8], host: &[u8]) -> Vec<u8> {
    mac(token, role, master, host)
        .finalize()
        .into_bytes()
        .to_vec()
}

/// Whether `tag` is the proof of `role` (compared in constant time).
pub fn verify(token: &[u8], role: &str, master: &[u8], host: &[u8], tag: &[u8]) -> bool {
    mac(token, role, master, host).verify_slice(tag).is_ok()
}

/// Reads one frame of at most `max` bytes.
pub fn receive_at_most(from: &mut impl Read, buf: &mut Vec<u8>, max: usize) -> io::Result<()> {
    let mut len = [0u8; 4];
    from.read_exact(&mut len)?;
    let n = u32::from_le_bytes(len) as usize;
    if n == 0 || n > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("a frame of {n} bytes where at most {max} are expected"),
        ));
    }
    buf.clear();
    buf.resize(n, 0);
    from.read_exact(buf)
}

/// A reply `ERR` with one line.
pub fn refuse(to: &mut impl Write, line: &str) -> io::Result<()> {
    Out::default().start(protocol::ERR).str(line).send(to)
}

/// The line of an `ERR` reply, or `Ok` with what follows an `OK`.
fn accepted<'a>(frame: &'a [u8]) -> Result<In<'a>, String> {
    match frame.first() {
        Some(&protocol::OK) => Ok(In::new(&frame[1..])),
        Some(&protocol::ERR) => Err(In::new(&frame[1..])
            .str()
            .unwrap_or("a malformed refusal")
            .to_string()),
        _ => Err("a malformed reply".into()),
    }
}

/// Connects to the host at `host.address`, authenticates both sides and
/// hands it `fmu` (its archive, or the path on the host); returns the
/// connection and the FMU's directory on the host.
pub fn connect(host: &RemoteHost, fmu: &Path) -> Result<(TcpStream, String), String> {
    let token = read_token(&host.token_file)?;
    let address = &host.address;
    let addrs = address
        .to_socket_addrs()
        .map_err(|e| format!("host {address}: {e}"))?;
    let mut last = None;
    let mut stream = None;
    for a in addrs {
        match TcpStream::connect_timeout(&a, OPENING_TIMEOUT) {
            Ok(s) => {
                stream = Some(s);
                break;
            }
            Err(e) => last = Some(e),
        }
    }
    let within = OPENING_TIMEOUT.as_secs();
    let stream = stream.ok_or_else(|| match last {
        Some(e) if e.kind() == io::ErrorKind::TimedOut => {
            format!("no answer from host {address} within {within} s (connect time-out)")
        }
        Some(e) => format!("cannot connect to host {address}: {e}"),
        None => format!("host {address} has no address"),
    })?;
    let io_error = |e: io::Error| match e.kind() {
        io::ErrorKind::WouldBlock | io::ErrorKind::TimedOut => {
            format!("no answer from host {address} within {within} s (read time-out)")
        }
        _ => format!("host {address}: the connection failed ({e})"),
    };
    stream.set_nodelay(true).map_err(io_error)?;
    stream
        .set_read_timeout(Some(OPENING_TIMEOUT))
        .map_err(io_error)?;
    let mut reader = BufReader::new(stream.try_clone().map_err(io_error)?);
    let mut writer = stream.try_clone().map_err(io_error)?;
    let mut frame = Vec::new();
    let mut out = Out::default();

    let master = nonce().map_err(io_error)?;
    out.start(protocol::OK)
        .str(MAGIC)
        .u32(protocol::VERSION)
        .bytes(&master)
        .send(&mut writer)
        .map_err(io_error)?;
    receive_at_most(&mut reader, &mut frame, MAX_OPENING_FRAME).map_err(io_error)?;
    let mut hello = accepted(&frame).map_err(|line| format!("host {address} refused: {line}"))?;
    let mut read = || -> io::Result<(u32, Vec<u8>, Vec<u8>)> {
        Ok((
            hello.u32()?,
            hello.bytes()?.to_vec(),
            hello.bytes()?.to_vec(),
        ))
    };
    let (version, host_nonce, host_proof) =
        read().map_err(|e| format!("host {address} sent a malformed reply ({e})"))?;
    if version != protocol::VERSION {
        return Err(format!(
            "host {address} speaks protocol version {version}, this Tether {}; run the same Tether version on both sides",
            protocol::VERSION
        ));
    }
    if !verify(&token, "host", &master, &host_nonce, &host_proof) {
        let _ = refuse(&mut writer, "the host did not prove the token");
        return Err(format!(
            "host {address} did not prove it holds the token of {} (a different token, or not a Tether host)",
            host.token_file.display()
        ));
    }
    out.start(protocol::OK)
        .bytes(&proof(&token, "master", &master, &host_nonce))
        .send(&mut writer)
        .map_err(io_error)?;
    receive_at_most(&mut reader, &mut frame, MAX_OPENING_FRAME).map_err(io_error)?;
    accepted(&frame).map_err(|line| format!("host {address} refused: {line}"))?;

    // Authenticated: the FMU.
    stream.set_read_timeout(None).map_err(io_error)?;
    match &host.fmu_on_host {
        Some(path) => {
            let path = path
                .to_str()
                .ok_or_else(|| format!("fmu_on_host {} is not UTF-8", path.display()))?;
            out.start(FMU_PATH)
                .str(path)
                .send(&mut writer)
                .map_err(io_error)?;
        }
        None => {
            let mut file = std::fs::File::open(fmu)
                .map_err(|e| format!("cannot send FMU {}: {e}", fmu.display()))?;
            if !file.metadata().is_ok_and(|m| m.is_file()) {
                return Err(format!(
                    "cannot send FMU {}: not an archive (a remote host takes a .fmu file, or fmu_on_host)",
                    fmu.display()
                ));
            }
            let mut chunk = vec![0u8; MAX_CHUNK];
            loop {
                let n = file
                    .read(&mut chunk)
                    .map_err(|e| format!("cannot send FMU {}: {e}", fmu.display()))?;
                if n == 0 {
                    break;
                }
                out.start(FMU_CHUNK)
                    .bytes(&chunk[..n])
                    .send(&mut writer)
                    .map_err(io_error)?;
            }
            out.start(FMU_END).send(&mut writer).map_err(io_error)?;
        }
    }
    receive_at_most(&mut reader, &mut frame, MAX_OPENING_FRAME).map_err(io_error)?;
    let mut opened = accepted(&frame).map_err(|line| format!("host {address}: {line}"))?;
    let dir = opened
        .str()
        .map_err(|e| format!("host {address} sent a malformed reply ({e})"))?
        .to_string();
    if !reader.buffer().is_empty() {
        return Err(format!("host {address} sent more than asked"));
    }
    Ok((stream, dir))
}
