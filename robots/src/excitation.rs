//! Excitation signals for system identification: what the robot is commanded while it is being
//! identified.
//!
//! A [`Signal`] is one scalar command u(t) (v_ref [m/s] or ω_ref [rad/s]); an [`Excitation`] is
//! the pair. Every signal is a pure function of time, so the same configuration always gives the
//! same commands. [`Signal`] is an internally tagged serde enum, so it can be written in TOML:
//!
//! ```toml
//! [v_ref]
//! type = "multisine"
//! offset = 0.3
//! amplitude = 0.15
//! f_min_hz = 0.01
//! f_max_hz = 0.5
//! lines = 50
//! period_s = 100.0
//! phases = { type = "schroeder" }
//!
//! [w_ref]
//! type = "sum_of_sines"
//! offset = 0.0
//! terms = [[0.5, 1.0], [0.25, 0.3]]   # (amplitude, angular frequency [rad/s])
//! ```
//!
//! The signals (t \[s\]; τ = t mod P):
//!
//! * [`Signal::Constant`]: u = value.
//! * [`Signal::SumOfSines`]: u = c + Σᵢ aᵢ sin(ωᵢ t), ωᵢ in rad/s — the form of every
//!   excitation in the thesis (§4.2, §4.4.1, §4.4.2).
//! * [`Signal::Steps`]: u = levels[⌊t / hold⌋ mod n], each level held `hold_s`, cycling.
//! * [`Signal::Chirp`]: linear sweep from f₀ to f₁ \[Hz\] over T,
//!   u = c + A sin θ(t), θ(t) = 2π (f₀ t + (f₁ − f₀) t² / (2T)) for 0 ≤ t ≤ T, so the
//!   instantaneous frequency θ'(t)/2π = f₀ + (f₁ − f₀) t/T. After T the sweep does not repeat:
//!   the phase continues at f₁ (θ = θ(T) + 2π f₁ (t − T)), so u stays smooth; before 0 it runs
//!   at f₀.
//! * [`Signal::Sines`]: u = c + Σᵢ aᵢ sin(2π fᵢ t + φᵢ), each line its own amplitude and
//!   phase (a designed experiment).
//! * [`Signal::Multisine`]: u = c + a Σₖ cos(2π nₖ τ / P + φₖ), k = 1…K, on the frequency grid
//!   nₖ/P \[Hz\] between f_min and f_max, periodic with period P, with Schroeder phases
//!   φₖ = −k(k − 1)π/K (Schroeder 1970, low crest factor for a flat spectrum) or
//!   independent uniform random phases from a seeded ChaCha8 stream. a is chosen so that the
//!   **peak** max |u − c| over a period equals `amplitude` (see [`MultisineSpec::amplitude`]).
//!
//! The crest factor (peak / rms of u − mean) measures how much of an actuator's range a signal
//! of given power needs: a single sine has √2, a Schroeder multisine with 16–100 consecutive
//! lines 1.83–1.68, random phases typically ≈ 3 (mean 3.0 over ten seeds at K = 32). See
//! Pintelon & Schoukens, *System Identification: A Frequency Domain Approach*, on multisine
//! design; [`crest_factor`] and [`Multisine::crest_factor`] compute it.

use std::f64::consts::PI;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};
use wheelid_core::Error;

/// u(t) = offset + Σ aᵢ sin(ωᵢ t).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SumOfSines {
    /// Constant offset (units of u).
    pub offset: f64,
    /// Terms (amplitude aᵢ in units of u, angular frequency ωᵢ [rad/s]).
    pub terms: Vec<(f64, f64)>,
}

impl SumOfSines {
    /// Value at time `t` \[s\].
    pub fn at(&self, t: f64) -> f64 {
        self.offset
            + self
                .terms
                .iter()
                .map(|(a, w)| a * (w * t).sin())
                .sum::<f64>()
    }
}

/// Phase choice of a [`Multisine`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Phases {
    /// Schroeder phases φₖ = −k(k − 1)π/K, k = 1…K (K = number of lines): for consecutive
    /// harmonics of equal amplitude this gives a low crest factor (1.83 at K = 16, 1.73 at 32,
    /// 1.68 at 100; the tests check < 2 for K = 16…100).
    Schroeder,
    /// Independent phases uniform on [0, 2π), drawn in line order from
    /// `ChaCha8Rng::seed_from_u64(seed)` — reproducible across platforms. (TOML integers are
    /// signed 64-bit: keep `seed` below 2⁶³ if the configuration is to be written as TOML.)
    Random {
        /// Random seed.
        seed: u64,
    },
}

/// The configuration of a [`Multisine`] (what is written in a TOML file).
///
/// The excited lines are K = `lines` harmonics nₖ of 1/P chosen from the grid
/// n_lo…n_hi, n_lo = max(1, ⌈f_min·P⌉), n_hi = ⌊f_max·P⌋ (with a 1e−9 tolerance on the
/// products so that e.g. f = 1/60 Hz, P = 60 s is harmonic 1), spread evenly:
/// nₖ = n_lo + round((k − 1)(n_hi − n_lo)/(K − 1)), k = 1…K (nₖ = n_lo for K = 1). With
/// K = n_hi − n_lo + 1 every grid line is excited (consecutive harmonics). DC is never a line;
/// the offset is [`MultisineSpec::offset`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MultisineSpec {
    /// Constant offset c (units of u).
    pub offset: f64,
    /// Peak deviation from the offset: max over one period of |u(t) − c| equals this (units of
    /// u; found on a grid of 64 samples per cycle of the highest line (≤ 2²⁰ samples), refined
    /// by Newton's method, relative accuracy ≈ 1e−12; building costs O(K · 64 n_K) operations).
    /// The rms of u − c is `amplitude / crest_factor`.
    pub amplitude: f64,
    /// Lowest admissible line \[Hz\].
    pub f_min_hz: f64,
    /// Highest admissible line \[Hz\].
    pub f_max_hz: f64,
    /// Number of excited lines K (≥ 1 and at most the number of grid lines in the band).
    pub lines: usize,
    /// Period P \[s\]; the frequency resolution is 1/P.
    pub period_s: f64,
    /// Phase choice.
    pub phases: Phases,
}

