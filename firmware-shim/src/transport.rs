//! The link to PX4: UDP (`udpin`, `udpout`) on our own socket, or serial through
//! `mavlink::connect`; frames are read and written with the `mavlink` crate.
//!
//! Addresses as the `mavlink` crate and MAVSDK spell them:
//!
//! | address | meaning |
//! | --- | --- |
//! | `udpin:127.0.0.1:14540` | listen (PX4 SITL's offboard link sends to 14540); locked onto one peer ([`Trust`]), answers go to it |
//! | `udpout:192.168.1.10:14580` | send to a fixed address, and take datagrams only from it |
//! | `serial:/dev/ttyACM0:921600` | a serial port (Pixhawk TELEM2 / USB) at the given baud rate |
//!
//! [`Link::try_recv`] never blocks, so the controller loop keeps its rate. On UDP every
//! datagram passes a [`Gate`] (one peer: the companion's link takes only the autopilot that
//! sent the first PX4 HEARTBEAT) and, with a [`SigningKey`], every frame a signature check
//! (MAVLink 2 signing, replays refused); bytes that are no CRC-valid MAVLink 2 frame are
//! dropped. [`Link::stats`] counts all of it.

use std::collections::VecDeque;
use std::net::{Ipv4Addr, Ipv6Addr, SocketAddr, ToSocketAddrs, UdpSocket};
use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};
use std::sync::{Mutex, MutexGuard, PoisonError};
use std::time::Instant;

use mavlink::dialects::common::MavMessage;
use mavlink::{
    MAVLinkMessageRaw, MavConnection, MavHeader, MavlinkReader, MavlinkVersion, Message,
};
use serde::Serialize;

use crate::messages::COMPANION_COMPONENT;
use crate::signing::{Check, Signer, SigningKey};
use crate::trust::{Gate, Trust, TrustStats};

/// Why a link could not be opened or used.
#[derive(Debug, thiserror::Error)]
pub enum TransportError {
    /// The address is malformed.
    #[error(
        "link address `{given}`: {why}; use udpin:127.0.0.1:14540 (PX4 SITL's offboard \
         link), udpout:HOST:PORT or serial:/dev/ttyACM0:921600"
    )]
    Address {
        /// What was given.
        given: String,
        /// What is wrong with it.
        why: String,
    },
    /// Opening the socket or port failed.
    #[error("cannot open `{address}`: {source}")]
    Open {
        /// The address.
        address: String,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// Sending failed.
    #[error("cannot send on `{address}`: {message}")]
    Send {
        /// The address.
        address: String,
        /// The crate's error.
        message: String,
    },
}

/// A parsed link address.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Address {
    /// Listen on HOST:PORT.
    UdpIn {
        /// Host.
        host: String,
        /// Port.
        port: u16,
    },
    /// Send to HOST:PORT.
    UdpOut {
        /// Host.
        host: String,
        /// Port.
        port: u16,
    },
    /// A serial port.
    Serial {
        /// Device path.
        path: String,
        /// Baud rate.
        baud: u32,
    },
}

impl FromStr for Address {
    type Err = TransportError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = |why: &str| TransportError::Address {
            given: s.to_string(),
            why: why.to_string(),
        };
        let (kind, rest) = s.split_once(':').ok_or_else(|| bad("no `kind:` prefix"))?;
        let (left, right) = rest
            .rsplit_once(':')
            .ok_or_else(|| bad("expected `kind:HOST:PORT` or `serial:PATH:BAUD`"))?;
        if left.is_empty() {
            return Err(bad("empty host or path"));
        }
        match kind {
            "udpin" | "udpout" => {
                let port: u16 = right
                    .parse()
                    .map_err(|_| bad("the port must be a number in 0..=65535"))?;
                let host = left.to_string();
                Ok(if kind == "udpin" {
                    Address::UdpIn { host, port }
                } else {
                    if port == 0 {
                        return Err(bad("udpout needs a destination port (not 0)"));
                    }
                    Address::UdpOut { host, port }
                })
            }
            "serial" => {
                let baud: u32 = right
                    .parse()
                    .ok()
                    .filter(|b| *b > 0)
                    .ok_or_else(|| bad("the baud rate must be a positive number"))?;
                Ok(Address::Serial {
                    path: left.to_string(),
                    baud,
                })
            }
            _ => Err(bad("unknown kind (udpin, udpout or serial)")),
        }
    }
}

