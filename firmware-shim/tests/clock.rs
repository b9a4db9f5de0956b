//! The vehicle clock against clocks whose truth is known: rates 5 % off the wall clock
//! either way, jittered delays, jumps forward and back, a stream of states from another clock
//! interleaved with the vehicle's; and the TIMESYNC round trips.

use firmware_shim::clock::{RoundTrip, VehicleClock, Verdict};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// States every 10 ms of wall time from a vehicle whose clock runs at `rate` with `offset`,
/// delayed by 1 ms plus up to `jitter` s: (vehicle time, arrival wall time).
fn stream(rate: f64, offset: f64, jitter: f64, seconds: f64, seed: u64) -> Vec<(f64, f64)> {
    let mut rng = StdRng::seed_from_u64(seed);
    let mut out: Vec<(f64, f64)> = (0..(seconds * 100.0) as usize)
        .map(|i| {
            let sent = i as f64 * 0.01;
            let delay = 0.001 + rng.random::<f64>() * jitter;
            (offset + rate * sent, sent + delay)
        })
        .collect();
    out.sort_by(|a, b| a.1.total_cmp(&b.1));
    out
}

#[test]
fn the_rate_and_offset_are_followed_five_percent_off_the_wall_clock() {
    for (rate, jitter) in [
        (0.95, 0.0),
        (1.05, 0.0),
        (0.988, 0.03),
        (1.1, 0.03),
        (0.9, 0.01),
    ] {
        let mut clock = VehicleClock::default();
        for (v, w) in stream(rate, 1000.0, jitter, 12.0, 7) {
            assert_eq!(clock.observe(v, w), Verdict::Consistent, "rate {rate}");
        }
        assert!(
            (clock.rate() - rate).abs() < 2e-3,
            "rate {rate}: {}",
            clock.rate()
        );
        // The clock reads the vehicle's time less the least delay (1 ms), at most a few ms
        // behind or ahead: never the growing lead of a clock assumed to run at the wall's rate.
        let wall = 12.5;
        let truth = 1000.0 + rate * wall;
        let now = clock.now(wall).unwrap();
        assert!(
            (now - truth).abs() < 0.006,
            "rate {rate}, jitter {jitter}: {now} vs {truth}"
        );
    }
}

#[test]
fn a_clock_assumed_at_the_walls_rate_would_lead_by_the_rate_error() {
    // The failure this clock fixes: at 1.5 % slow, 10 s of flight put a wall-rate clock
    // 150 ms ahead. Here the lead stays under 5 ms the whole time, after the first second.
    let mut clock = VehicleClock::default();
    let mut worst: f64 = 0.0;
    for (v, w) in stream(0.985, 0.0, 0.002, 12.0, 3) {
        clock.observe(v, w);
        if w > 1.5 {
            let lead = clock.now(w).unwrap() - 0.985 * w;
            worst = worst.max(lead.abs());
        }
    }
    assert!(worst < 0.005, "lead {worst} s");
}

#[test]
fn a_jump_of_the_vehicles_clock_is_taken_and_the_time_scale_stays_continuous() {
    for jump in [30.0, -30.0, 2.0, -0.8] {
        let mut clock = VehicleClock::default();
        let mut jumped = None;
        let mut last_local = f64::NEG_INFINITY;
        for (i, (v, w)) in stream(1.0, 100.0, 0.001, 6.0, 1).into_iter().enumerate() {
            let v = if w > 3.0 { v + jump } else { v };
            match clock.observe(v, w) {
                Verdict::Jumped { by } => {
                    assert!(jumped.is_none(), "one jump");
                    jumped = Some((i, by, w));
                }
                Verdict::Inconsistent => assert!(w > 3.0 && jumped.is_none(), "at {w}"),
                Verdict::Consistent => {
                    let local = clock.local(v);
                    assert!(
                        local > last_local - 0.005,
                        "continuous: {local} after {last_local}"
                    );
                    last_local = local;
                }
            }
        }
        let (_, by, w) = jumped.expect("the jump taken");
        assert!((by - jump).abs() < 0.01, "{by} vs {jump}");
        // Taken within 60 ms of the first state on the new clock (under the odometry
        // timeout).
        assert!(w - 3.0 < 0.06, "taken at {w}");
        assert_eq!(clock.jumps(), 1);
        let now = clock.now(6.1).unwrap();
        assert!((now - (100.0 + 6.1)).abs() < 0.01, "{now}");
    }
}

#[test]
fn states_from_another_clock_interleaved_with_the_vehicles_never_move_it() {
    // A sender 1000 s ahead, five times as fast as the vehicle's 100 Hz: never five in a row
    // over 50 ms without a genuine state between.
    let mut clock = VehicleClock::default();
    let genuine = stream(1.0, 50.0, 0.001, 5.0, 2);
    let mut rogue = 0;
    for (v, w) in &genuine {
        assert_eq!(clock.observe(*v, *w), Verdict::Consistent);
        for k in 1..=5 {
            let wr = w + 0.0019 * f64::from(k);
            assert_eq!(clock.observe(1050.0 + wr, wr), Verdict::Inconsistent);
            rogue += 1;
        }
    }
    assert_eq!(clock.jumps(), 0);
    assert_eq!(clock.inconsistent(), rogue);
    assert!((clock.now(5.0).unwrap() - 55.0).abs() < 0.005);
}

#[test]
fn the_round_trip_bound_is_the_longest_recent_answer() {
    let mut rt = RoundTrip::default();
    assert_eq!(rt.bound(), None);
    let mut rng = StdRng::seed_from_u64(9);
    for i in 0..40 {
        let sent = f64::from(i) * 0.5;
        let rtt = 0.001 + 0.01 * rng.random::<f64>();
        rt.on_answer(sent, sent + rtt);
    }
    rt.on_answer(30.0, 29.0); // from the future: ignored
    rt.on_answer(30.0, 35.0); // older than 2 s: ignored
    assert_eq!(rt.count(), 40);
    let (lo, hi) = (rt.min().unwrap(), rt.bound().unwrap());
    assert!(
        (0.001..=0.011).contains(&lo) && lo <= hi && hi <= 0.011,
        "{lo} {hi}"
    );
}
