//! The link to PX4: UDP (`udpin`, `udpout`) or serial, through `mavlink::connect`.
//!
//! Addresses as the `mavlink` crate and MAVSDK spell them:
//!
//! | address | meaning |
//! | --- | --- |
//! | `udpin:127.0.0.1:14540` | listen (PX4 SITL's offboard link sends to 14540); answers go to the last sender |
//! | `udpout:192.168.1.10:14580` | send to a fixed address (and receive on the bound socket) |
//! | `serial:/dev/ttyACM0:921600` | a serial port (Pixhawk TELEM2 / USB) at the given baud rate |
//!
//! [`Link::try_recv`] never blocks, so the controller loop keeps its rate; frames with a bad
//! CRC or of another dialect are dropped by the crate's reader.

use std::str::FromStr;
use std::sync::atomic::{AtomicU8, Ordering};

use mavlink::dialects::common::MavMessage;
use mavlink::{MavConnection, MavHeader};

use crate::messages::COMPANION_COMPONENT;

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

/// An open link: MAVLink 2, common dialect, our system id and the companion component.
pub struct Link {
    conn: mavlink::Connection<MavMessage>,
    address: String,
    system_id: u8,
    component_id: u8,
    sequence: AtomicU8,
}

impl Link {
    /// Opens `address` (non-blocking reads) for the system `system_id` (PX4's companion
    /// convention: the vehicle's system id, 1).
    ///
    /// # Errors
    /// [`TransportError::Open`] if the socket or port cannot be opened.
    pub fn open(address: &Address, system_id: u8) -> Result<Self, TransportError> {
        Self::open_as(address, system_id, COMPANION_COMPONENT)
    }

    /// Opens `address` sending as `system_id` / `component_id` (the simulated PX4 sends as
    /// 1 / 1, the autopilot).
    ///
    /// # Errors
    /// [`TransportError::Open`] if the socket or port cannot be opened.
    pub fn open_as(
        address: &Address,
        system_id: u8,
        component_id: u8,
    ) -> Result<Self, TransportError> {
        let s = address.to_string();
        let open_err = |source| TransportError::Open {
            address: s.clone(),
            source,
        };
        let mut conn = mavlink::connect::<MavMessage>(&s).map_err(open_err)?;
        conn.set_protocol_version(mavlink::MavlinkVersion::V2);
        Ok(Self {
            conn,
            address: s,
            system_id,
            component_id,
            sequence: AtomicU8::new(0),
        })
    }

    /// The address this link was opened with.
    pub fn address(&self) -> &str {
        &self.address
    }

    /// Sends `msg` with this link's system and component ids and the next sequence number.
    ///
    /// # Errors
    /// [`TransportError::Send`] if the crate cannot send (e.g. a `udpin` link that has not
    /// heard from anyone yet has nobody to answer to).
    pub fn send(&self, msg: &MavMessage) -> Result<(), TransportError> {
        let seq = self.sequence.fetch_add(1, Ordering::Relaxed);
        self.conn
            .send(
                &MavHeader {
                    system_id: self.system_id,
                    component_id: self.component_id,
                    sequence: seq,
                },
                msg,
            )
            .map(|_| ())
            .map_err(|e| TransportError::Send {
                address: self.address.clone(),
                message: e.to_string(),
            })
    }

    /// The next received message, if one is waiting; never blocks.
    pub fn try_recv(&self) -> Option<(MavHeader, MavMessage)> {
        self.conn.try_recv().ok()
    }
}
