//! The vehicle's clock as the companion sees it, from the states' timestamps and their
//! arrival times, and the link's round trip from MAVLink TIMESYNC.
//!
//! PX4 stamps its states with its own clock, which need not run at the wall clock's rate: SIH
//! in lockstep ran 1.0-1.5 % slower than the wall clock, and a speed factor scales it by
//! design. [`VehicleClock`] models the vehicle's time as a line of the wall clock,
//! `vehicle = v0 + rate * (wall - w0)`:
//!
//! * the **rate** is the least-squares slope of the least delayed state of each
//!   [`ClockConfig::window`] over the last [`ClockConfig::windows`] windows (10 s), so a
//!   clock a few percent off the wall clock is followed within a second or two;
//! * the **offset** is that of the least delayed state (a state never arrives before it was
//!   stamped: one that arrives earlier than the line says raises it at once), forgotten at
//!   [`ClockConfig::forget`] so that the rate's residual error and a change of the link's
//!   base latency are followed;
//! * a state more than [`ClockConfig::jump`] off the line is **inconsistent** and not used;
//!   a run of inconsistent states that agree with each other, with no consistent state
//!   among them, for [`ClockConfig::jump_confirm`] is a **jump** of the vehicle's clock (a
//!   reboot, a restarted simulation). The clock then shifts its time scale by the jump, so
//!   the times it gives ([`VehicleClock::local`], [`VehicleClock::now`]) stay continuous
//!   across it: a mission scheduled on them does not notice.
//!
//! [`RoundTrip`] keeps the link's round-trip times measured with TIMESYNC (PX4 answers a
//! request with `tc1 = 0` with its own time): a bound on how late a state can be, and so on
//! how far ahead the controller may predict.

use std::collections::VecDeque;

/// Settings of [`VehicleClock`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClockConfig {
    /// Length of the windows whose least delayed states fit the rate \[s\].
    pub window: f64,
    /// Number of windows the rate is fitted on.
    pub windows: usize,
    /// How fast the offset forgets its least delay \[s per s\].
    pub forget: f64,
    /// A state this far off the clock (either way) is inconsistent \[s\].
    pub jump: f64,
    /// Inconsistent states that agree with each other for this long, with no consistent
    /// state among them, are a jump of the vehicle's clock \[s\].
    pub jump_confirm: f64,
    /// Inconsistent states that agree within this much are one run \[s\].
    pub jump_tolerance: f64,
    /// The slowest and the fastest vehicle clock, relative to the wall clock.
    pub rate_range: (f64, f64),
}

impl Default for ClockConfig {
    /// Windows of 0.25 s, 40 of them (10 s); forgetting 1 ms/s; jumps of more than 0.5 s,
    /// confirmed by 50 ms of states 20 ms apart at most; rates 0.5 to 2.
    fn default() -> Self {
        Self {
            window: 0.25,
            windows: 40,
            forget: 1e-3,
            jump: 0.5,
            jump_confirm: 0.05,
            jump_tolerance: 0.02,
            rate_range: (0.5, 2.0),
        }
    }
}

/// What the clock made of a state's timestamp.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// On the clock: use the state.
    Consistent,
    /// Too far off the clock, and not (yet) a jump: drop the state.
    Inconsistent,
    /// The vehicle's clock jumped by this much \[s\]; the state is on the new clock.
    Jumped {
        /// The jump \[s\] (positive: the vehicle's clock went forward).
        by: f64,
    },
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Line {
    wall: f64,
    vehicle: f64,
    rate: f64,
}

impl Line {
    fn at(&self, wall: f64) -> f64 {
        self.vehicle + self.rate * (wall - self.wall)
    }
}

/// The least delayed state of a window: its wall time and (continuous) vehicle time.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Window {
    start: f64,
    wall: f64,
    vehicle: f64,
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Run {
    first_wall: f64,
    last_wall: f64,
    key: f64,
    count: u32,
}

