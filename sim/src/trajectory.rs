//! The world: tanker, drogue and receiver in local NED, one step per frame.
//!
//! Positions relative to the tanker are in "tanker axes" (forward, right,
//! down of its heading; the tanker flies straight and level).
//!
//! Drogue centre = trail offset + sway (Dryden, [`crate::turbulence`]) + bow
//! wave + hose whip; once coupled, it rides on the probe tip.
//!
//! Bow wave model: the receiver's forebody pushes air outward from its
//! axis (the line through the receiver's body origin along the flight path).
//! Let `s` be how far the undisturbed drogue is ahead of the probe tip
//! (along track, clamped at >= 0), `l` the drogue's and `l_tip` the probe
//! tip's sideways offsets (right, down) from the forebody axis. The drogue is
//! pushed along `l / |l|` (away from the forebody axis) by
//! `max_push_m * exp(-s / decay_m) * exp(-|l - l_tip|^2 / width_m^2)`:
//! strongest when the drogue is right at the probe tip, decaying ahead of it
//! and sideways. Quasi-static: computed from the undisturbed drogue, no lag.
//!
//! Hose whip: when the probe tip crosses the drogue plane farther than
//! `capture_radius_m` from the centre (a missed contact), the drogue gets
//! `amplitude_m * exp(-tau / damping_s) * sin(2 pi f tau)` along the miss
//! direction, and the receiver backs off at 1 m/s to 3 m behind.

use crate::geometry::{M3, V3, euler_zyx};
use crate::scenario::{BowWaveSpec, Scenario};
use crate::turbulence::{SCALE_LENGTH_M, SwayAxis, sigma_mps};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Everything about the world at one instant.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldState {
    /// Time, seconds from the run's start.
    pub t: f64,
    /// Tanker position, NED, metres.
    pub tanker_ned: V3,
    /// Tanker attitude, tanker axes → NED.
    pub r_ned_tanker: M3,
    /// Inner circle centre, NED.
    pub drogue_ned: V3,
    /// Drogue axis pointing aft (downstream, toward the receiver), NED.
    pub drogue_aft_ned: V3,
    /// Drogue velocity, NED, metres per second.
    pub drogue_velocity_ned: V3,
    /// Where the hose leaves the tanker, NED, metres.
    pub hose_exit_ned: V3,
    /// Receiver body origin, NED, metres.
    pub receiver_ned: V3,
    /// Receiver attitude, body FRD → NED.
    pub r_ned_body: M3,
    /// Receiver velocity, NED, metres per second.
    pub receiver_velocity_ned: V3,
    /// Sideways displacements of the drogue (right, down), metres.
    pub sway_m: [f64; 2],
    /// The bow wave's push on the drogue (right, down), metres.
    pub bow_push_m: [f64; 2],
    /// The hose whip's displacement of the drogue (right, down), metres.
    pub whip_m: [f64; 2],
    /// The probe is in the drogue (contact made).
    pub coupled: bool,
    /// A contact has been missed (the hose whips, the receiver backs off).
    pub missed: bool,
}

/// Deterministic world driver.
pub struct World {
    sc: Scenario,
    rng: ChaCha8Rng,
    lateral: SwayAxis,
    vertical: SwayAxis,
    dt: f64,
    step: u64,
    track: [f64; 2],
    coupled: bool,
    miss: Option<(f64, [f64; 2], f64)>,
    prev_sep: Option<f64>,
    prev: Option<(V3, V3)>,
    supplied: Option<(V3, M3)>,
}

