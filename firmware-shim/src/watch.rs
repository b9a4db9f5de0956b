//! The flight watch: from PX4's state and the mission's reference, whether the vehicle is on
//! the ground and whether it is still flying its mission.
//!
//! * **Ground.** PX4's height estimate can be decimetres off at touchdown (EKF2 on GNSS:
//!   up to 0.8 m on SIH), so a height threshold alone cannot tell when the vehicle is down.
//!   In the mission's landing the vehicle is down when PX4's land detector says so
//!   (EXTENDED_SYS_STATE `ON_GROUND`) or when the descent has stalled: over
//!   [`WatchConfig::stall_time`] the reference descended but the estimate's height fell by
//!   less than 30 % of that, below [`WatchConfig::stall_height`]; or, at the latest, when
//!   the reference is [`LAND_OVERRUN_M`] below the start point. Elsewhere, the estimate's
//!   height and speed near zero (the take-off).
//! * **Off the mission.** The vehicle has left its mission when, outside the landing, it is
//!   far below the reference ([`WatchConfig::below`], more around the flip), far from it
//!   ([`WatchConfig::off_course`]), upside down outside the flip ([`WatchConfig::inverted`]),
//!   each for a while, or on the ground (PX4's land detector, or the estimate's height under
//!   [`WatchConfig::ground_contact`]) after take-off. The controller
//!   then stops the mission: a vehicle that did not fly its mission never passes.

use std::collections::VecDeque;

use mpc_mission::mission::{Phase, RefPoint};
use nalgebra::Vector3;

use crate::link::Deviation;
use crate::pilot::{GROUND_HEIGHT_M, GROUND_SPEED_M_S, State};

/// The landing's reference this far below the start point: down \[m\] (EKF2's height was
/// up to 0.8 m off at touchdown; its correction on the ground can look like a descent).
pub const LAND_OVERRUN_M: f64 = 1.0;
/// A stalled descent must stay stalled this long \[s\].
pub const STALL_CONFIRM_S: f64 = 0.1;

/// Thresholds of the [`Watch`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WatchConfig {
    /// Below the reference by more than this for [`WatchConfig::below_time`]: off the
    /// mission \[m\].
    pub below: f64,
    /// The same around the flip (ascent, flip, recovery) \[m\].
    pub below_flip: f64,
    /// See [`WatchConfig::below`] \[s\].
    pub below_time: f64,
    /// Farther than this from the reference for [`WatchConfig::off_course_time`] \[m\].
    pub off_course: f64,
    /// See [`WatchConfig::off_course`] \[s\].
    pub off_course_time: f64,
    /// Tilted more than this outside the flip for [`WatchConfig::inverted_time`] \[rad\].
    pub inverted: f64,
    /// See [`WatchConfig::inverted`] \[s\].
    pub inverted_time: f64,
    /// The landing's descent is judged over this long \[s\].
    pub stall_time: f64,
    /// Only below this height above the start point \[m\] (the estimate's error included).
    pub stall_height: f64,
    /// After take-off and before the landing, the estimate's height over the start point
    /// under this: the vehicle has hit the ground \[m\] (no mission flies this low there).
    pub ground_contact: f64,
}

impl Default for WatchConfig {
    /// 1.5 m below for 0.5 s (2.5 m around the flip), 3 m off for 1 s, tilted over 100 deg
    /// for 0.25 s, a landing's descent judged over 0.5 s below 1.5 m, ground contact under
    /// 0.3 m.
    fn default() -> Self {
        Self {
            below: 1.5,
            below_flip: 2.5,
            below_time: 0.5,
            off_course: 3.0,
            off_course_time: 1.0,
            inverted: 100f64.to_radians(),
            inverted_time: 0.25,
            stall_time: 0.5,
            stall_height: 1.5,
            ground_contact: 0.3,
        }
    }
}

/// What the watch saw in one state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Seen {
    /// The vehicle is on the ground (the mission's input).
    pub on_ground: bool,
    /// The vehicle has left its mission.
    pub deviation: Option<Deviation>,
}

/// A condition that must hold for a while: since when it holds.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Since(Option<f64>);

