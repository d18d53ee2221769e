//! Experiment design: the excitation that identifies θ to a target accuracy in the shortest
//! drive, within the robot's limits and a given floor space (the thesis's future work, ch. 5).
//!
//! The commands are periodic multisines of period P on interleaved harmonic lines (v_ref on
//! the even lines, ω_ref on the odd ones, Schroeder phases, no offset: a zero-mean forward
//! command keeps the robot near its start):
//!
//! ```text
//! v_ref(t) = Σᵢ aᵢ sin(2π fᵢ t + φᵢ),   ω_ref(t) = Σⱼ bⱼ sin(2π gⱼ t + ψⱼ)
//! ```
//!
//! For a prior θ and white output noise σ_v, σ_ω, the Fisher information of the output-error
//! problem over one period of the steady periodic response is
//!
//! ```text
//! M_P = Σ_k Σ_c ψ_{c,k} ψ_{c,k}ᵀ / σ_c²,     ψ_{c,k} = ∂ŷ_c(t_k)/∂θ   (6 × 6)
//! ```
//!
//! (the model's own sensitivities, `DynamicModel::simulate_with_sensitivities`), and a drive
//! of T seconds — whole periods — has the information (T/P) M_P, so the predicted standard
//! errors are √(P/T [M_P⁻¹]_ii) and the shortest drive reaching a relative accuracy ε on the
//! target parameters is
//!
//! ```text
//! T = P · ⌈ max_i [M_P⁻¹]_ii / (ε θ_i)² ⌉   (periods)
//! ```
//!
//! The amplitudes minimise that drive (before rounding; [`Criterion::Duration`], the default)
//! or maximise log det(M_P / P) (D-optimal, [`Criterion::DOptimal`]: the information per
//! second on all six θ) over the lines' shares, each channel's peak |v_ref|, |ω_ref| held at its limit,
//! the commands' slopes within the acceleration limits, and the pose — integrated from the
//! model's response over the whole drive — inside the rectangle (the robot starts at its
//! centre facing +x); where the pose leaves it the forward amplitude is scaled down until it
//! stays. The search is coordinate-wise on the log shares (×1.5, ÷1.5) until no step improves,
//! every line keeping at least a tenth of its channel's largest (a design on one or two lines
//! is optimal only for the prior θ).
//!
//! **The band.** Eq. 2.19 is a first-order model of a closed velocity loop: a robot's motors,
//! wheels and contacts add dynamics it leaves out, which lines near and above the bandwidth
//! 1/(2π max(θ1, θ2)) excite and which then bias θ. The design starts on lines up to half the
//! bandwidth ([`DesignSettings::for_robot`]) and doubles the band (to at most
//! [`DesignSettings::f_max_limit_hz`]) only while no design on it keeps the robot inside the
//! space — low lines drive far.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};
use wheelid_core::{DynamicModel, Error, Recording, Result};
use wheelid_robots::Excitation;
use wheelid_robots::excitation::Signal;

/// What the design is asked for.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DesignSettings {
    /// The prior θ1…θ6 (from an earlier identification or the robot's physical map).
    pub theta: [f64; 6],
    /// White noise of the measured v \[m/s\] and ω \[rad/s\] (1σ).
    pub noise_std: [f64; 2],
    /// Sample period of the drive \[s\].
    pub dt_s: f64,
    /// Largest |v_ref| \[m/s\] and |ω_ref| \[rad/s\].
    pub command_max: [f64; 2],
    /// Largest slopes |v̇_ref| \[m/s²\] and |ω̇_ref| \[rad/s²\] (infinite: none).
    pub slope_max: [f64; 2],
    /// The floor space, a rectangle of these sides along x and y \[m\], centred on the start.
    pub space_m: [f64; 2],
    /// Where the drive starts in that space: x, y \[m\] from its centre and the heading ψ
    /// \[rad\] from its x axis (default the centre, facing +x; a re-design on the way starts
    /// where the robot is).
    #[serde(default)]
    pub start_pose: [f64; 3],
    /// The robot's (v \[m/s\], ω \[rad/s\]) as the drive starts (default at rest).
    #[serde(default)]
    pub start_velocity: [f64; 2],
    /// Target relative standard error of the target parameters (0.01: 1 %).
    pub accuracy: f64,
    /// The parameters the accuracy is asked of (0-based; default θ1, θ2, θ4, θ6).
    pub targets: Vec<usize>,
    /// Period P of the multisines \[s\] (the lowest line is 1/P).
    pub period_s: f64,
    /// Highest line \[Hz\] the design starts from.
    pub f_max_hz: f64,
    /// The highest line may be doubled up to this \[Hz\] when no design on the lower band
    /// keeps the robot inside the space (0 or below `f_max_hz`: never).
    #[serde(default)]
    pub f_max_limit_hz: f64,
    /// Lines per channel.
    pub lines: usize,
    /// What the amplitudes optimise.
    pub criterion: Criterion,
}

