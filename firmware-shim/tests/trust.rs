//! The link trusts one autopilot: locked onto the first PX4 HEARTBEAT's sender, deaf to
//! every other address and to bytes that are no MAVLink 2, and with a key, to anything not
//! signed with it (replays included). Peers here are plain UDP sockets writing frames with
//! the `mavlink` crate.

use std::net::UdpSocket;
use std::time::{Duration, Instant};

use firmware_shim::messages::{self, heartbeat, set_attitude_target};
use firmware_shim::signing::{Check, Signer, SigningKey};
use firmware_shim::transport::{Link, LinkOptions};
use firmware_shim::trust::{RELOCK_SILENCE_S, Trust};
use mavlink::dialects::common::{MavFrame, MavMessage, ODOMETRY_DATA};
use mavlink::{MAVLinkMessageRaw, MavHeader, MavlinkReader, MavlinkVersion};
use rand::{Rng, SeedableRng};

mod support;

const PX4: MavHeader = MavHeader {
    system_id: 1,
    component_id: 1,
    sequence: 0,
};

fn frame(msg: &MavMessage, signer: Option<&Signer>) -> Vec<u8> {
    let mut out = Vec::new();
    match signer {
        Some(s) => mavlink::write_v2_msg_signed(&mut out, PX4, msg, Some(s.data())),
        None => mavlink::write_v2_msg(&mut out, PX4, msg),
    }
    .unwrap();
    out
}

fn px4_heartbeat() -> MavMessage {
    let mut m = heartbeat();
    if let MavMessage::HEARTBEAT(h) = &mut m {
        h.autopilot = mavlink::dialects::common::MavAutopilot::MAV_AUTOPILOT_PX4;
        h.mavtype = mavlink::dialects::common::MavType::MAV_TYPE_QUADROTOR;
    }
    m
}

fn odometry(x: f32, t_us: u64) -> MavMessage {
    MavMessage::ODOMETRY(ODOMETRY_DATA {
        time_usec: t_us,
        x,
        z: -2.0,
        q: [1.0, 0.0, 0.0, 0.0],
        frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        child_frame_id: MavFrame::MAV_FRAME_LOCAL_NED,
        ..ODOMETRY_DATA::DEFAULT
    })
}

fn peer() -> UdpSocket {
    let s = UdpSocket::bind("127.0.0.1:0").unwrap();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    s
}