/// A periodic multisine u = c + a Σₖ cos(2π nₖ τ / P + φₖ), τ = t mod P (see
/// [`MultisineSpec`] for the lines, [`Phases`] for φₖ).
///
/// Built (and validated) once from its [`MultisineSpec`]; the lines, phases and the peak
/// normalisation are cached, so [`Multisine::at`] costs K cosines. Serialises as its spec.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MultisineSpec", into = "MultisineSpec")]
pub struct Multisine {
    spec: MultisineSpec,
    harmonics: Vec<usize>,
    phases: Vec<f64>,
    /// a: the amplitude of each line.
    line_amplitude: f64,
    /// max |Σ cos(…)| over a period (unnormalised).
    raw_peak: f64,
}

/// Relative tolerance when mapping a band edge \[Hz\] to a harmonic number.
const GRID_TOL: f64 = 1e-9;

fn invalid(msg: impl Into<String>) -> Error {
    Error::InvalidSetting(msg.into())
}

impl Multisine {
    /// Builds the multisine.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if a number is not finite, `period_s ≤ 0`, `amplitude < 0`,
    /// `lines == 0`, the band holds fewer than `lines` grid lines, or f_max·P > 10⁶.
    pub fn new(spec: MultisineSpec) -> Result<Self, Error> {
        let s = &spec;
        for (name, x) in [
            ("offset", s.offset),
            ("amplitude", s.amplitude),
            ("f_min_hz", s.f_min_hz),
            ("f_max_hz", s.f_max_hz),
            ("period_s", s.period_s),
        ] {
            if !x.is_finite() {
                return Err(invalid(format!("multisine: {name} = {x} is not finite")));
            }
        }
        if s.period_s <= 0.0 {
            return Err(invalid(format!(
                "multisine: period_s = {} must be > 0",
                s.period_s
            )));
        }
        if s.amplitude < 0.0 {
            return Err(invalid(format!(
                "multisine: amplitude = {} must be ≥ 0",
                s.amplitude
            )));
        }
        if s.lines == 0 {
            return Err(invalid("multisine: lines must be ≥ 1"));
        }
        let lo = (s.f_min_hz * s.period_s - GRID_TOL).ceil().max(1.0);
        let hi = (s.f_max_hz * s.period_s + GRID_TOL).floor();
        let available = if hi >= lo { hi - lo + 1.0 } else { 0.0 };
        if (s.lines as f64) > available {
            return Err(invalid(format!(
                "multisine: {} lines requested but the band [{}, {}] Hz holds {} lines of the \
                 1/{} s grid",
                s.lines, s.f_min_hz, s.f_max_hz, available, s.period_s
            )));
        }
        if hi > 1e6 {
            return Err(invalid(format!(
                "multisine: harmonic {hi} of 1/P is too high (f_max·P must be ≤ 1e6)"
            )));
        }
        let (lo, hi) = (lo as usize, hi as usize);
        let k_n = s.lines;
        let harmonics: Vec<usize> = if k_n == 1 {
            vec![lo]
        } else {
            let span = hi - lo;
            (0..k_n)
                .map(|k| lo + (2 * k * span + (k_n - 1)) / (2 * (k_n - 1)))
                .collect()
        };
        let phases: Vec<f64> = match s.phases {
            Phases::Schroeder => (1..=k_n)
                .map(|k| -((k * (k - 1)) as f64) * PI / k_n as f64)
                .collect(),
            Phases::Random { seed } => {
                let mut rng = ChaCha8Rng::seed_from_u64(seed);
                (0..k_n).map(|_| 2.0 * PI * rng.random::<f64>()).collect()
            }
        };
        let raw_peak = raw_peak(&harmonics, &phases);
        let line_amplitude = s.amplitude / raw_peak;
        Ok(Self {
            spec,
            harmonics,
            phases,
            line_amplitude,
            raw_peak,
        })
    }

    /// The configuration it was built from.
    pub fn spec(&self) -> &MultisineSpec {
        &self.spec
    }

    /// Harmonic numbers nₖ of the excited lines (line k at nₖ / P Hz), increasing.
    pub fn harmonics(&self) -> &[usize] {
        &self.harmonics
    }

    /// Frequencies of the excited lines \[Hz\].
    pub fn frequencies_hz(&self) -> Vec<f64> {
        self.harmonics
            .iter()
            .map(|&n| n as f64 / self.spec.period_s)
            .collect()
    }

    /// Phases φₖ \[rad\], in line order.
    pub fn phases(&self) -> &[f64] {
        &self.phases
    }

    /// The amplitude a of each line (units of u): `amplitude` / max |Σ cos(…)|.
    pub fn line_amplitude(&self) -> f64 {
        self.line_amplitude
    }

    /// Crest factor of u − c over one period: peak / rms = max|Σ cos| / √(K/2) (the rms of K
    /// cosines at distinct non-zero harmonics is exactly √(K/2)).
    pub fn crest_factor(&self) -> f64 {
        self.raw_peak / (self.harmonics.len() as f64 / 2.0).sqrt()
    }

    /// Value at time `t` \[s\].
    pub fn at(&self, t: f64) -> f64 {
        let p = self.spec.period_s;
        let x = t.rem_euclid(p) / p;
        self.spec.offset + self.line_amplitude * raw_sum(&self.harmonics, &self.phases, x, 0)
    }
}

