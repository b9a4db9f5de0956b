//! The link over loopback UDP, and the shim's packets checked by pymavlink (an independent
//! MAVLink implementation; `.ci/run` installs it).

use std::io::{BufRead, BufReader};
use std::process::{Command as Process, Stdio};
use std::time::{Duration, Instant};

use firmware_shim::messages::{
    self, Command, Px4Mode, command_long, heartbeat, set_attitude_target,
};
use firmware_shim::transport::{Address, Link, LinkOptions, TransportError};
use mavlink::dialects::common::MavMessage;

mod support;

#[test]
fn addresses_parse_and_bad_ones_say_what_to_use() {
    assert_eq!(
        "udpin:127.0.0.1:14540".parse::<Address>().unwrap(),
        Address::UdpIn {
            host: "127.0.0.1".into(),
            port: 14540
        }
    );
    assert_eq!(
        "udpout:10.0.0.2:14580".parse::<Address>().unwrap(),
        Address::UdpOut {
            host: "10.0.0.2".into(),
            port: 14580
        }
    );
    assert_eq!(
        "serial:/dev/ttyACM0:921600".parse::<Address>().unwrap(),
        Address::Serial {
            path: "/dev/ttyACM0".into(),
            baud: 921_600
        }
    );
    for (bad, why) in [
        ("14540", "no `kind:`"),
        ("udp:127.0.0.1:14540", "unknown kind"),
        ("udpin:127.0.0.1:port", "port must be a number"),
        ("udpin:127.0.0.1:70000", "port must be a number"),
        ("udpout:127.0.0.1:0", "destination port"),
        ("serial:/dev/ttyACM0:0", "baud rate"),
        ("udpin::14540", "empty host"),
    ] {
        let e = bad.parse::<Address>().unwrap_err();
        assert!(matches!(e, TransportError::Address { .. }), "{bad}");
        let msg = e.to_string();
        assert!(msg.contains(why), "{bad}: {msg}");
        assert!(msg.contains("udpin:127.0.0.1:14540"), "{bad}: {msg}");
    }
    for a in [
        "udpin:0.0.0.0:14540",
        "udpout:1.2.3.4:5",
        "serial:COM3:57600",
    ] {
        assert_eq!(a.parse::<Address>().unwrap().to_string(), a);
    }
}

fn recv_within(link: &Link, timeout: Duration) -> Option<MavMessage> {
    let start = Instant::now();
    while start.elapsed() < timeout {
        if let Some((_, m)) = link.try_recv() {
            return Some(m);
        }
        std::thread::sleep(Duration::from_millis(1));
    }
    None
}

#[test]
fn udpin_and_udpout_talk_over_loopback_without_blocking() {
    // The listening side as the simulated PX4 (locked onto the first sender).
    let (server, port) = support::open_udpin_with(&LinkOptions::autopilot(1, 1));
    let client = Link::open(&format!("udpout:127.0.0.1:{port}").parse().unwrap(), 1).unwrap();
    // Nothing waiting: returns at once.
    let t = Instant::now();
    assert!(server.try_recv().is_none());
    assert!(t.elapsed() < Duration::from_millis(500));
    let sent: Vec<MavMessage> = (0..5)
        .map(|i| set_attitude_target([0.1 * i as f32, 0.0, -0.2], 0.5, i))
        .collect();
    for m in &sent {
        client.send(m).unwrap();
    }
    for m in &sent {
        assert_eq!(
            recv_within(&server, Duration::from_secs(5)).as_ref(),
            Some(m)
        );
    }
    // udpin answers the sender it locked onto.
    server.send(&heartbeat()).unwrap();
    assert!(matches!(
        recv_within(&client, Duration::from_secs(5)),
        Some(MavMessage::HEARTBEAT(_))
    ));
}

#[test]
fn pymavlink_decodes_what_the_shim_sends() {
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/pymavlink_check.py");
    let msgs = vec![
        heartbeat(),
        set_attitude_target([0.5, -1.0, 0.25], 0.0, 10),
        set_attitude_target([0.0, 0.0, 0.0], 0.495, 20),
        set_attitude_target([-3.0, 3.0, 1.0], 1.0, 30),
        command_long(Command::SetMode(Px4Mode::Offboard), 0),
        command_long(Command::Arm, 1),
    ];
    let mut child = Process::new("python3")
        .arg(script)
        .arg(msgs.len().to_string())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("python3 runs (installed by .ci/run with pymavlink)");
    let mut out = BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    out.read_line(&mut line).unwrap();
    let port: u16 = line.trim().parse().unwrap_or_else(|_| {
        let mut err = String::new();
        let _ = std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut err);
        panic!(
            "pymavlink_check.py did not start (is pymavlink installed? `python3 -m pip install \
             pymavlink`): {line}{err}"
        )
    });
    let link = Link::open(&format!("udpout:127.0.0.1:{port}").parse().unwrap(), 1).unwrap();
    for m in &msgs {
        link.send(m).unwrap();
    }
    line.clear();
    out.read_line(&mut line).unwrap();
    let status = child.wait().unwrap();
    let v: serde_json::Value = serde_json::from_str(line.trim()).expect(&line);
    assert!(status.success(), "{v}");
    assert_eq!(v["ok"], true, "{v}");
    let decoded = v["decoded"].as_array().unwrap();
    let names: Vec<&str> = decoded
        .iter()
        .map(|d| d["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "HEARTBEAT",
            "SET_ATTITUDE_TARGET",
            "SET_ATTITUDE_TARGET",
            "SET_ATTITUDE_TARGET",
            "COMMAND_LONG",
            "COMMAND_LONG"
        ]
    );
    let ids: Vec<u64> = decoded.iter().map(|d| d["id"].as_u64().unwrap()).collect();
    assert_eq!(ids, [0, 82, 82, 82, 76, 76]);
    assert_eq!(decoded[0]["type"], 18);
    assert_eq!(decoded[0]["autopilot"], 8);
    assert_eq!(decoded[2]["thrust"].as_f64().unwrap() as f32, 0.495);
    assert_eq!(decoded[1]["rates"][1].as_f64().unwrap(), -1.0);
    assert_eq!(decoded[4]["command"], 176);
    assert_eq!(decoded[4]["params"][1], 6.0);
    assert_eq!(decoded[5]["command"], 400);
    for d in decoded {
        assert_eq!(d["header"][1], u64::from(messages::COMPANION_COMPONENT));
    }
}