/// The design criterion.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    /// Maximise log det(M_P / P): the information per second on all six θ (D-optimal).
    DOptimal,
    /// Minimise the drive that reaches the accuracy on the targets, max_i P [M_P⁻¹]_ii/(ε θ_i)²
    /// (before rounding to whole periods): what the design is for; θ3, θ5 only as they help.
    Duration,
}

impl DesignSettings {
    /// Settings for a robot with prior `theta`, sample period `dt_s` and command limits
    /// `command_max`: noise 0.005 m/s and 0.01 rad/s, no slope limit, a 4 m × 4 m floor, 1 %
    /// on θ1, θ2, θ4, θ6, over a period of 10 s (longer where the band holds fewer than two
    /// harmonics of it), up to 6 lines per channel (as the harmonics
    /// below f_max allow), the shortest drive as the criterion; lines up to half the robot's
    /// bandwidth 1/(2π max(θ1, θ2)), raised (doubled, to at most twice the bandwidth and a
    /// fifth of the sample rate) only where no design on the lower band stays inside the
    /// space. Eq. 2.19 holds best well inside the bandwidth: on the rigid-body Khepera lines
    /// to 2× biased θ1 −2 % and θ6 +7 %, to 0.5× they did not; the Pioneer-like robot needs 1×
    /// to stay in 3 m × 3 m.
    pub fn for_robot(theta: [f64; 6], dt_s: f64, command_max: [f64; 2]) -> Self {
        let bandwidth = 1.0 / (2.0 * std::f64::consts::PI * theta[0].max(theta[1]));
        let f_max_limit_hz = (2.0 * bandwidth).min(0.2 / dt_s);
        let f_max_hz = (0.5 * bandwidth).min(f_max_limit_hz);
        // Two harmonics at least below the band (one line a channel): a slow robot's period
        // grows beyond 10 s.
        let period_s = (2.0 / f_max_hz).max(10.0);
        Self {
            theta,
            noise_std: [0.005, 0.01],
            dt_s,
            command_max,
            slope_max: [f64::INFINITY; 2],
            space_m: [4.0, 4.0],
            start_pose: [0.0; 3],
            start_velocity: [0.0; 2],
            accuracy: 0.01,
            targets: vec![0, 1, 3, 5],
            period_s,
            f_max_hz,
            f_max_limit_hz,
            lines: lines_below(f_max_hz, period_s),
            criterion: Criterion::Duration,
        }
    }

    fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::InvalidSetting(m));
        let positive = |x: f64| x > 0.0 && x.is_finite();
        if !self.theta.iter().all(|x| x.is_finite()) || !positive(self.theta[0]) {
            return bad(format!("prior θ {:?} is not usable", self.theta));
        }
        if !(positive(self.dt_s) && positive(self.period_s) && positive(self.f_max_hz)) {
            return bad("dt_s, period_s and f_max_hz must be positive".into());
        }
        if !self
            .noise_std
            .iter()
            .chain(&self.command_max)
            .all(|&x| positive(x))
        {
            return bad("noise_std and command_max must be positive".into());
        }
        if !(self.slope_max.iter().all(|&x| x > 0.0) && self.space_m.iter().all(|&x| x > 0.0)) {
            return bad("slope_max and space_m must be positive".into());
        }
        let [x0, y0, psi] = self.start_pose;
        if !(psi.is_finite()
            && self.start_velocity.iter().all(|x| x.is_finite())
            && x0.abs() < 0.5 * self.space_m[0]
            && y0.abs() < 0.5 * self.space_m[1])
        {
            return bad(format!(
                "start pose {:?} is not inside the {} m × {} m space",
                self.start_pose, self.space_m[0], self.space_m[1]
            ));
        }
        if !(self.accuracy > 0.0 && self.accuracy < 1.0) {
            return bad(format!("accuracy {} is not in (0, 1)", self.accuracy));
        }
        if self.targets.is_empty() || self.targets.iter().any(|&i| i >= 6) {
            return bad(format!("targets {:?} are not θ indices 0…5", self.targets));
        }
        if self.lines == 0 || 2 * self.lines > (self.f_max_hz * self.period_s) as usize {
            return bad(format!(
                "{} lines per channel need 2 × {} harmonics of 1/{} s below {} Hz",
                self.lines, self.lines, self.period_s, self.f_max_hz
            ));
        }
        Ok(())
    }
}