impl TryFrom<MultisineSpec> for Multisine {
    type Error = Error;
    fn try_from(spec: MultisineSpec) -> Result<Self, Error> {
        Self::new(spec)
    }
}

impl From<Multisine> for MultisineSpec {
    fn from(m: Multisine) -> Self {
        m.spec
    }
}

/// `order`-th derivative with respect to x (= τ/P ∈ [0, 1)) of Σ cos(2π nₖ x + φₖ), order ≤ 2.
fn raw_sum(harmonics: &[usize], phases: &[f64], x: f64, order: u8) -> f64 {
    harmonics
        .iter()
        .zip(phases)
        .map(|(&n, &ph)| {
            let w = 2.0 * PI * n as f64;
            let arg = w * x + ph;
            match order {
                0 => arg.cos(),
                1 => -w * arg.sin(),
                _ => -w * w * arg.cos(),
            }
        })
        .sum()
}

/// max over one period of |Σ cos(2π nₖ x + φₖ)|: a grid of 64 samples per cycle of the highest
/// harmonic (at least 4096, at most 2²⁰ samples; phasor recurrence, reset every 256 steps), then
/// Newton's method on the derivative from the best 16 grid points. Cost O(K · n).
fn raw_peak(harmonics: &[usize], phases: &[f64]) -> f64 {
    let n_max = harmonics.iter().copied().max().unwrap_or(1);
    let n = (64 * n_max).clamp(4096, 1 << 20);
    let mut acc = vec![0.0f64; n];
    for (&h, &ph) in harmonics.iter().zip(phases) {
        let step = 2.0 * PI * h as f64 / n as f64;
        let (ws, wc) = step.sin_cos();
        let (mut zs, mut zc) = (0.0, 0.0);
        for (j, a) in acc.iter_mut().enumerate() {
            if j % 256 == 0 {
                (zs, zc) = (step * j as f64 + ph).sin_cos();
            }
            *a += zc;
            (zc, zs) = (zc * wc - zs * ws, zs * wc + zc * ws);
        }
    }
    // Refine the best few grid maxima of |sum| (distinct peaks may be nearly equal).
    let mut idx: Vec<usize> = (0..n).collect();
    let keep = 16.min(n);
    idx.select_nth_unstable_by(keep - 1, |&a, &b| acc[b].abs().total_cmp(&acc[a].abs()));
    let mut best = 0.0f64;
    for &j in &idx[..keep] {
        let mut x = j as f64 / n as f64;
        best = best.max(acc[j].abs());
        for _ in 0..6 {
            let d1 = raw_sum(harmonics, phases, x, 1);
            let d2 = raw_sum(harmonics, phases, x, 2);
            if d2 == 0.0 {
                break;
            }
            let dx = (d1 / d2).clamp(-1.0 / n as f64, 1.0 / n as f64);
            x -= dx;
        }
        best = best.max(raw_sum(harmonics, phases, x, 0).abs());
    }
    best
}

/// Crest factor of sampled data: max |xᵢ − x̄| / rms(x − x̄) (1 for a square wave, √2 for a
/// sine sampled over whole periods). NaN for fewer than two samples or constant data.
pub fn crest_factor(samples: &[f64]) -> f64 {
    if samples.len() < 2 {
        return f64::NAN;
    }
    let mean = samples.iter().sum::<f64>() / samples.len() as f64;
    let peak = samples
        .iter()
        .map(|x| (x - mean).abs())
        .fold(0.0f64, f64::max);
    let rms =
        (samples.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / samples.len() as f64).sqrt();
    if rms == 0.0 { f64::NAN } else { peak / rms }
}

/// One scalar excitation signal u(t) (see the module documentation for the formulas).
///
/// Serde: internally tagged by `type` (`constant`, `sum_of_sines`, `steps`, `chirp`,
/// `multisine`, `sines`), unknown fields rejected.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "type", rename_all = "snake_case", deny_unknown_fields)]
pub enum Signal {
    /// u = value.
    Constant {
        /// The value (units of u).
        value: f64,
    },
    /// u = offset + Σ aᵢ sin(ωᵢ t) (the thesis's signals).
    SumOfSines(SumOfSines),
    /// Piecewise constant: levels[⌊t / hold_s⌋ mod n] (t < 0 wraps the same way); an empty
    /// list gives 0 and `hold_s ≤ 0` gives the first level forever.
    Steps {
        /// The levels, in order (units of u).
        levels: Vec<f64>,
        /// How long each level is held \[s\].
        hold_s: f64,
    },
    /// Linear chirp u = offset + A sin θ(t), θ = 2π (f₀ t + (f₁ − f₀) t²/(2T)) on [0, T];
    /// continues at f₁ after T (phase continuous, no repeat) and runs at f₀ before 0.
    /// `duration_s ≤ 0` gives a sine at f₁.
    Chirp {
        /// Offset (units of u).
        offset: f64,
        /// Amplitude A (units of u; peak deviation from the offset).
        amplitude: f64,
        /// Start frequency f₀ \[Hz\].
        f0_hz: f64,
        /// End frequency f₁ \[Hz\].
        f1_hz: f64,
        /// Sweep duration T \[s\].
        duration_s: f64,
    },
    /// A periodic multisine with peak normalisation (see [`Multisine`]).
    Multisine(Multisine),
    /// u = offset + Σ aᵢ sin(2π fᵢ t + φᵢ): lines with their own amplitudes and phases (what
    /// an experiment design gives, `wheelid::design`).
    Sines {
        /// Offset (units of u).
        offset: f64,
        /// The lines: (amplitude aᵢ in units of u, frequency fᵢ \[Hz\], phase φᵢ \[rad\]).
        lines: Vec<(f64, f64, f64)>,
    },
}