impl std::fmt::Display for Address {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Address::UdpIn { host, port } => write!(f, "udpin:{host}:{port}"),
            Address::UdpOut { host, port } => write!(f, "udpout:{host}:{port}"),
            Address::Serial { path, baud } => write!(f, "serial:{path}:{baud}"),
        }
    }
}

/// How a link is opened: who it speaks as, whom it trusts, whether it signs.
#[derive(Clone, Debug)]
pub struct LinkOptions {
    /// Our system id.
    pub system_id: u8,
    /// Our component id.
    pub component_id: u8,
    /// Whom a `udpin` link locks onto (a `udpout` link trusts its destination only; a
    /// serial port is one peer by wiring).
    pub trust: Trust,
    /// Sign every frame sent and take only frames signed with this key.
    pub signing: Option<SigningKey>,
    /// The signature's link id.
    pub link_id: u8,
}

impl LinkOptions {
    /// The companion's link (`mpcc fly`): our system `system_id`, the companion component,
    /// locked onto the first PX4 HEARTBEAT's sender.
    pub fn companion(system_id: u8) -> Self {
        Self {
            system_id,
            component_id: COMPANION_COMPONENT,
            trust: Trust::Autopilot { system: None },
            signing: None,
            link_id: 0,
        }
    }

    /// The simulated autopilot's link (`mpcc sitl`, PX4's own ids): locked onto the first
    /// sender, as PX4 answers whoever sends to it.
    pub fn autopilot(system_id: u8, component_id: u8) -> Self {
        Self {
            system_id,
            component_id,
            trust: Trust::FirstSender,
            signing: None,
            link_id: 1,
        }
    }
}

/// What a link took in and kept out, for the session's summary.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct LinkStats {
    /// The peer lock's counts (UDP only).
    pub trust: TrustStats,
    /// Datagrams with no CRC-valid MAVLink 2 frame (random bytes, truncated frames, a bad
    /// CRC, MAVLink 1).
    pub malformed: u64,
    /// Whether frames are signed and checked.
    pub signing: bool,
    /// Unsigned frames refused (signing on).
    pub unsigned: u64,
    /// Frames signed with another key (or altered) refused.
    pub bad_signature: u64,
    /// Frames with a correct signature but an old timestamp (replays) refused.
    pub replayed: u64,
}

/// The most frames taken from one datagram (a MAVLink 2 frame is at least 12 bytes).
const MAX_FRAMES_PER_DATAGRAM: usize = 64;

enum Io {
    Udp(UdpSocket),
    Serial(Box<mavlink::Connection<MavMessage>>),
}

struct Inbox {
    gate: Gate,
    queue: VecDeque<(MavHeader, MavMessage)>,
    stats: LinkStats,
    buf: Vec<u8>,
}

/// An open link: MAVLink 2, common dialect, our system and component ids; on UDP locked
/// onto one peer ([`Trust`]) and, with a key, signed.
pub struct Link {
    io: Io,
    address: String,
    system_id: u8,
    component_id: u8,
    sequence: AtomicU8,
    signer: Option<Signer>,
    inbox: Mutex<Inbox>,
    opened: Instant,
}

impl Link {
    /// Opens `address` (non-blocking reads) as the companion of system `system_id`
    /// ([`LinkOptions::companion`]).
    ///
    /// # Errors
    /// [`TransportError::Open`] if the socket or port cannot be opened.
    pub fn open(address: &Address, system_id: u8) -> Result<Self, TransportError> {
        Self::open_with(address, &LinkOptions::companion(system_id))
    }