/// Lines per channel below `f_max_hz` on harmonics of 1/`period_s`: half the harmonics, 1 to 6.
fn lines_below(f_max_hz: f64, period_s: f64) -> usize {
    ((f_max_hz * period_s) as usize / 2).clamp(1, 6)
}

/// A designed experiment.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Design {
    /// The commands (sums of sines; drive them with `wheelid run`).
    pub excitation: Excitation,
    /// The drive's length: whole periods \[s\].
    pub duration_s: f64,
    /// Predicted standard errors of θ1…θ6 after the drive.
    pub predicted_std_err: [f64; 6],
    /// log det of the information per second, M_P / P.
    pub log_det_per_s: f64,
    /// The largest |x|, |y| the pose reaches over the drive (the model's response) \[m\].
    pub extent_m: [f64; 2],
    /// Candidate designs evaluated (over every band tried).
    pub evaluations: usize,
    /// The highest line of the band the design is on \[Hz\] (`f_max_hz`, or raised).
    pub f_max_hz: f64,
    /// The pose (x, y) \[m\] the model predicts at every sample of the drive, from the
    /// origin facing +x.
    pub path_m: Vec<[f64; 2]>,
}

/// The lines of the two channels: harmonics of 1/P, log-spaced, interleaved (v even, ω odd).
fn harmonics(s: &DesignSettings) -> [Vec<usize>; 2] {
    let top = (s.f_max_hz * s.period_s).floor() as usize;
    let n = 2 * s.lines;
    let mut all: Vec<usize> = (0..n)
        .map(|i| {
            let x = (top as f64).powf(i as f64 / (n - 1) as f64);
            x.round().max(1.0) as usize
        })
        .collect();
    // Distinct, increasing.
    for i in 1..n {
        if all[i] <= all[i - 1] {
            all[i] = all[i - 1] + 1;
        }
    }
    [
        all.iter().step_by(2).copied().collect(),
        all.iter().skip(1).step_by(2).copied().collect(),
    ]
}

/// A channel's signal from its lines' harmonics and amplitudes, Schroeder phases
/// φᵢ = −i(i + 1)π/K (a low crest factor for comparable amplitudes).
fn signal(period_s: f64, lines: &[usize], amps: &[f64]) -> Signal {
    let k = lines.len() as f64;
    Signal::Sines {
        offset: 0.0,
        lines: lines
            .iter()
            .zip(amps)
            .enumerate()
            .map(|(i, (&n, &a))| {
                let i = i as f64;
                (
                    a,
                    n as f64 / period_s,
                    -i * (i + 1.0) * std::f64::consts::PI / k,
                )
            })
            .collect(),
    }
}

/// Peak |u| and peak |u̇| of a `Signal::Sines` over one period, on a grid 8× finer than the
/// highest line's cycle (at least 2048 points).
fn peaks(sig: &Signal, period_s: f64) -> (f64, f64) {
    let Signal::Sines { lines, .. } = sig else {
        return (f64::NAN, f64::NAN);
    };
    let top = lines.iter().map(|l| l.1).fold(0.0, f64::max);
    let n = ((8.0 * top * period_s).ceil() as usize * 8).max(2048);
    let two_pi = 2.0 * std::f64::consts::PI;
    let (mut p, mut d) = (0.0f64, 0.0f64);
    for k in 0..n {
        let t = period_s * k as f64 / n as f64;
        let (mut u, mut du) = (0.0, 0.0);
        for &(a, f, ph) in lines {
            let arg = two_pi * f * t + ph;
            u += a * arg.sin();
            du += a * two_pi * f * arg.cos();
        }
        p = p.max(u.abs());
        d = d.max(du.abs());
    }
    (p, d)
}

/// The channel's amplitudes from its shares, scaled so that the peak command is at its
/// limit and the peak slope within its own (`scale` ≤ 1 scales the result further: the
/// space constraint).
fn amplitudes(
    s: &DesignSettings,
    lines: &[usize],
    shares: &[f64],
    c: usize,
    scale: f64,
) -> Vec<f64> {
    let (p, d) = peaks(&signal(s.period_s, lines, shares), s.period_s);
    let k = (s.command_max[c] / p).min(s.slope_max[c] / d) * scale;
    shares.iter().map(|a| a * k).collect()
}