impl Signal {
    /// Value at time `t` \[s\].
    pub fn at(&self, t: f64) -> f64 {
        match self {
            Self::Constant { value } => *value,
            Self::SumOfSines(s) => s.at(t),
            Self::Steps { levels, hold_s } => {
                if levels.is_empty() {
                    0.0
                } else if *hold_s <= 0.0 || !hold_s.is_finite() {
                    levels[0]
                } else {
                    let i = (t / hold_s).floor().rem_euclid(levels.len() as f64);
                    levels[(i as usize).min(levels.len() - 1)]
                }
            }
            Self::Chirp {
                offset,
                amplitude,
                f0_hz,
                f1_hz,
                duration_s,
            } => offset + amplitude * chirp_phase(*f0_hz, *f1_hz, *duration_s, t).sin(),
            Self::Multisine(m) => m.at(t),
            Self::Sines { offset, lines } => {
                offset
                    + lines
                        .iter()
                        .map(|(a, f, ph)| a * (2.0 * PI * f * t + ph).sin())
                        .sum::<f64>()
            }
        }
    }

    /// A multisine signal.
    ///
    /// # Errors
    /// As [`Multisine::new`].
    pub fn multisine(spec: MultisineSpec) -> Result<Self, Error> {
        Multisine::new(spec).map(Self::Multisine)
    }

    /// Checks that every number is finite and the durations are positive (a [`Multisine`] is
    /// checked when it is built).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] naming the offending field.
    pub fn validate(&self) -> Result<(), Error> {
        let check = |name: &str, x: f64| {
            if x.is_finite() {
                Ok(())
            } else {
                Err(invalid(format!("signal: {name} = {x} is not finite")))
            }
        };
        match self {
            Self::Constant { value } => check("value", *value),
            Self::SumOfSines(s) => {
                check("offset", s.offset)?;
                for &(a, w) in &s.terms {
                    check("term amplitude", a)?;
                    check("term frequency", w)?;
                }
                Ok(())
            }
            Self::Steps { levels, hold_s } => {
                if levels.is_empty() {
                    return Err(invalid("steps: levels is empty"));
                }
                for &l in levels {
                    check("level", l)?;
                }
                check("hold_s", *hold_s)?;
                if *hold_s <= 0.0 {
                    return Err(invalid(format!("steps: hold_s = {hold_s} must be > 0")));
                }
                Ok(())
            }
            Self::Chirp {
                offset,
                amplitude,
                f0_hz,
                f1_hz,
                duration_s,
            } => {
                check("offset", *offset)?;
                check("amplitude", *amplitude)?;
                check("f0_hz", *f0_hz)?;
                check("f1_hz", *f1_hz)?;
                check("duration_s", *duration_s)?;
                if *duration_s <= 0.0 {
                    return Err(invalid(format!(
                        "chirp: duration_s = {duration_s} must be > 0"
                    )));
                }
                Ok(())
            }
            Self::Multisine(_) => Ok(()),
            Self::Sines { offset, lines } => {
                check("offset", *offset)?;
                for &(a, f, ph) in lines {
                    check("line amplitude", a)?;
                    check("line frequency", f)?;
                    check("line phase", ph)?;
                }
                Ok(())
            }
        }
    }
}

/// θ(t) of the linear chirp \[rad\] (see [`Signal::Chirp`]).
fn chirp_phase(f0: f64, f1: f64, dur: f64, t: f64) -> f64 {
    if dur <= 0.0 {
        return 2.0 * PI * f1 * t;
    }
    if t <= 0.0 {
        2.0 * PI * f0 * t
    } else if t <= dur {
        2.0 * PI * (f0 * t + (f1 - f0) * t * t / (2.0 * dur))
    } else {
        2.0 * PI * (0.5 * (f0 + f1) * dur + f1 * (t - dur))
    }
}

impl From<SumOfSines> for Signal {
    fn from(s: SumOfSines) -> Self {
        Self::SumOfSines(s)
    }
}

impl From<Multisine> for Signal {
    fn from(m: Multisine) -> Self {
        Self::Multisine(m)
    }
}

/// Period P \[s\] of [`Excitation::random_multisine`]: frequency resolution 1/60 Hz.
pub const RANDOM_MULTISINE_PERIOD_S: f64 = 60.0;

/// A pair of commands (v_ref [m/s], ω_ref [rad/s]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Excitation {
    /// Forward-velocity command [m/s].
    pub v_ref: Signal,
    /// Angular-velocity command [rad/s].
    pub w_ref: Signal,
}

impl Excitation {
    /// The thesis's Pioneer 3-DX excitation (§4.4.2):
    /// v_ref = 0.4 + 0.1 sin 2t + 0.1 sin t + 0.1 sin(t/3) + 0.1 sin(t/11),
    /// ω_ref = 0.75 + 0.25 sin(3t/2) + 0.25 sin t + 0.25 sin(t/2) + 0.25 sin(t/5).
    pub fn thesis_pioneer() -> Self {
        Self {
            v_ref: Signal::SumOfSines(SumOfSines {
                offset: 0.4,
                terms: vec![(0.1, 2.0), (0.1, 1.0), (0.1, 1.0 / 3.0), (0.1, 1.0 / 11.0)],
            }),
            w_ref: Signal::SumOfSines(SumOfSines {
                offset: 0.75,
                terms: vec![(0.25, 1.5), (0.25, 1.0), (0.25, 0.5), (0.25, 0.2)],
            }),
        }
    }

    /// The thesis's Khepera III excitation (§4.4.1):
    /// v_ref = 0.1 + 0.05 sin 2t + 0.05 sin t + 0.05 sin(t/3) + 0.05 sin(t/11),
    /// ω_ref = 1.5 + 0.5 sin(3t/2) + 0.5 sin t + 0.25 sin(t/2) + 0.25 sin(t/5).
    pub fn thesis_khepera() -> Self {
        Self {
            v_ref: Signal::SumOfSines(SumOfSines {
                offset: 0.1,
                terms: vec![
                    (0.05, 2.0),
                    (0.05, 1.0),
                    (0.05, 1.0 / 3.0),
                    (0.05, 1.0 / 11.0),
                ],
            }),
            w_ref: Signal::SumOfSines(SumOfSines {
                offset: 1.5,
                terms: vec![(0.5, 1.5), (0.5, 1.0), (0.25, 0.5), (0.25, 0.2)],
            }),
        }
    }