impl Since {
    /// Whether `now` has held for `long` (from the first `t` it held, in a row).
    fn held(&mut self, now: bool, t: f64, long: f64) -> bool {
        if !now {
            self.0 = None;
            return false;
        }
        t - *self.0.get_or_insert(t) >= long
    }
}

/// The flight watch. See the [module documentation](self).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Watch {
    cfg: WatchConfig,
    airborne: bool,
    below: Since,
    off: Since,
    inverted: Since,
    stall: Since,
    heights: VecDeque<(f64, f64)>,
}

impl Watch {
    /// A watch with these thresholds.
    pub fn new(cfg: WatchConfig) -> Self {
        Self {
            cfg,
            ..Self::default()
        }
    }

    /// The state `s` at mission time `t` \[s\], in `phase`, against the reference `r`; the
    /// height is over the start point; `px4_on_ground`: PX4's land detector says landed.
    pub fn observe(
        &mut self,
        t: f64,
        phase: Phase,
        s: &State,
        r: &RefPoint,
        height: f64,
        px4_on_ground: bool,
    ) -> Seen {
        self.airborne |= height > 0.3;
        let on_ground = match phase {
            Phase::Land => {
                let stalled = self.stalled(t, r, height);
                // The reference's height over the start point: far below it, the vehicle
                // is down whatever the estimate says (it may drift down on the ground).
                let overrun = r.p.z - s.p.z + height < -LAND_OVERRUN_M;
                px4_on_ground || overrun || self.stall.held(stalled, t, STALL_CONFIRM_S)
            }
            Phase::Landed => true,
            _ => height < GROUND_HEIGHT_M && s.v.norm() < GROUND_SPEED_M_S,
        };
        let deviation = if matches!(phase, Phase::Land | Phase::Landed) {
            None
        } else {
            self.deviation(
                t,
                phase,
                s,
                r,
                px4_on_ground || self.hit_ground(phase, height),
            )
        };
        Seen {
            on_ground,
            deviation,
        }
    }

    /// Down on the ground between take-off and landing by the estimate's height: PX4's land
    /// detector takes seconds to say so, and a vehicle that hit the ground in a maneuver
    /// (in a flip starved of CPU: 4 m/s by the truth) may bounce and fly on.
    fn hit_ground(&self, phase: Phase, height: f64) -> bool {
        self.airborne && phase != Phase::Takeoff && height < self.cfg.ground_contact
    }

    /// The landing's reference descends, the vehicle does not, low enough: over the last
    /// [`WatchConfig::stall_time`] the estimate's height fell by less than 30 % of the
    /// reference's descent. Judged on the height, not on the estimate's vertical speed:
    /// EKF2's was seen reading 0.27 m/s down for seconds on the ground.
    fn stalled(&mut self, t: f64, r: &RefPoint, height: f64) -> bool {
        let window = self.cfg.stall_time;
        self.heights.push_back((t, height));
        while self.heights.get(1).is_some_and(|(t1, _)| t - t1 >= window) {
            self.heights.pop_front();
        }
        let Some(&(t0, h0)) = self.heights.front() else {
            return false;
        };
        let span = t - t0;
        let expected = -r.v.z * span;
        span >= window
            && r.v.z < -0.1
            && h0 - height < 0.3 * expected
            && height < self.cfg.stall_height
    }

    fn deviation(
        &mut self,
        t: f64,
        phase: Phase,
        s: &State,
        r: &RefPoint,
        px4_on_ground: bool,
    ) -> Option<Deviation> {
        let c = self.cfg;
        let flip = matches!(phase, Phase::Ascend | Phase::Flip | Phase::Recover);
        let below = r.p.z - s.p.z > if flip { c.below_flip } else { c.below };
        let tilt = (s.q * Vector3::z()).z.clamp(-1.0, 1.0).acos();
        if self.below.held(below, t, c.below_time) {
            Some(Deviation::BelowReference)
        } else if self
            .off
            .held((s.p - r.p).norm() > c.off_course, t, c.off_course_time)
        {
            Some(Deviation::OffCourse)
        } else if self
            .inverted
            .held(!flip && tilt > c.inverted, t, c.inverted_time)
        {
            Some(Deviation::Inverted)
        } else if self.airborne && px4_on_ground && phase != Phase::Takeoff {
            Some(Deviation::OnGround)
        } else {
            None
        }
    }
}