/// Everything `link` hands out within `wait`.
fn drain(link: &Link, wait: Duration) -> Vec<MavMessage> {
    let start = Instant::now();
    let mut out = Vec::new();
    while start.elapsed() < wait {
        while let Some((_, m)) = link.try_recv() {
            out.push(m);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    out
}

/// How many datagrams `s` receives within `wait`.
fn received(s: &UdpSocket, wait: Duration) -> usize {
    let start = Instant::now();
    let mut buf = [0u8; 2048];
    let mut n = 0;
    while start.elapsed() < wait {
        if s.recv(&mut buf).is_ok() {
            n += 1;
        }
    }
    n
}

fn x_of(m: &MavMessage) -> Option<f32> {
    match m {
        MavMessage::ODOMETRY(o) => Some(o.x),
        _ => None,
    }
}

#[test]
fn the_companion_locks_onto_the_first_px4_heartbeat_and_ignores_everyone_else() {
    let (link, port) = support::open_udpin_on_a_free_port();
    let (px4, rogue) = (peer(), peer());
    px4.connect(("127.0.0.1", port)).unwrap();
    rogue.connect(("127.0.0.1", port)).unwrap();
    // Before any PX4 HEARTBEAT nothing is taken and nothing can be sent.
    rogue.send(&frame(&odometry(30.0, 1), None)).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    assert!(link.send(&set_attitude_target([0.0; 3], 0.5, 0)).is_err());
    // PX4 speaks first: the link is its.
    px4.send(&frame(&px4_heartbeat(), None)).unwrap();
    px4.send(&frame(&odometry(1.0, 10), None)).unwrap();
    // The rogue then claims to be PX4 (same ids, a PX4 heartbeat), 500 times (read as it
    // goes, so that no datagram is lost to a full socket buffer).
    let mut got = Vec::new();
    for i in 0..250 {
        rogue.send(&frame(&px4_heartbeat(), None)).unwrap();
        rogue
            .send(&frame(&odometry(30.0, 1_000_000_000 + i), None))
            .unwrap();
        got.extend(drain(&link, Duration::from_micros(200)));
    }
    got.extend(drain(&link, Duration::from_millis(100)));
    assert_eq!(got.len(), 2, "{got:?}");
    assert_eq!(got.iter().filter_map(x_of).collect::<Vec<_>>(), [1.0]);
    // Setpoints go to PX4 only.
    for i in 0..20 {
        link.send(&set_attitude_target([0.0; 3], 0.5, i)).unwrap();
    }
    assert_eq!(received(&px4, Duration::from_millis(200)), 20);
    assert_eq!(received(&rogue, Duration::from_millis(100)), 0);
    let s = link.stats();
    assert_eq!(s.trust.peer, Some(px4.local_addr().unwrap().to_string()));
    assert_eq!((s.trust.ignored, s.trust.ignored_senders), (500, 1));
    assert_eq!((s.trust.before_lock, s.trust.accepted), (1, 2));
    assert!(s.trust.relocks.is_empty());
}

#[test]
fn another_autopilot_is_taken_only_after_the_locked_one_fell_silent() {
    let (link, port) = support::open_udpin_on_a_free_port();
    let (px4, other) = (peer(), peer());
    px4.connect(("127.0.0.1", port)).unwrap();
    other.connect(("127.0.0.1", port)).unwrap();
    px4.send(&frame(&px4_heartbeat(), None)).unwrap();
    assert_eq!(drain(&link, Duration::from_millis(50)).len(), 1);
    // Silent for less than the link-loss time: still refused.
    std::thread::sleep(Duration::from_secs_f64(RELOCK_SILENCE_S * 0.5));
    other.send(&frame(&px4_heartbeat(), None)).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    // Silent for longer: a PX4 heartbeat relocks, anything else does not.
    std::thread::sleep(Duration::from_secs_f64(RELOCK_SILENCE_S * 0.6));
    other.send(&frame(&odometry(5.0, 1), None)).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    other.send(&frame(&px4_heartbeat(), None)).unwrap();
    assert_eq!(drain(&link, Duration::from_millis(50)).len(), 1);
    // The old autopilot is now the stranger.
    px4.send(&frame(&px4_heartbeat(), None)).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    let s = link.stats();
    assert_eq!(s.trust.relocks.len(), 1);
    assert_eq!(
        s.trust.relocks[0].from,
        px4.local_addr().unwrap().to_string()
    );
    assert_eq!(
        s.trust.relocks[0].to,
        other.local_addr().unwrap().to_string()
    );
    assert_eq!(s.trust.ignored, 3);
}

#[test]
fn an_expected_system_or_a_fixed_address_narrows_the_lock() {
    let mut opts = LinkOptions::companion(1);
    opts.trust = Trust::Autopilot { system: Some(2) };
    let (link, port) = support::open_udpin_with(&opts);
    let p = peer();
    p.connect(("127.0.0.1", port)).unwrap();
    p.send(&frame(&px4_heartbeat(), None)).unwrap(); // system 1: not the one expected
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    let mut buf = Vec::new();
    let sys2 = MavHeader {
        system_id: 2,
        ..PX4
    };
    mavlink::write_v2_msg(&mut buf, sys2, &px4_heartbeat()).unwrap();
    p.send(&buf).unwrap();
    assert_eq!(drain(&link, Duration::from_millis(50)).len(), 1);

    // A udpin link given the autopilot's address (`mpcc fly --autopilot`) takes only it,
    // even when another sends a PX4 HEARTBEAT first.
    let px4 = peer();
    let mut opts = LinkOptions::companion(1);
    opts.trust = Trust::Fixed(px4.local_addr().unwrap());
    let (fixed, port) = support::open_udpin_with(&opts);
    p.send_to(&frame(&px4_heartbeat(), None), ("127.0.0.1", port))
        .unwrap();
    px4.send_to(&frame(&odometry(4.0, 1), None), ("127.0.0.1", port))
        .unwrap();
    let got = drain(&fixed, Duration::from_millis(50));
    assert_eq!(got.iter().filter_map(x_of).collect::<Vec<_>>(), [4.0]);
    assert_eq!(got.len(), 1);
    assert_eq!(fixed.stats().trust.ignored, 1);

    // A udpout link takes only its destination.
    let dest = peer();
    let stranger = peer();
    let out = Link::open(
        &format!("udpout:{}", dest.local_addr().unwrap())
            .parse()
            .unwrap(),
        1,
    )
    .unwrap();
    out.send(&set_attitude_target([0.0; 3], 0.5, 0)).unwrap();
    let mut b = [0u8; 512];
    let (_, from) = dest.recv_from(&mut b).unwrap();
    stranger
        .send_to(&frame(&px4_heartbeat(), None), from)
        .unwrap();
    assert!(drain(&out, Duration::from_millis(50)).is_empty());
    dest.send_to(&frame(&px4_heartbeat(), None), from).unwrap();
    assert_eq!(drain(&out, Duration::from_millis(50)).len(), 1);
    assert_eq!(out.stats().trust.ignored, 1);
}

/// Random bytes, half with the MAVLink 2 magic first; truncated frames; frames with one
/// byte flipped (a bad CRC); MAVLink 1 frames; oversized datagrams.
fn junk(rng: &mut rand::rngs::StdRng, good: &[u8], v1: &[u8]) -> Vec<u8> {
    match rng.random_range(0..5) {
        0 => {
            let mut b: Vec<u8> = (0..rng.random_range(1..300))
                .map(|_| rng.random())
                .collect();
            if rng.random_bool(0.5) {
                b[0] = 0xFD;
            }
            b
        }
        1 => good[..rng.random_range(1..good.len())].to_vec(),
        2 => {
            let mut b = good.to_vec();
            let i = rng.random_range(1..b.len());
            b[i] ^= 1 << rng.random_range(0..8);
            b
        }
        3 => v1.to_vec(),
        _ => (0..rng.random_range(2_000..60_000))
            .map(|_| rng.random())
            .collect(),
    }
}

#[test]
fn junk_at_a_kilohertz_from_the_autopilot_and_a_stranger_changes_nothing() {
    let (link, port) = support::open_udpin_on_a_free_port();
    let (px4, stranger) = (peer(), peer());
    px4.connect(("127.0.0.1", port)).unwrap();
    stranger.connect(("127.0.0.1", port)).unwrap();
    px4.send(&frame(&px4_heartbeat(), None)).unwrap();
    let good = frame(&odometry(2.0, 7), None);
    let mut v1 = Vec::new();
    mavlink::write_v1_msg(&mut v1, PX4, &px4_heartbeat()).unwrap();
    let mut rng = rand::rngs::StdRng::seed_from_u64(35);
    let mut got = Vec::new();
    let (mut junk_sent, mut genuine) = (0u64, 0usize);
    for i in 0..2_000 {
        let from = if i % 2 == 0 { &px4 } else { &stranger };
        if from.send(&junk(&mut rng, &good, &v1)).is_ok() {
            junk_sent += 1;
        }
        if i % 50 == 0 {
            px4.send(&good).unwrap();
            genuine += 1;
        }
        while let Some((_, m)) = link.try_recv() {
            got.push(m);
        }
        std::thread::sleep(Duration::from_micros(1_000));
    }
    got.extend(drain(&link, Duration::from_millis(100)));
    // Only the heartbeat and the genuine odometry (x = 2) came through.
    let xs: Vec<f32> = got.iter().filter_map(x_of).collect();
    assert_eq!(xs, vec![2.0; genuine], "{:?}", &got[..got.len().min(5)]);
    assert_eq!(got.len(), genuine + 1);
    let s = link.stats();
    assert!(s.malformed >= junk_sent / 4, "{s:?} of {junk_sent}");
    assert!(s.trust.ignored >= junk_sent / 2 - 5, "{s:?}");
    // And it still answers the autopilot.
    link.send(&set_attitude_target([0.0; 3], 0.5, 0)).unwrap();
    assert_eq!(received(&px4, Duration::from_millis(100)), 1);
}

fn key(b: u8) -> SigningKey {
    SigningKey::new([b; 32])
}

#[test]
fn with_a_key_only_frames_signed_with_it_and_newer_than_the_last_are_taken() {
    let mut opts = LinkOptions::companion(1);
    opts.signing = Some(key(7));
    let (link, port) = support::open_udpin_with(&opts);
    let px4 = peer();
    px4.connect(("127.0.0.1", port)).unwrap();
    let px4_signer = Signer::new(key(7), 3);
    let wrong = Signer::new(key(8), 3);
    // Unsigned and wrongly signed heartbeats do not even lock the link.
    px4.send(&frame(&px4_heartbeat(), None)).unwrap();
    px4.send(&frame(&px4_heartbeat(), Some(&wrong))).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    assert!(link.peer().is_none());
    let hb = frame(&px4_heartbeat(), Some(&px4_signer));
    px4.send(&hb).unwrap();
    let od = frame(&odometry(1.0, 5), Some(&px4_signer));
    px4.send(&od).unwrap();
    assert_eq!(drain(&link, Duration::from_millis(50)).len(), 2);
    // The same frames again (a replay), an altered one, a wrong key: all refused.
    px4.send(&hb).unwrap();
    px4.send(&od).unwrap();
    let mut altered = frame(&odometry(1.0, 6), Some(&px4_signer));
    altered[12] ^= 0x40; // in the payload; the CRC is fixed up below
    let crc = mavlink::calculate_crc(
        &altered[1..altered.len() - 15],
        <MavMessage as mavlink::Message>::extra_crc(331),
    );
    let n = altered.len();
    altered[n - 15..n - 13].copy_from_slice(&crc.to_le_bytes());
    px4.send(&altered).unwrap();
    px4.send(&frame(&odometry(30.0, 7), Some(&wrong))).unwrap();
    px4.send(&frame(&odometry(30.0, 8), None)).unwrap();
    assert!(drain(&link, Duration::from_millis(50)).is_empty());
    let s = link.stats();
    assert!(s.signing);
    assert_eq!(
        (s.unsigned, s.bad_signature, s.replayed),
        (2, 3, 2),
        "{s:?}"
    );
    // A new frame signed with the key is taken again.
    px4.send(&frame(&odometry(3.0, 9), Some(&px4_signer)))
        .unwrap();
    let got = drain(&link, Duration::from_millis(50));
    assert_eq!(got.iter().filter_map(x_of).collect::<Vec<_>>(), [3.0]);
    // What the link sends is signed with the key (and not with another).
    link.send(&set_attitude_target([0.0; 3], 0.5, 0)).unwrap();
    let mut buf = [0u8; 512];
    let n = px4.recv(&mut buf).unwrap();
    let MAVLinkMessageRaw::V2(raw) = MavlinkReader::new(&buf[..n])
        .read_raw_message::<MavMessage>(MavlinkVersion::V2)
        .unwrap()
    else {
        panic!("a MAVLink 2 frame")
    };
    assert_eq!(Signer::new(key(8), 9).check(&raw), Check::BadSignature);
    assert_eq!(Signer::new(key(7), 9).check(&raw), Check::Valid);
    assert_eq!(raw.system_id(), 1);
    assert_eq!(raw.component_id(), messages::COMPANION_COMPONENT);
}
