//! Shared by the loopback tests: a listening link on a free port.

use std::sync::atomic::{AtomicU16, Ordering};

use firmware_shim::transport::{Link, TransportError};

/// Ports are handed out from 20000..32000, below Linux's default ephemeral range
/// (32768..=60999): a socket bound to port 0 elsewhere in the run (a client link, a test
/// beside this one) is never given one of them between the check here and the bind.
const FIRST: u16 = 20_000;
const COUNT: u16 = 12_000;

/// Opens `udpin:127.0.0.1:<port>` on a free port and returns the link with its port (the
/// `mavlink` crate binds the address it is given, so the port is chosen first). A port
/// another program holds is skipped.
pub fn open_udpin_on_a_free_port() -> (Link, u16) {
    static NEXT: AtomicU16 = AtomicU16::new(0);
    // Runs of the same tests at once (two checkouts) start apart.
    let start = (std::process::id() % u32::from(COUNT)) as u16;
    let mut last = None;
    for _ in 0..256 {
        let i = NEXT.fetch_add(1, Ordering::Relaxed);
        let port = FIRST + (start.wrapping_add(i.wrapping_mul(7)) % COUNT);
        match Link::open(&format!("udpin:127.0.0.1:{port}").parse().unwrap(), 1) {
            Ok(link) => return (link, port),
            Err(TransportError::Open { source, .. })
                if source.kind() == std::io::ErrorKind::AddrInUse =>
            {
                last = Some(source);
            }
            Err(e) => panic!("udpin:127.0.0.1:{port}: {e}"),
        }
    }
    panic!("no free loopback port in 256 tries: {last:?}")
}