/// A simulated drive: the recording of the commands, the outputs (v, ω) and ∂ŷ_c/∂θ per
/// channel.
type Response = (Recording, Vec<Vec<f64>>, Vec<DMatrix<f64>>);

/// The recording of `exc`'s commands (held) over `duration_s` at the design's sample period,
/// its outputs zero.
fn commands(s: &DesignSettings, exc: &Excitation, duration_s: f64) -> Result<Recording> {
    let n = (duration_s / s.dt_s).round() as usize + 1;
    let t: Vec<f64> = (0..n).map(|k| k as f64 * s.dt_s).collect();
    let (v_ref, w_ref): (Vec<f64>, Vec<f64>) = t.iter().map(|&x| exc.at(x)).unzip();
    let mut rec = Recording::new("design", t, v_ref, w_ref, vec![0.0; n], vec![0.0; n])?;
    rec.set_meta("command_hold", "zoh");
    Ok(rec)
}

/// The model's response to `exc` from rest over `duration_s`, with its sensitivities.
fn respond(
    model: &dyn DynamicModel,
    s: &DesignSettings,
    exc: &Excitation,
    duration_s: f64,
) -> Result<Response> {
    let rec = commands(s, exc, duration_s)?;
    let (sim, sens) = model
        .simulate_with_sensitivities(&s.theta, &rec, &s.start_velocity)?
        .ok_or_else(|| Error::InvalidSetting("the model gives no sensitivities".into()))?;
    Ok((rec, sim, sens.theta))
}

/// M_P over the second of two periods (the response then periodic) and log det(M_P / P).
fn information(
    model: &dyn DynamicModel,
    s: &DesignSettings,
    exc: &Excitation,
) -> Result<(DMatrix<f64>, f64)> {
    let (rec, _, sens) = respond(model, s, exc, 2.0 * s.period_s)?;
    let first = rec
        .t
        .iter()
        .position(|&t| t >= s.period_s - 1e-9)
        .unwrap_or(0);
    let mut m = DMatrix::zeros(6, 6);
    for (c, sc) in sens.iter().enumerate() {
        let w = 1.0 / s.noise_std[c].powi(2);
        // The last sample closes the period: rows first..n−1 are one period.
        let rows = sc.rows(first, sc.nrows() - 1 - first);
        m += rows.transpose() * rows * w;
    }
    let per_s = &m / s.period_s;
    let log_det = per_s.clone().cholesky().map_or(f64::NEG_INFINITY, |c| {
        2.0 * c.l().diagonal().map(f64::ln).sum()
    });
    Ok((m, log_det))
}

/// The periods of driving the target accuracy needs (not rounded), the whole periods' drive
/// \[s\] and the predicted standard errors after it.
fn duration(s: &DesignSettings, m: &DMatrix<f64>) -> Option<(f64, f64, [f64; 6])> {
    let inv = m.clone().try_inverse()?;
    let needed = s
        .targets
        .iter()
        .map(|&i| inv[(i, i)] / (s.accuracy * s.theta[i]).powi(2))
        .fold(0.0f64, f64::max);
    if !needed.is_finite() || needed <= 0.0 {
        return None;
    }
    let periods = needed.ceil().max(1.0);
    let se = std::array::from_fn(|i| (inv[(i, i)] / periods).max(0.0).sqrt());
    Some((needed, periods * s.period_s, se))
}

/// The unicycle pose (x, y) driven by the simulated (v, ω) from the origin facing +x, at
/// every sample.
fn path(rec: &Recording, sim: &[Vec<f64>]) -> Vec<[f64; 2]> {
    let (mut x, mut y, mut phi) = (0.0f64, 0.0f64, 0.0f64);
    let mut out = vec![[0.0, 0.0]];
    for k in 1..rec.len() {
        let dt = rec.t[k] - rec.t[k - 1];
        let (v, w) = (sim[0][k - 1], sim[1][k - 1]);
        x += v * phi.cos() * dt;
        y += v * phi.sin() * dt;
        phi += w * dt;
        out.push([x, y]);
    }
    out
}