/// The vehicle's clock. See the [module documentation](self).
#[derive(Clone, Debug, PartialEq)]
pub struct VehicleClock {
    cfg: ClockConfig,
    line: Option<Line>,
    set_at: f64,
    points: VecDeque<(f64, f64)>,
    window: Option<Window>,
    run: Option<Run>,
    shift: f64,
    last: f64,
    jumps: u32,
    inconsistent: u64,
}

impl Default for VehicleClock {
    fn default() -> Self {
        Self::new(ClockConfig::default())
    }
}

impl VehicleClock {
    /// A clock that has seen no state yet.
    pub fn new(cfg: ClockConfig) -> Self {
        Self {
            cfg,
            line: None,
            set_at: 0.0,
            points: VecDeque::new(),
            window: None,
            run: None,
            shift: 0.0,
            last: f64::NEG_INFINITY,
            jumps: 0,
            inconsistent: 0,
        }
    }

    /// Whether a state has set the clock.
    pub fn started(&self) -> bool {
        self.line.is_some()
    }

    /// The vehicle's clock rate over the wall clock's, as estimated (1 before the fit).
    pub fn rate(&self) -> f64 {
        self.line.map_or(1.0, |l| l.rate)
    }

    /// Jumps of the vehicle's clock so far.
    pub fn jumps(&self) -> u32 {
        self.jumps
    }

    /// States found inconsistent with the clock so far.
    pub fn inconsistent(&self) -> u64 {
        self.inconsistent
    }

    /// A vehicle timestamp \[s\] on the clock's continuous time scale (the vehicle's own, less
    /// the jumps seen).
    pub fn local(&self, vehicle: f64) -> f64 {
        vehicle - self.shift
    }

    /// The vehicle's time now \[s\] (continuous time scale), at wall time `wall`; never goes
    /// backwards. `None` before the first state.
    pub fn now(&mut self, wall: f64) -> Option<f64> {
        let t = self.line?.at(wall);
        self.last = self.last.max(t);
        Some(self.last)
    }

    /// The latest time [`VehicleClock::now`] gave.
    pub fn last(&self) -> Option<f64> {
        self.line.map(|_| self.last)
    }

    /// A state stamped `vehicle` \[s, the vehicle's clock\] arrived at wall time `wall` \[s\].
    pub fn observe(&mut self, vehicle: f64, wall: f64) -> Verdict {
        let Some(line) = self.line else {
            self.line = Some(Line {
                wall,
                vehicle,
                rate: 1.0,
            });
            self.set_at = wall;
            return Verdict::Consistent;
        };
        let v = self.local(vehicle);
        let e = v - line.at(wall);
        if e.abs() > self.cfg.jump {
            return self.inconsistent_state(vehicle, wall, e);
        }
        self.run = None;
        self.follow(v, wall, line);
        self.keep_point(v, wall);
        Verdict::Consistent
    }

    /// The line through the least delayed state, forgetting at `forget`.
    fn follow(&mut self, v: f64, wall: f64, line: Line) {
        let forgotten = line.at(wall) - self.cfg.forget * (wall - self.set_at).max(0.0);
        self.line = Some(Line {
            wall,
            vehicle: v.max(forgotten),
            rate: line.rate,
        });
        self.set_at = wall;
    }

    /// Keeps the least delayed state of each window; at a window's end, fits the rate.
    fn keep_point(&mut self, v: f64, wall: f64) {
        let rate = self.rate();
        let w = self.window.get_or_insert(Window {
            start: wall,
            wall,
            vehicle: v,
        });
        if v - rate * wall > w.vehicle - rate * w.wall {
            w.wall = wall;
            w.vehicle = v;
        }
        if wall - w.start < self.cfg.window {
            return;
        }
        self.points.push_back((w.wall, w.vehicle));
        self.window = None;
        while self.points.len() > self.cfg.windows {
            self.points.pop_front();
        }
        self.fit_rate(wall);
    }