/// The tip counts as at the drogue plane within this (the coupling's depth).
const CONTACT_DEPTH_M: f64 = 0.01;

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// The bow wave's sideways push (right, down) on a drogue at `drogue_t`,
/// probe tip at `tip_t`, receiver body origin at `body_t` (tanker axes).
pub fn bow_push(spec: &BowWaveSpec, drogue_t: &V3, tip_t: &V3, body_t: &V3) -> [f64; 2] {
    let s = (drogue_t.x - tip_t.x).max(0.0);
    let l = [drogue_t.y - body_t.y, drogue_t.z - body_t.z];
    let dl = [drogue_t.y - tip_t.y, drogue_t.z - tip_t.z];
    let mag = spec.max_push_m
        * (-s / spec.decay_m).exp()
        * (-(dl[0] * dl[0] + dl[1] * dl[1]) / spec.width_m.powi(2)).exp();
    let n = (l[0] * l[0] + l[1] * l[1]).sqrt();
    if n < 1e-9 {
        return [0.0, -mag];
    }
    [mag * l[0] / n, mag * l[1] / n]
}

impl World {
    /// The world at t = 0 of the scenario, its random processes seeded from it.
    pub fn new(sc: &Scenario) -> World {
        let mut rng = ChaCha8Rng::seed_from_u64(sc.seed);
        let dt = 1.0 / sc.fps;
        let sigma = sigma_mps(sc.turbulence.intensity, sc.tanker.altitude_m);
        let v = sc.tanker.airspeed_mps;
        let tb = &sc.turbulence;
        let lateral = SwayAxis::new(
            sigma,
            SCALE_LENGTH_M,
            v,
            tb.hose_lever_m,
            tb.sway_lag_s,
            dt,
            &mut rng,
        );
        let vertical = SwayAxis::new(
            sigma,
            SCALE_LENGTH_M,
            v,
            tb.hose_lever_m,
            tb.sway_lag_s,
            dt,
            &mut rng,
        );
        World {
            sc: sc.clone(),
            rng,
            lateral,
            vertical,
            dt,
            step: 0,
            track: [0.0; 2],
            coupled: false,
            miss: None,
            prev_sep: None,
            prev: None,
            supplied: None,
        }
    }

    /// From now on the receiver is at this pose instead of its script.
    pub fn set_receiver_pose(&mut self, position_ned_m: V3, r_ned_body: M3) {
        self.supplied = Some((position_ned_m, r_ned_body));
    }

    fn tanker(&self, t: f64) -> (V3, M3) {
        let psi = self.sc.tanker.heading_deg.to_radians();
        let r = euler_zyx(0.0, 0.0, psi);
        let pos = V3::new(0.0, 0.0, -self.sc.tanker.altitude_m)
            + r * V3::new(self.sc.tanker.airspeed_mps * t, 0.0, 0.0);
        (pos, r)
    }

    /// The scripted receiver attitude relative to NED.
    fn scripted_attitude(&self, t: f64, r_ned_tanker: &M3) -> M3 {
        let rc = &self.sc.receiver;
        let w = 2.0 * std::f64::consts::PI * rc.wobble_hz * t;
        let a = rc.wobble_deg;
        let phase = (self.sc.seed % 97) as f64 * 0.37;
        r_ned_tanker
            * euler_zyx(
                (rc.roll_deg + a * (w + phase).sin()).to_radians(),
                (rc.pitch_deg + 0.7 * a * (1.3 * w + 2.0 * phase).sin()).to_radians(),
                (rc.yaw_deg + 0.5 * a * (0.8 * w + 3.0 * phase).cos()).to_radians(),
            )
    }