/// The largest |x|, |y| of a path.
fn extent(path: &[[f64; 2]]) -> [f64; 2] {
    path.iter().fold([0.0f64; 2], |e, p| {
        [e[0].max(p[0].abs()), e[1].max(p[1].abs())]
    })
}

/// Whether a `path` (from the start, in the robot's start frame) stays inside the space from
/// the settings' start pose.
fn inside_space(s: &DesignSettings, path: &[[f64; 2]]) -> bool {
    let [x0, y0, psi] = s.start_pose;
    let (sn, cs) = psi.sin_cos();
    path.iter().all(|&[x, y]| {
        let (wx, wy) = (x0 + x * cs - y * sn, y0 + x * sn + y * cs);
        wx.abs() <= 0.5 * s.space_m[0] && wy.abs() <= 0.5 * s.space_m[1]
    })
}

/// One candidate: its excitation, information, drive and extent.
struct Candidate {
    exc: Excitation,
    log_det: f64,
    /// Periods needed (not rounded).
    needed: f64,
    duration_s: f64,
    se: [f64; 6],
    path: Vec<[f64; 2]>,
}

/// The candidate with these shares: amplitudes at the limits, the forward ones scaled down
/// (halving, then bisecting 8 times) until the pose stays inside the space over the drive.
fn candidate(
    model: &dyn DynamicModel,
    s: &DesignSettings,
    lines: &[Vec<usize>; 2],
    shares: &[Vec<f64>; 2],
) -> Result<Option<Candidate>> {
    let build = |scale: f64| Excitation {
        v_ref: signal(
            s.period_s,
            &lines[0],
            &amplitudes(s, &lines[0], &shares[0], 0, scale),
        ),
        w_ref: signal(
            s.period_s,
            &lines[1],
            &amplitudes(s, &lines[1], &shares[1], 1, 1.0),
        ),
    };
    let inside = |p: &[[f64; 2]]| inside_space(s, p);
    let eval = |scale: f64| -> Result<Option<Candidate>> {
        let exc = build(scale);
        let (m, log_det) = information(model, s, &exc)?;
        let Some((needed, duration_s, se)) = duration(s, &m) else {
            return Ok(None);
        };
        // The pose needs the outputs alone: 2 states a step instead of the sensitivity pass's 18.
        let rec = commands(s, &exc, duration_s)?;
        let sim = model.simulate(&s.theta, &rec, &s.start_velocity)?;
        Ok(Some(Candidate {
            path: path(&rec, &sim),
            exc,
            log_det,
            needed,
            duration_s,
            se,
        }))
    };
    let mut best = eval(1.0)?;
    if best.as_ref().is_some_and(|c| inside(&c.path)) {
        return Ok(best);
    }
    // Halve until inside, then bisect between the last outside and the first inside scale.
    let (mut lo, mut hi) = (0.0, 1.0);
    best = None;
    for _ in 0..12 {
        let mid = if best.is_none() {
            0.5 * hi
        } else {
            0.5 * (lo + hi)
        };
        match eval(mid)? {
            Some(c) if inside(&c.path) => {
                lo = mid;
                best = Some(c);
            }
            _ => hi = mid,
        }
        if best.is_some() && hi - lo < 1.0 / 256.0 {
            break;
        }
    }
    Ok(best)
}

/// Whether `a` beats `b` by the criterion (by more than 10⁻⁶, relative for the duration).
fn better(criterion: Criterion, a: &Candidate, b: &Candidate) -> bool {
    match criterion {
        Criterion::DOptimal => a.log_det > b.log_det + 1e-6,
        Criterion::Duration => a.needed < b.needed * (1.0 - 1e-6),
    }
}

/// The smallest share of a line against its channel's largest.
const MIN_SHARE: f64 = 0.1;

/// Designs the experiment for `model` (module docs): on the band up to `f_max_hz`, doubled
/// (with the lines it allows) up to `f_max_limit_hz` while no design on it keeps the robot
/// inside the space.
///
/// # Errors
/// [`Error::InvalidSetting`] for invalid settings or a model without sensitivities; an
/// error when no candidate on any band keeps the robot inside the space.
pub fn design(model: &dyn DynamicModel, s: &DesignSettings) -> Result<Design> {
    s.validate()?;
    let mut band = s.clone();
    let mut evaluations = 0;
    loop {
        let (found, n) = design_on(model, &band)?;
        evaluations += n;
        if let Some(mut d) = found {
            d.evaluations = evaluations;
            return Ok(d);
        }
        if 2.0 * band.f_max_hz > s.f_max_limit_hz * (1.0 + 1e-9) {
            return Err(Error::InvalidSetting(format!(
                "no excitation on lines up to {:.3} Hz keeps the robot inside the {} m × {} m \
                 space",
                band.f_max_hz, s.space_m[0], s.space_m[1]
            )));
        }
        band.f_max_hz *= 2.0;
        band.lines = band.lines.max(lines_below(band.f_max_hz, band.period_s));
    }
}