    /// Opens `address` sending as `system_id` / `component_id`, locked onto the first
    /// sender ([`LinkOptions::autopilot`]: the simulated PX4 sends as 1 / 1).
    ///
    /// # Errors
    /// [`TransportError::Open`] if the socket or port cannot be opened.
    pub fn open_as(
        address: &Address,
        system_id: u8,
        component_id: u8,
    ) -> Result<Self, TransportError> {
        Self::open_with(address, &LinkOptions::autopilot(system_id, component_id))
    }

    /// Opens `address` with `options`.
    ///
    /// # Errors
    /// [`TransportError::Open`] if the socket or port cannot be opened or a host does not
    /// resolve.
    pub fn open_with(address: &Address, options: &LinkOptions) -> Result<Self, TransportError> {
        let s = address.to_string();
        let open_err = |source| TransportError::Open {
            address: s.clone(),
            source,
        };
        let signer = options
            .signing
            .clone()
            .map(|k| Signer::new(k, options.link_id));
        let (io, trust) = match address {
            Address::UdpIn { host, port } => {
                let socket = UdpSocket::bind((host.as_str(), *port)).map_err(open_err)?;
                (Io::Udp(socket), options.trust)
            }
            Address::UdpOut { host, port } => {
                let to = resolve(host, *port).map_err(open_err)?;
                let any: SocketAddr = if to.is_ipv4() {
                    (Ipv4Addr::UNSPECIFIED, 0).into()
                } else {
                    (Ipv6Addr::UNSPECIFIED, 0).into()
                };
                (
                    Io::Udp(UdpSocket::bind(any).map_err(open_err)?),
                    Trust::Fixed(to),
                )
            }
            Address::Serial { .. } => {
                let mut conn = mavlink::connect::<MavMessage>(&s).map_err(open_err)?;
                conn.set_protocol_version(mavlink::MavlinkVersion::V2);
                if let Some(k) = &options.signing {
                    conn.setup_signing(Some(k.config(options.link_id)));
                }
                (Io::Serial(Box::new(conn)), options.trust)
            }
        };
        if let Io::Udp(socket) = &io {
            socket.set_nonblocking(true).map_err(open_err)?;
        }
        Ok(Self {
            io,
            address: s,
            system_id: options.system_id,
            component_id: options.component_id,
            sequence: AtomicU8::new(0),
            inbox: Mutex::new(Inbox {
                gate: Gate::new(trust),
                queue: VecDeque::new(),
                stats: LinkStats {
                    signing: signer.is_some(),
                    ..LinkStats::default()
                },
                buf: vec![0; 65_536],
            }),
            signer,
            opened: Instant::now(),
        })
    }

    /// The address this link was opened with.
    pub fn address(&self) -> &str {
        &self.address
    }

    /// The local address of a UDP link's socket (`udpin:HOST:0` binds a free port).
    pub fn local_addr(&self) -> Option<SocketAddr> {
        match &self.io {
            Io::Udp(socket) => socket.local_addr().ok(),
            Io::Serial(_) => None,
        }
    }

