//! Whom a UDP link listens to: one peer at a time, chosen by a [`Trust`] rule, with a count
//! of everything else.
//!
//! System and component ids are labels anyone can write; a source address at least takes
//! a process on the path. The companion's link locks onto the address of the first PX4
//! HEARTBEAT (or an address given by the user) and from then on takes datagrams only from
//! it and sends only to it. Another address is accepted only after the locked one has been
//! silent for [`RELOCK_SILENCE_S`], and only by the same rule. [`Gate`] is that decision,
//! with no socket: [`crate::transport::Link`] feeds it every datagram.

use std::collections::HashSet;
use std::net::SocketAddr;

use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use serde::Serialize;

use crate::messages;

/// The locked peer must be silent this long \[s\] before another may take its place: a
/// second of PX4's 1 Hz HEARTBEAT, and PX4's own offboard-loss time (`COM_OF_LOSS_T`,
/// default 1 s). By then the controller has already declared its odometry lost.
pub const RELOCK_SILENCE_S: f64 = 1.0;

/// Distinct ignored senders remembered for the count (beyond it they are still ignored,
/// only no longer counted as new senders).
const MAX_SENDERS: usize = 1024;

/// Which peer a link accepts.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trust {
    /// The first sender of a PX4 HEARTBEAT (autopilot PX4, component 1), of `system` if
    /// given: the companion's rule.
    Autopilot {
        /// The autopilot's system id, if known in advance.
        system: Option<u8>,
    },
    /// The first sender of any valid MAVLink 2 frame: the simulated PX4's and the relay's
    /// rule (PX4 itself answers whoever sent last).
    FirstSender,
    /// This address only, for the whole session (a `udpout` destination, or an address
    /// the user gave).
    Fixed(SocketAddr),
}

/// A change of the locked peer.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Relock {
    /// When \[s\] since the link opened.
    pub at_s: f64,
    /// The peer that had been silent.
    pub from: String,
    /// The peer now locked.
    pub to: String,
}

/// What the gate let through and what it kept out.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TrustStats {
    /// The locked peer, if any.
    pub peer: Option<String>,
    /// Peer changes after silence.
    pub relocks: Vec<Relock>,
    /// Datagrams from the locked peer.
    pub accepted: u64,
    /// Datagrams from other addresses while a peer was locked.
    pub ignored: u64,
    /// How many distinct addresses those came from (counted up to 1024).
    pub ignored_senders: u64,
    /// Datagrams before any peer was locked that did not qualify to lock one.
    pub before_lock: u64,
}

/// The lock of one link ([`Trust`]) and its counts.
#[derive(Clone, Debug)]
pub struct Gate {
    trust: Trust,
    peer: Option<SocketAddr>,
    last_heard: f64,
    senders: HashSet<SocketAddr>,
    stats: TrustStats,
}

impl Gate {
    /// A gate with no peer yet (or the fixed one).
    pub fn new(trust: Trust) -> Self {
        let peer = match trust {
            Trust::Fixed(a) => Some(a),
            _ => None,
        };
        Self {
            trust,
            peer,
            last_heard: 0.0,
            senders: HashSet::new(),
            stats: TrustStats {
                peer: peer.map(|a| a.to_string()),
                ..TrustStats::default()
            },
        }
    }

    /// The locked peer: where to send.
    pub fn peer(&self) -> Option<SocketAddr> {
        self.peer
    }

    /// The counts so far.
    pub fn stats(&self) -> &TrustStats {
        &self.stats
    }

    /// Whether a datagram from `from` at `now` \[s\], holding `frames` (its valid MAVLink 2
    /// frames), is taken. Locks (or relocks, after [`RELOCK_SILENCE_S`] of silence) onto
    /// `from` when the frames qualify by the gate's rule.
    pub fn admit(
        &mut self,
        from: SocketAddr,
        now: f64,
        frames: &[(MavHeader, MavMessage)],
    ) -> bool {
        if self.peer == Some(from) {
            self.last_heard = now;
            self.stats.accepted += 1;
            return true;
        }
        let open = match self.peer {
            None => true,
            Some(_) => {
                !matches!(self.trust, Trust::Fixed(_)) && now - self.last_heard > RELOCK_SILENCE_S
            }
        };
        if open && self.qualifies(frames) {
            self.lock(from, now);
            return true;
        }
        if self.peer.is_none() {
            self.stats.before_lock += 1;
        } else {
            self.stats.ignored += 1;
            if self.senders.len() < MAX_SENDERS && self.senders.insert(from) {
                self.stats.ignored_senders += 1;
            }
        }
        false
    }

    fn qualifies(&self, frames: &[(MavHeader, MavMessage)]) -> bool {
        match self.trust {
            Trust::Autopilot { system } => frames.iter().any(|(h, m)| {
                messages::px4_heartbeat_system(h, m).is_some_and(|s| system.is_none_or(|w| w == s))
            }),
            Trust::FirstSender => !frames.is_empty(),
            Trust::Fixed(_) => false,
        }
    }

    fn lock(&mut self, to: SocketAddr, now: f64) {
        if let Some(from) = self.peer {
            self.stats.relocks.push(Relock {
                at_s: now,
                from: from.to_string(),
                to: to.to_string(),
            });
        }
        self.peer = Some(to);
        self.last_heard = now;
        self.stats.peer = Some(to.to_string());
        self.stats.accepted += 1;
    }
}