/// [`design`] on one band: the design (none when no candidate stays inside the space) and the
/// candidates evaluated.
fn design_on(model: &dyn DynamicModel, s: &DesignSettings) -> Result<(Option<Design>, usize)> {
    let lines = harmonics(s);
    let mut shares = [vec![1.0; s.lines], vec![1.0; s.lines]];
    let mut evaluations = 1;
    let Some(mut best) = candidate(model, s, &lines, &shares)? else {
        return Ok((None, evaluations));
    };
    let mut improved = true;
    while improved && evaluations < 400 {
        improved = false;
        for c in 0..2 {
            for i in 0..s.lines {
                for factor in [1.5, 1.0 / 1.5] {
                    let mut trial = shares.clone();
                    trial[c][i] *= factor;
                    // Every line keeps at least MIN_SHARE of the channel's largest: a design
                    // on one or two lines is optimal only for the prior θ.
                    let top = trial[c].iter().fold(0.0f64, |a, &b| a.max(b));
                    if trial[c][i] < MIN_SHARE * top
                        || trial[c].iter().any(|&x| x < MIN_SHARE * top)
                    {
                        continue;
                    }
                    evaluations += 1;
                    if let Some(t) = candidate(model, s, &lines, &trial)?
                        && better(s.criterion, &t, &best)
                    {
                        best = t;
                        shares = trial;
                        improved = true;
                    }
                }
            }
        }
    }
    let design = Design {
        excitation: best.exc,
        duration_s: best.duration_s,
        predicted_std_err: best.se,
        log_det_per_s: best.log_det,
        extent_m: extent(&best.path),
        evaluations,
        f_max_hz: s.f_max_hz,
        path_m: best.path,
    };
    Ok((Some(design), evaluations))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// M_P against its closed form for a sine on the v channel alone (θ3 = θ5 = 0, ω = 0): the
    /// steady response is A |G| sin(…), G(jω) = 1/(θ4 + jωθ1), ∂G/∂θ1 = −jω/(θ4 + jωθ1)², so
    /// over one period of N samples M_11 = N A² ω² / (2 σ_v² |θ4 + jωθ1|⁴).
    #[test]
    fn the_information_of_a_sine_is_its_closed_form() {
        let theta = [0.26, 0.25, 0.0, 1.0, 0.0, 1.0];
        let mut s = DesignSettings::for_robot(theta, 0.002, [1.0, 1.0]);
        s.period_s = 2.0;
        let (a, f) = (0.3, 0.5);
        let exc = Excitation {
            v_ref: Signal::Sines {
                offset: 0.0,
                lines: vec![(a, f, 0.0)],
            },
            w_ref: Signal::Constant { value: 0.0 },
        };
        let (m, _) = information(&wheelid_models::VwPd, &s, &exc).expect("information");
        let w = 2.0 * std::f64::consts::PI * f;
        let n = s.period_s / s.dt_s;
        let mod2 = theta[3].powi(2) + (w * theta[0]).powi(2);
        let closed = n * a * a * w * w / (2.0 * s.noise_std[0].powi(2) * mod2 * mod2);
        assert!(
            (m[(0, 0)] / closed - 1.0).abs() < 0.01,
            "M_11 {} vs {closed}",
            m[(0, 0)]
        );
        // θ4's: ∂G/∂θ4 = −1/(θ4 + jωθ1)².
        let closed44 = n * a * a / (2.0 * s.noise_std[0].powi(2) * mod2 * mod2);
        assert!((m[(3, 3)] / closed44 - 1.0).abs() < 0.01);
    }

    #[test]
    fn bad_settings_are_errors() {
        let mut s = DesignSettings::for_robot([0.26, 0.25, 0.0, 1.0, 0.2, 1.0], 0.1, [1.0, 1.0]);
        s.accuracy = 1.5;
        assert!(design(&wheelid_models::VwPd, &s).is_err());
        s.accuracy = 0.01;
        s.targets = vec![7];
        assert!(design(&wheelid_models::VwPd, &s).is_err());
    }
}