    /// Advances to the next frame and returns the world at its capture time.
    pub fn advance(&mut self) -> WorldState {
        if self.step > 0 {
            self.lateral.step(&mut self.rng);
            self.vertical.step(&mut self.rng);
        }
        let t = self.step as f64 * self.dt;
        self.step += 1;
        let sc = self.sc.clone();
        let (tanker_ned, r_nt) = self.tanker(t);
        let to_ned = |off: V3| tanker_ned + r_nt * off;
        let trail = V3::from(sc.drogue.trail_offset_m);
        let sway = [
            self.lateral.displacement_m(),
            self.vertical.displacement_m(),
        ];
        let whip = match self.miss {
            Some((t0, dir, _)) if sc.whip.enabled => {
                let tau = t - t0;
                let m = sc.whip.amplitude_m
                    * (-tau / sc.whip.damping_s).exp()
                    * (2.0 * std::f64::consts::PI * sc.whip.frequency_hz * tau).sin();
                [m * dir[0], m * dir[1]]
            }
            _ => [0.0; 2],
        };
        let undisturbed = trail + V3::new(0.0, sway[0] + whip[0], sway[1] + whip[1]);

        // Receiver: scripted or supplied; probe tip in tanker axes.
        let tip_body = V3::from(sc.mount.probe_tip_body_m);
        let (receiver_ned, r_ned_body) = match self.supplied {
            Some((p, r)) => (p, r),
            None => {
                let rc = &sc.receiver;
                let span = rc.approach_end_s - rc.approach_start_s;
                let f = if span > 0.0 {
                    smoothstep((t - rc.approach_start_s) / span)
                } else {
                    1.0
                };
                let start = V3::from(rc.start_offset_m);
                let end = V3::from(rc.end_offset_m);
                let mut off = start + (end - start) * f;
                if let Some((t0, _, s0)) = self.miss {
                    off.x = (s0 - (t - t0)).max(-3.0).min(off.x);
                }
                let tip_t = trail + off + V3::new(0.0, self.track[0], self.track[1]);
                let r = self.scripted_attitude(t, &r_nt);
                let tip_ned = to_ned(tip_t);
                (tip_ned - r * tip_body, r)
            }
        };
        let tip_ned = receiver_ned + r_ned_body * tip_body;
        let tip_t = r_nt.transpose() * (tip_ned - tanker_ned);

        // Bow wave.
        let body_t = r_nt.transpose() * (receiver_ned - tanker_ned);
        let bow = if sc.bow_wave.enabled && !self.coupled {
            bow_push(&sc.bow_wave, &undisturbed, &tip_t, &body_t)
        } else {
            [0.0; 2]
        };
        let mut drogue_t = undisturbed + V3::new(0.0, bow[0], bow[1]);

        // Contact or miss when the tip crosses the drogue plane.
        let sep = drogue_t.x - tip_t.x;
        if let Some(prev) = self.prev_sep
            && !self.coupled
            && prev > CONTACT_DEPTH_M
            && sep <= CONTACT_DEPTH_M
        {
            let l = [drogue_t.y - tip_t.y, drogue_t.z - tip_t.z];
            let dist = (l[0] * l[0] + l[1] * l[1]).sqrt();
            if dist <= sc.whip.capture_radius_m {
                self.coupled = true;
            } else if self.miss.is_none() {
                self.miss = Some((t, [l[0] / dist, l[1] / dist], tip_t.x - trail.x));
            }
        }
        self.prev_sep = Some(sep);
        if self.coupled {
            drogue_t = tip_t;
        }

        // The pilot follows the drogue's sideways motion with a lag.
        let disp = [drogue_t.y - trail.y, drogue_t.z - trail.z];
        let lag = sc.receiver.tracking_lag_s;
        if lag > 0.0 {
            let k = 1.0 - (-self.dt / lag).exp();
            self.track[0] += k * (disp[0] - self.track[0]);
            self.track[1] += k * (disp[1] - self.track[1]);
        }

        let drogue_ned = to_ned(drogue_t);
        let (drogue_velocity_ned, receiver_velocity_ned) = match self.prev {
            Some((pd, pr)) => ((drogue_ned - pd) / self.dt, (receiver_ned - pr) / self.dt),
            None => {
                let v = r_nt * V3::new(sc.tanker.airspeed_mps, 0.0, 0.0);
                (v, v)
            }
        };
        self.prev = Some((drogue_ned, receiver_ned));
        // The drogue trails in the relative wind (gusts minus its own motion).
        let rel_vel_t =
            r_nt.transpose() * drogue_velocity_ned - V3::new(sc.tanker.airspeed_mps, 0.0, 0.0);
        let air_t = V3::new(
            -sc.tanker.airspeed_mps,
            self.lateral.gust_mps(),
            self.vertical.gust_mps(),
        ) - V3::new(0.0, rel_vel_t.y, rel_vel_t.z);
        WorldState {
            t,
            tanker_ned,
            r_ned_tanker: r_nt,
            drogue_ned,
            drogue_aft_ned: r_nt * air_t.normalize(),
            drogue_velocity_ned,
            hose_exit_ned: to_ned(V3::from(sc.drogue.hose_exit_m)),
            receiver_ned,
            r_ned_body,
            receiver_velocity_ned,
            sway_m: sway,
            bow_push_m: bow,
            whip_m: whip,
            coupled: self.coupled,
            missed: self.miss.is_some(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::turbulence::Intensity;

    fn calm(name: &str) -> Scenario {
        let mut s = Scenario::builtin(name).unwrap();
        s.turbulence.intensity = Intensity::None;
        s.receiver.wobble_deg = 0.0;
        s
    }

    #[test]
    fn bow_wave_pushes_the_drogue_away_as_specified() {
        let mut s = calm("approach");
        s.receiver.tracking_lag_s = 0.0;
        s.receiver.start_offset_m = [-12.0, 0.3, 0.2];
        s.receiver.end_offset_m = [-0.05, 0.3, 0.2];
        let mut w = World::new(&s);
        let trail = V3::from(s.drogue.trail_offset_m);
        let mut last_mag = -1.0;
        let mut checked = 0;
        for _ in 0..s.frame_count() {
            let st = w.advance();
            let tip_ned = st.receiver_ned + st.r_ned_body * V3::from(s.mount.probe_tip_body_m);
            let tip_t = st.r_ned_tanker.transpose() * (tip_ned - st.tanker_ned);
            let dro_t = st.r_ned_tanker.transpose() * (st.drogue_ned - st.tanker_ned);
            // Spec, evaluated independently: undisturbed drogue = trail here.
            let body_t = st.r_ned_tanker.transpose() * (st.receiver_ned - st.tanker_ned);
            let sep = (trail.x - tip_t.x).max(0.0);
            let dl = [trail.y - tip_t.y, trail.z - tip_t.z];
            let l = [trail.y - body_t.y, trail.z - body_t.z];
            let mag = 0.25 * (-sep / 1.5).exp() * (-(dl[0] * dl[0] + dl[1] * dl[1]) / 0.64).exp();
            let n = (l[0] * l[0] + l[1] * l[1]).sqrt();
            let expect = [mag * l[0] / n, mag * l[1] / n];
            assert!((dro_t.y - trail.y - expect[0]).abs() < 1e-9);
            assert!((dro_t.z - trail.z - expect[1]).abs() < 1e-9);
            // Away from the forebody axis, growing as the nose nears.
            let push = [dro_t.y - trail.y, dro_t.z - trail.z];
            assert!(push[0] * l[0] + push[1] * l[1] >= 0.0);
            let m = (push[0].powi(2) + push[1].powi(2)).sqrt();
            assert!(m >= last_mag - 1e-12, "push shrank: {m} < {last_mag}");
            last_mag = m;
            checked += 1;
        }
        assert!(checked > 500 && last_mag > 0.1, "{last_mag}");
    }

    #[test]
    fn approach_reaches_contact_in_calm_air() {
        let s = calm("approach");
        let mut w = World::new(&s);
        let states: Vec<_> = (0..s.frame_count()).map(|_| w.advance()).collect();
        let first = &states[0];
        let d0 = (first.drogue_ned - first.receiver_ned).norm();
        assert!(d0 > 12.0 && d0 < 20.0, "{d0}");
        assert!(states.last().unwrap().coupled, "no contact");
        assert!(!states.iter().any(|s| s.missed));
    }

    #[test]
    fn same_seed_same_world() {
        let s = Scenario::builtin("severe_turbulence").unwrap();
        let (mut a, mut b) = (World::new(&s), World::new(&s));
        for _ in 0..200 {
            assert_eq!(a.advance(), b.advance());
        }
        let mut s2 = s.clone();
        s2.seed += 1;
        let mut c = World::new(&s2);
        let mut a = World::new(&s);
        let differs = (0..50).any(|_| a.advance().drogue_ned != c.advance().drogue_ned);
        assert!(differs);
    }
}