    /// The least-squares slope of the windows' points, from four points over a second on,
    /// through the least delayed of them.
    fn fit_rate(&mut self, wall: f64) {
        let (Some(first), Some(last), Some(line)) =
            (self.points.front(), self.points.back(), self.line)
        else {
            return;
        };
        if self.points.len() < 4 || last.0 - first.0 < 1.0 {
            return;
        }
        let n = self.points.len() as f64;
        let (mw, mv) = self
            .points
            .iter()
            .fold((0.0, 0.0), |(a, b), (w, v)| (a + w / n, b + v / n));
        let (sxy, sxx) = self.points.iter().fold((0.0, 0.0), |(a, b), (w, v)| {
            (a + (w - mw) * (v - mv), b + (w - mw) * (w - mw))
        });
        if sxx <= 0.0 {
            return;
        }
        let (lo, hi) = self.cfg.rate_range;
        let rate = (sxy / sxx).clamp(lo, hi);
        // Through the least delayed of the windows' states on the new slope: the lead or lag
        // the old slope ran up is dropped with it.
        let through = self
            .points
            .iter()
            .map(|(w, v)| v + rate * (wall - w))
            .fold(f64::NEG_INFINITY, f64::max);
        let vehicle = if through.is_finite() {
            through
        } else {
            line.at(wall)
        };
        self.line = Some(Line {
            wall,
            vehicle,
            rate,
        });
        self.set_at = wall;
    }

    /// A state `e` \[s\] off the clock: dropped, unless it completes a run of states that
    /// agree with each other: then the clock jumps to them.
    fn inconsistent_state(&mut self, vehicle: f64, wall: f64, e: f64) -> Verdict {
        self.inconsistent += 1;
        let key = vehicle - self.rate() * wall;
        let run = match self.run {
            Some(r) if (key - r.key).abs() <= self.cfg.jump_tolerance => Run {
                last_wall: wall,
                count: r.count + 1,
                ..r
            },
            _ => Run {
                first_wall: wall,
                last_wall: wall,
                key,
                count: 1,
            },
        };
        self.run = Some(run);
        if run.count < 5 || run.last_wall - run.first_wall < self.cfg.jump_confirm {
            return Verdict::Inconsistent;
        }
        self.run = None;
        self.shift += e;
        self.jumps += 1;
        // The new clock's rate is the old one's; its windows start afresh.
        self.points.clear();
        self.window = None;
        if let Some(line) = self.line {
            self.follow(self.local(vehicle), wall, line);
        }
        Verdict::Jumped { by: e }
    }
}

/// Round trips of the link measured with TIMESYNC.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct RoundTrip {
    rtts: VecDeque<f64>,
    count: u64,
}

/// The round trips [`RoundTrip`] keeps.
pub const ROUND_TRIPS_KEPT: usize = 16;

impl RoundTrip {
    /// A TIMESYNC answer to our request sent at wall time `sent` \[s\] arrived at `wall`;
    /// answers older than 2 s or from the future are ignored.
    pub fn on_answer(&mut self, sent: f64, wall: f64) {
        let rtt = wall - sent;
        if !(rtt.is_finite() && (0.0..2.0).contains(&rtt)) {
            return;
        }
        self.rtts.push_back(rtt);
        if self.rtts.len() > ROUND_TRIPS_KEPT {
            self.rtts.pop_front();
        }
        self.count += 1;
    }

    /// Answers received.
    pub fn count(&self) -> u64 {
        self.count
    }

    /// The longest of the last [`ROUND_TRIPS_KEPT`] round trips \[s\], if any: no state that
    /// left the vehicle with the least delay of its window can be later than this behind it.
    pub fn bound(&self) -> Option<f64> {
        self.rtts.iter().copied().reduce(f64::max)
    }

    /// The shortest of the last round trips \[s\].
    pub fn min(&self) -> Option<f64> {
        self.rtts.iter().copied().reduce(f64::min)
    }
}