    /// The thesis's simulated linear-regression excitation, §4.2 "second case" (Fig. 4.10(c),
    /// (d)):
    /// v_ref = 0.2 sin t + 0.1 sin 1.5t + 0.1 sin 3t + 0.1 sin 0.1t + 0.08 sin 0.013t +
    /// 0.1 sin 5t,
    /// ω_ref = (5π/3) sin 2t + 0.1 sin 0.1t + 0.1 sin 0.09t.
    pub fn thesis_regression() -> Self {
        Self {
            v_ref: Signal::SumOfSines(SumOfSines {
                offset: 0.0,
                terms: vec![
                    (0.2, 1.0),
                    (0.1, 1.5),
                    (0.1, 3.0),
                    (0.1, 0.1),
                    (0.08, 0.013),
                    (0.1, 5.0),
                ],
            }),
            w_ref: Signal::SumOfSines(SumOfSines {
                offset: 0.0,
                terms: vec![(5.0 * PI / 3.0, 2.0), (0.1, 0.1), (0.1, 0.09)],
            }),
        }
    }

    /// Random-phase multisines on interleaved lines, period
    /// [`RANDOM_MULTISINE_PERIOD_S`] = 60 s (resolution 1/60 Hz):
    /// with N the largest odd harmonic ≤ f_max·60, v_ref excites the odd harmonics 1, 3, …, N
    /// and ω_ref the even ones 2, 4, …, N − 1, so over each period the two commands are
    /// exactly uncorrelated. v_ref = `v_offset` ± `v_amp` (peak), ω_ref = 0 ± `w_amp` (peak);
    /// phases from `seed` (v_ref) and `seed + 1` (ω_ref, wrapping).
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if f_max_hz < 3/60 Hz (N ≥ 3 is needed for ω_ref to get a
    /// line) or a number is invalid (see [`Multisine::new`]).
    pub fn random_multisine(
        seed: u64,
        v_offset: f64,
        v_amp: f64,
        w_amp: f64,
        f_max_hz: f64,
    ) -> Result<Self, Error> {
        let p = RANDOM_MULTISINE_PERIOD_S;
        if !f_max_hz.is_finite() {
            return Err(invalid(format!("random_multisine: f_max_hz = {f_max_hz}")));
        }
        let mut n = (f_max_hz * p + GRID_TOL).floor();
        if n % 2.0 == 0.0 {
            n -= 1.0;
        }
        if n < 3.0 {
            return Err(invalid(format!(
                "random_multisine: f_max_hz = {f_max_hz} must be ≥ 3/{p} Hz"
            )));
        }
        let n = n as usize;
        let v = MultisineSpec {
            offset: v_offset,
            amplitude: v_amp,
            f_min_hz: 1.0 / p,
            f_max_hz: n as f64 / p,
            lines: n.div_ceil(2),
            period_s: p,
            phases: Phases::Random { seed },
        };
        let w = MultisineSpec {
            offset: 0.0,
            amplitude: w_amp,
            f_min_hz: 2.0 / p,
            f_max_hz: (n - 1) as f64 / p,
            lines: (n - 1) / 2,
            period_s: p,
            phases: Phases::Random {
                seed: seed.wrapping_add(1),
            },
        };
        Ok(Self {
            v_ref: Signal::multisine(v)?,
            w_ref: Signal::multisine(w)?,
        })
    }

    /// Commands (v_ref [m/s], ω_ref [rad/s]) at time `t` \[s\].
    pub fn at(&self, t: f64) -> (f64, f64) {
        (self.v_ref.at(t), self.w_ref.at(t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    fn ms(offset: f64, amp: f64, lo: f64, hi: f64, lines: usize, p: f64, ph: Phases) -> Multisine {
        Multisine::new(MultisineSpec {
            offset,
            amplitude: amp,
            f_min_hz: lo,
            f_max_hz: hi,
            lines,
            period_s: p,
            phases: ph,
        })
        .expect("valid multisine")
    }

    #[test]
    fn thesis_presets_keep_their_numbers() {
        let t = 1.234_f64;
        let (v, w) = Excitation::thesis_pioneer().at(t);
        let v_exp = 0.4
            + 0.1 * (2.0 * t).sin()
            + 0.1 * t.sin()
            + 0.1 * (t / 3.0).sin()
            + 0.1 * (t / 11.0).sin();
        let w_exp = 0.75
            + 0.25 * (1.5 * t).sin()
            + 0.25 * t.sin()
            + 0.25 * (0.5 * t).sin()
            + 0.25 * (0.2 * t).sin();
        assert_relative_eq!(v, v_exp, max_relative = 1e-15);
        assert_relative_eq!(w, w_exp, max_relative = 1e-15);

        let (v, w) = Excitation::thesis_khepera().at(t);
        let v_exp = 0.1
            + 0.05 * (2.0 * t).sin()
            + 0.05 * t.sin()
            + 0.05 * (t / 3.0).sin()
            + 0.05 * (t / 11.0).sin();
        let w_exp = 1.5
            + 0.5 * (1.5 * t).sin()
            + 0.5 * t.sin()
            + 0.25 * (0.5 * t).sin()
            + 0.25 * (0.2 * t).sin();
        assert_relative_eq!(v, v_exp, max_relative = 1e-15);
        assert_relative_eq!(w, w_exp, max_relative = 1e-15);

        let t = 7.5_f64;
        let (v, w) = Excitation::thesis_regression().at(t);
        let v_exp = 0.2 * t.sin()
            + 0.1 * (1.5 * t).sin()
            + 0.1 * (3.0 * t).sin()
            + 0.1 * (0.1 * t).sin()
            + 0.08 * (0.013 * t).sin()
            + 0.1 * (5.0 * t).sin();
        let w_exp =
            5.0 * PI / 3.0 * (2.0 * t).sin() + 0.1 * (0.1 * t).sin() + 0.1 * (0.09 * t).sin();
        assert_relative_eq!(v, v_exp, max_relative = 1e-14);
        assert_relative_eq!(w, w_exp, max_relative = 1e-14);
        // ω_ref's leading term: (5π/3) sin 2t peaks at 5.236 rad/s at t = π/4.
        let (_, w) = Excitation::thesis_regression().at(PI / 4.0);
        assert_relative_eq!(
            w,
            5.0 * PI / 3.0 + 0.1 * (0.1 * PI / 4.0).sin() + 0.1 * (0.09 * PI / 4.0).sin(),
            max_relative = 1e-14
        );
    }

    #[test]
    fn schroeder_crest_factor_is_low_and_random_phases_are_worse() {
        for k in [16usize, 20, 31, 32, 50, 64, 100] {
            // k consecutive harmonics 1…k of 1/10 Hz.
            let m = ms(0.0, 1.0, 0.1, k as f64 / 10.0, k, 10.0, Phases::Schroeder);
            assert_eq!(m.harmonics(), (1..=k).collect::<Vec<_>>().as_slice());
            let cf = m.crest_factor();
            // Independent check on a dense sample grid (one period).
            let n = 200 * k;
            let u: Vec<f64> = (0..n).map(|j| m.at(10.0 * j as f64 / n as f64)).collect();
            let cf_sampled = crest_factor(&u);
            assert!(cf < 2.0, "K = {k}: Schroeder crest factor {cf}");
            assert!(
                cf > 1.3,
                "K = {k}: crest factor {cf} below any flat-spectrum multisine"
            );
            assert_relative_eq!(cf_sampled, cf, max_relative = 1e-3);
        }
        // Random phases, K = 32: typically ≈ 3 or more.
        let cfs: Vec<f64> = (0..10u64)
            .map(|seed| ms(0.0, 1.0, 0.1, 3.2, 32, 10.0, Phases::Random { seed }).crest_factor())
            .collect();
        let mean = cfs.iter().sum::<f64>() / cfs.len() as f64;
        let schroeder = ms(0.0, 1.0, 0.1, 3.2, 32, 10.0, Phases::Schroeder).crest_factor();
        assert!(mean > 2.5, "random-phase crest factors {cfs:?}");
        assert!(cfs.iter().all(|&c| c > schroeder), "{cfs:?} vs {schroeder}");
    }

    #[test]
    fn multisine_peak_equals_amplitude() {
        for ph in [Phases::Schroeder, Phases::Random { seed: 7 }] {
            let m = ms(0.3, 0.15, 0.01, 0.5, 50, 100.0, ph);
            let n = 200_000;
            let peak = (0..n)
                .map(|j| (m.at(100.0 * j as f64 / n as f64) - 0.3).abs())
                .fold(0.0f64, f64::max);
            assert!(peak <= 0.15 * (1.0 + 1e-12), "{peak}");
            assert_relative_eq!(peak, 0.15, max_relative = 1e-5);
            // rms = amplitude / crest factor.
            let rms = ((0..n)
                .map(|j| (m.at(100.0 * j as f64 / n as f64) - 0.3).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt();
            assert_relative_eq!(rms, 0.15 / m.crest_factor(), max_relative = 1e-9);
        }
    }

    #[test]
    fn multisine_is_periodic() {
        let m = ms(0.5, 0.2, 0.05, 2.0, 25, 20.0, Phases::Random { seed: 3 });
        let p = 20.0;
        for j in 0..500 {
            let t = -13.7 + 0.917 * j as f64;
            assert!((m.at(t + p) - m.at(t)).abs() < 1e-12, "t = {t}");
            assert!((m.at(t + 7.0 * p) - m.at(t)).abs() < 1e-12, "t = {t}");
        }
    }

    #[test]
    fn multisine_spectrum_has_power_only_on_its_lines() {
        // 12 lines spread over harmonics 3…40 of 1/16 Hz; one period sampled at 128 points.
        let p = 16.0;
        let m = ms(
            0.25,
            1.0,
            3.0 / p,
            40.0 / p,
            12,
            p,
            Phases::Random { seed: 11 },
        );
        let lines = m.harmonics().to_vec();
        assert_eq!(lines.len(), 12);
        assert_eq!((lines[0], lines[11]), (3, 40));
        assert!(lines.windows(2).all(|w| w[1] > w[0]));
        let n = 128usize;
        let u: Vec<f64> = (0..n).map(|j| m.at(p * j as f64 / n as f64)).collect();
        for bin in 0..n / 2 {
            let (mut re, mut im) = (0.0, 0.0);
            for (j, &x) in u.iter().enumerate() {
                let a = -2.0 * PI * (bin * j) as f64 / n as f64;
                re += x * a.cos();
                im += x * a.sin();
            }
            let mag = re.hypot(im) / n as f64;
            if bin == 0 {
                assert_relative_eq!(mag, 0.25, max_relative = 1e-12);
            } else if let Some(k) = lines.iter().position(|&l| l == bin) {
                // cos(θ) puts half its amplitude in the positive-frequency bin, with phase φₖ.
                assert_relative_eq!(mag, m.line_amplitude() / 2.0, max_relative = 1e-10);
                let phase = im.atan2(re);
                let d = (phase - m.phases()[k]).rem_euclid(2.0 * PI);
                assert!(
                    !(1e-9..=2.0 * PI - 1e-9).contains(&d),
                    "bin {bin}: {phase} vs {}",
                    m.phases()[k]
                );
            } else {
                assert!(mag < 1e-12, "bin {bin} has |U| = {mag}");
            }
        }
    }

    #[test]
    fn schroeder_phases_follow_the_formula() {
        let m = ms(0.0, 1.0, 0.1, 2.0, 20, 10.0, Phases::Schroeder);
        for (i, &ph) in m.phases().iter().enumerate() {
            let k = (i + 1) as f64;
            assert_relative_eq!(ph, -k * (k - 1.0) * PI / 20.0, max_relative = 1e-15);
        }
        // Random phases are reproducible and depend on the seed.
        let a = ms(0.0, 1.0, 0.1, 2.0, 20, 10.0, Phases::Random { seed: 5 });
        let b = ms(0.0, 1.0, 0.1, 2.0, 20, 10.0, Phases::Random { seed: 5 });
        let c = ms(0.0, 1.0, 0.1, 2.0, 20, 10.0, Phases::Random { seed: 6 });
        assert_eq!(a.phases(), b.phases());
        assert_ne!(a.phases(), c.phases());
        assert!(a.phases().iter().all(|&p| (0.0..2.0 * PI).contains(&p)));
    }

    #[test]
    fn multisine_rejects_bad_specs() {
        let good = MultisineSpec {
            offset: 0.0,
            amplitude: 1.0,
            f_min_hz: 0.1,
            f_max_hz: 1.0,
            lines: 10,
            period_s: 10.0,
            phases: Phases::Schroeder,
        };
        assert!(Multisine::new(good.clone()).is_ok());
        for bad in [
            MultisineSpec {
                lines: 11,
                ..good.clone()
            },
            MultisineSpec {
                lines: 0,
                ..good.clone()
            },
            MultisineSpec {
                period_s: 0.0,
                ..good.clone()
            },
            MultisineSpec {
                amplitude: -1.0,
                ..good.clone()
            },
            MultisineSpec {
                f_max_hz: f64::NAN,
                ..good.clone()
            },
            MultisineSpec {
                f_min_hz: 2.0,
                ..good.clone()
            },
        ] {
            assert!(Multisine::new(bad.clone()).is_err(), "{bad:?}");
        }
    }

    /// Zero crossing of u − offset in [a, b] by bisection.
    fn crossing(s: &Signal, offset: f64, mut a: f64, mut b: f64) -> f64 {
        let fa = s.at(a) - offset;
        for _ in 0..200 {
            let m = 0.5 * (a + b);
            if (s.at(m) - offset).signum() == fa.signum() {
                a = m;
            } else {
                b = m;
            }
        }
        0.5 * (a + b)
    }

    #[test]
    fn chirp_instantaneous_frequency_is_linear() {
        let (f0, f1, dur) = (0.05, 1.0, 100.0);
        let s = Signal::Chirp {
            offset: 0.2,
            amplitude: 0.5,
            f0_hz: f0,
            f1_hz: f1,
            duration_s: dur,
        };
        s.validate().expect("valid");
        // Zero crossings of u − offset are where θ = mπ; bracket them on a fine grid.
        let dt = 0.01;
        let mut zs = Vec::new();
        let mut t = 0.005;
        while t + dt < dur {
            if (s.at(t) - 0.2).signum() != (s.at(t + dt) - 0.2).signum() {
                zs.push(crossing(&s, 0.2, t, t + dt));
            }
            t += dt;
        }
        // θ(T) = 2π (f0 + f1) T / 2 = 105π: crossings at θ = π, …, 104π (inside (0, T)).
        assert_eq!(zs.len(), 104);
        for w in zs.windows(2) {
            // θ is quadratic, so (θ(b) − θ(a))/(b − a) = θ'((a + b)/2) exactly: π/Δt = 2π f(mid).
            let f_est = 1.0 / (2.0 * (w[1] - w[0]));
            let mid = 0.5 * (w[0] + w[1]);
            assert_relative_eq!(f_est, f0 + (f1 - f0) * mid / dur, max_relative = 1e-9);
        }
        // After T the phase continues at f1 without a jump.
        let eps = 1e-9;
        assert!((s.at(dur + eps) - s.at(dur - eps)).abs() < 1e-6);
        let z1 = crossing(&s, 0.2, 100.2, 100.7);
        let z2 = crossing(&s, 0.2, 100.7, 101.2);
        assert_relative_eq!(1.0 / (2.0 * (z2 - z1)), f1, max_relative = 1e-9);
        // Peak = offset + amplitude.
        let peak = (0..100_000)
            .map(|j| s.at(j as f64 * 1e-3))
            .fold(f64::MIN, f64::max);
        assert_relative_eq!(peak, 0.7, max_relative = 1e-6);
    }

    #[test]
    fn steps_hold_their_levels_and_cycle() {
        let s = Signal::Steps {
            levels: vec![0.1, -0.3, 0.7],
            hold_s: 2.5,
        };
        s.validate().expect("valid");
        for (t, want) in [
            (0.0, 0.1),
            (2.49, 0.1),
            (2.5, -0.3),
            (4.99, -0.3),
            (5.0, 0.7),
            (7.49, 0.7),
            (7.5, 0.1),
            (17.6, -0.3),
            (22.6, 0.1),
            (-0.1, 0.7),
            (-5.1, 0.1),
            (-5.0, -0.3),
        ] {
            assert_eq!(s.at(t), want, "t = {t}");
        }
        assert_eq!(Signal::Constant { value: 0.42 }.at(123.0), 0.42);
        assert!(
            Signal::Steps {
                levels: vec![],
                hold_s: 1.0
            }
            .validate()
            .is_err()
        );
        assert!(
            Signal::Steps {
                levels: vec![1.0],
                hold_s: 0.0
            }
            .validate()
            .is_err()
        );
    }

    #[test]
    fn random_multisine_uses_interleaved_uncorrelated_lines() {
        let e = Excitation::random_multisine(9, 0.3, 0.2, 0.8, 0.5).expect("valid");
        let (Signal::Multisine(v), Signal::Multisine(w)) = (&e.v_ref, &e.w_ref) else {
            panic!("multisines expected");
        };
        // f_max 0.5 Hz → harmonic 30 → N = 29.
        assert_eq!(
            v.harmonics(),
            (0..15).map(|k| 1 + 2 * k).collect::<Vec<_>>().as_slice()
        );
        assert_eq!(
            w.harmonics(),
            (1..15).map(|k| 2 * k).collect::<Vec<_>>().as_slice()
        );
        let n = 6000;
        let p = RANDOM_MULTISINE_PERIOD_S;
        let (mut sv, mut sw, mut svw, mut vmax, mut wmax) = (0.0, 0.0, 0.0, 0.0f64, 0.0f64);
        for j in 0..n {
            let (a, b) = e.at(p * j as f64 / n as f64);
            let a = a - 0.3;
            sv += a * a;
            sw += b * b;
            svw += a * b;
            vmax = vmax.max(a.abs());
            wmax = wmax.max(b.abs());
        }
        assert!(
            svw.abs() / (sv * sw).sqrt() < 1e-12,
            "correlation {}",
            svw / (sv * sw).sqrt()
        );
        assert_relative_eq!(vmax, 0.2, max_relative = 1e-3);
        assert_relative_eq!(wmax, 0.8, max_relative = 1e-3);
        assert!(Excitation::random_multisine(9, 0.3, 0.2, 0.8, 0.04).is_err());
    }

    #[test]
    fn crest_factor_of_sampled_sine_and_square() {
        let n = 1000;
        let sine: Vec<f64> = (0..n)
            .map(|j| 3.0 + (2.0 * PI * j as f64 / n as f64).sin())
            .collect();
        assert_relative_eq!(crest_factor(&sine), 2f64.sqrt(), max_relative = 1e-12);
        let square: Vec<f64> = (0..n).map(|j| if j < n / 2 { 1.0 } else { -1.0 }).collect();
        assert_relative_eq!(crest_factor(&square), 1.0, max_relative = 1e-12);
        assert!(crest_factor(&[1.0]).is_nan());
    }

    #[test]
    fn excitation_round_trips_through_toml() {
        let cases = [
            Excitation::thesis_pioneer(),
            Excitation::thesis_regression(),
            Excitation::random_multisine(4, 0.3, 0.2, 0.8, 0.5).expect("valid"),
            Excitation {
                v_ref: Signal::Steps {
                    levels: vec![0.1, 0.35, -0.2],
                    hold_s: 3.0,
                },
                w_ref: Signal::Chirp {
                    offset: 0.1,
                    amplitude: 1.0 / 3.0,
                    f0_hz: 0.01,
                    f1_hz: 1.5,
                    duration_s: 120.0,
                },
            },
            Excitation {
                v_ref: Signal::Constant { value: 0.25 },
                w_ref: Signal::multisine(MultisineSpec {
                    offset: 0.0,
                    amplitude: 1.0,
                    f_min_hz: 0.02,
                    f_max_hz: 1.0,
                    lines: 30,
                    period_s: 50.0,
                    phases: Phases::Schroeder,
                })
                .expect("valid"),
            },
        ];
        for e in cases {
            let text = toml::to_string(&e).expect("serialises");
            let back: Excitation = toml::from_str(&text).expect("parses");
            assert_eq!(back, e, "{text}");
            assert_eq!(back.at(12.3), e.at(12.3));
        }
    }

    #[test]
    fn hand_written_toml_parses_and_typos_are_rejected() {
        let text = r#"
            [v_ref]
            type = "multisine"
            offset = 0.3
            amplitude = 0.15
            f_min_hz = 0.01
            f_max_hz = 0.5
            lines = 50
            period_s = 100.0
            phases = { type = "random", seed = 12 }

            [w_ref]
            type = "sum_of_sines"
            offset = 0.0
            terms = [[0.5, 1.0], [0.25, 0.3]]
        "#;
        let e: Excitation = toml::from_str(text).expect("parses");
        let Signal::Multisine(m) = &e.v_ref else {
            panic!("multisine expected")
        };
        assert_eq!(m.harmonics().len(), 50);
        assert_eq!(m.spec().phases, Phases::Random { seed: 12 });
        assert_relative_eq!(e.w_ref.at(2.0), 0.5 * 2f64.sin() + 0.25 * 0.6f64.sin());

        for bad in [
            // unknown field in a struct variant
            "[v_ref]\ntype = \"constant\"\nvalue = 1.0\nvalu = 2.0\n[w_ref]\ntype = \"constant\"\nvalue = 0.0\n",
            // unknown field in a newtype variant
            "[v_ref]\ntype = \"sum_of_sines\"\noffset = 0.0\nterms = []\nextra = 1\n[w_ref]\ntype = \"constant\"\nvalue = 0.0\n",
            // unknown variant
            "[v_ref]\ntype = \"prbs\"\n[w_ref]\ntype = \"constant\"\nvalue = 0.0\n",
            // invalid multisine (too many lines) is rejected while parsing
            "[v_ref]\ntype = \"multisine\"\noffset = 0.0\namplitude = 1.0\nf_min_hz = 0.1\nf_max_hz = 0.2\nlines = 5\nperiod_s = 10.0\nphases = { type = \"schroeder\" }\n[w_ref]\ntype = \"constant\"\nvalue = 0.0\n",
        ] {
            assert!(toml::from_str::<Excitation>(bad).is_err(), "{bad}");
        }
    }
}