    /// The peer a UDP link is locked onto (where it sends), if any yet.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.inbox().gate.peer()
    }

    /// What the link took in and kept out so far.
    pub fn stats(&self) -> LinkStats {
        let inbox = self.inbox();
        LinkStats {
            trust: inbox.gate.stats().clone(),
            ..inbox.stats.clone()
        }
    }

    fn inbox(&self) -> MutexGuard<'_, Inbox> {
        // A panic while holding the lock leaves counts and a queue, nothing inconsistent.
        self.inbox.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Sends `msg` with this link's system and component ids and the next sequence number
    /// (signed if the link signs) to the locked peer.
    ///
    /// # Errors
    /// [`TransportError::Send`] if sending fails, or a `udpin` link has locked onto no peer
    /// yet (it has nobody to answer to).
    pub fn send(&self, msg: &MavMessage) -> Result<(), TransportError> {
        let header = MavHeader {
            system_id: self.system_id,
            component_id: self.component_id,
            sequence: self.sequence.fetch_add(1, Ordering::Relaxed),
        };
        let fail = |message: String| TransportError::Send {
            address: self.address.clone(),
            message,
        };
        let socket = match &self.io {
            Io::Serial(conn) => {
                return conn
                    .send(&header, msg)
                    .map(|_| ())
                    .map_err(|e| fail(e.to_string()));
            }
            Io::Udp(socket) => socket,
        };
        let peer = self
            .peer()
            .ok_or_else(|| fail("no autopilot to answer yet (no PX4 HEARTBEAT heard)".into()))?;
        let mut frame = Vec::with_capacity(mavlink::consts::MAX_FRAME_SIZE);
        let written = match &self.signer {
            Some(s) => mavlink::write_v2_msg_signed(&mut frame, header, msg, Some(s.data())),
            None => mavlink::write_v2_msg(&mut frame, header, msg),
        };
        written.map_err(|e| fail(e.to_string()))?;
        socket
            .send_to(&frame, peer)
            .map(|_| ())
            .map_err(|e| fail(e.to_string()))
    }

    /// The next received message from the locked peer, if one is waiting; never blocks.
    /// Datagrams from other addresses, unsigned or wrongly signed frames (with a key) and
    /// bytes that are no MAVLink 2 are dropped and counted ([`Link::stats`]).
    pub fn try_recv(&self) -> Option<(MavHeader, MavMessage)> {
        let socket = match &self.io {
            Io::Serial(conn) => return conn.try_recv().ok(),
            Io::Udp(socket) => socket,
        };
        let mut inbox = self.inbox();
        loop {
            if let Some(m) = inbox.queue.pop_front() {
                return Some(m);
            }
            let inbox = &mut *inbox;
            let (n, from) = socket.recv_from(&mut inbox.buf).ok()?;
            let frames = decode(&inbox.buf[..n], self.signer.as_ref(), &mut inbox.stats);
            let now = self.opened.elapsed().as_secs_f64();
            if inbox.gate.admit(from, now, &frames) {
                inbox.queue.extend(frames);
            }
        }
    }
}

/// The first address `host:port` resolves to.
fn resolve(host: &str, port: u16) -> std::io::Result<SocketAddr> {
    (host, port).to_socket_addrs()?.next().ok_or_else(|| {
        std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!("`{host}` resolves to no address"),
        )
    })
}

/// The CRC-valid MAVLink 2 frames of `datagram` that pass the `signer`'s check (all of
/// them without one), decoded; what is refused is counted in `stats`.
fn decode(
    datagram: &[u8],
    signer: Option<&Signer>,
    stats: &mut LinkStats,
) -> Vec<(MavHeader, MavMessage)> {
    let mut reader = MavlinkReader::new(datagram);
    let mut out = Vec::new();
    let mut valid = 0;
    while valid < MAX_FRAMES_PER_DATAGRAM {
        let Ok(raw) = reader.read_raw_message::<MavMessage>(MavlinkVersion::V2) else {
            break;
        };
        let MAVLinkMessageRaw::V2(raw) = raw else {
            continue;
        };
        valid += 1;
        let verdict = signer.map_or(Check::Valid, |s| s.check(&raw));
        match verdict {
            Check::Valid => {}
            Check::Unsigned => stats.unsigned += 1,
            Check::BadSignature => stats.bad_signature += 1,
            Check::Replayed => stats.replayed += 1,
        }
        if verdict != Check::Valid {
            continue;
        }
        let header = MavHeader {
            system_id: raw.system_id(),
            component_id: raw.component_id(),
            sequence: raw.sequence(),
        };
        if let Ok(m) = MavMessage::parse(MavlinkVersion::V2, raw.message_id(), raw.payload()) {
            out.push((header, m));
        }
    }
    if valid == 0 {
        stats.malformed += 1;
    }
    out
}
