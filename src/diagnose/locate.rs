//! Where the misfit lives: per channel, the free-run residual e = y − ŷ is broken down by
//! lag (its cross-correlation with each command, Ljung §16.6), by frequency band (share of the
//! residual's power and its ratio to the output's power in the band), by operating region
//! (RMS of e in the region over the RMS of e everywhere) and by time window.

use serde::Serialize;
use wheelid_core::Recording;
use wheelid_core::residual::{self, Independence, Whiteness};

use super::score::Outputs;

/// Frequency bands \[Hz\] of the breakdown (the last one ends at Nyquist).
const BANDS: [f64; 5] = [0.0, 0.1, 0.3, 1.0, 3.0];

/// A region or window's share of the misfit.
#[derive(Debug, Clone, Serialize)]
pub struct Share {
    /// What it is (`v > 0`, `large |ω|`, `seg1.csv 40–50 s`, …).
    pub name: String,
    /// Fraction of the samples in it.
    pub fraction: f64,
    /// RMS of the residual in it over the RMS everywhere (> 1: the misfit gathers there).
    pub rms_ratio: f64,
}

/// A frequency band's part in the misfit.
#[derive(Debug, Clone, Serialize)]
pub struct Band {
    /// Lower edge \[Hz\].
    pub from_hz: f64,
    /// Upper edge \[Hz\].
    pub to_hz: f64,
    /// Share of the residual's power in this band.
    pub residual_share: f64,
    /// Residual power over output power in this band (error-to-signal ratio).
    pub error_to_signal: f64,
}

/// One channel's residual tests and breakdown.
#[derive(Debug, Clone, Serialize)]
pub struct ChannelLocation {
    /// `v` or `w`.
    pub channel: String,
    /// RMS of the residual [channel unit].
    pub rms: f64,
    /// Residual whiteness (Ljung–Box).
    pub whiteness: Whiteness,
    /// Residual–command independence, against `v_ref` then `w_ref`.
    pub independence: Vec<Independence>,
    /// Lags of the largest cross-correlation with `v_ref`, `w_ref` \[s\] (> 0: the residual
    /// follows the command).
    pub peak_lag_s: Vec<f64>,
    /// Breakdown by frequency band.
    pub bands: Vec<Band>,
    /// Breakdown by operating region, largest ratio first.
    pub regions: Vec<Share>,
    /// The time windows where the residual is largest (at most 3, ratio ≥ 1.5).
    pub windows: Vec<Share>,
}

/// The residual-analysis breakdown of the validation samples.
#[derive(Debug, Clone, Serialize)]
pub struct Location {
    /// Lags tested each side \[samples\].
    pub max_lag: usize,
    /// Sample period \[s\].
    pub dt: f64,
    /// v then ω.
    pub channels: Vec<ChannelLocation>,
}

impl Location {
    /// The independence tests' p-values in (channel, command) order.
    pub fn p_values(&self) -> Vec<f64> {
        self.channels
            .iter()
            .flat_map(|c| c.independence.iter().map(|t| t.p_value))
            .collect()
    }

    /// One line on where the misfit lives in channel `c`.
    pub fn summary(&self, c: usize) -> String {
        let ch = &self.channels[c];
        let mut parts = Vec::new();
        let band = ch
            .bands
            .iter()
            .max_by(|a, b| a.residual_share.total_cmp(&b.residual_share));
        if let Some(b) = band {
            parts.push(format!(
                "{:.0} % of its power at {}–{} Hz",
                100.0 * b.residual_share,
                b.from_hz,
                if b.to_hz.is_finite() {
                    format!("{:.1}", b.to_hz)
                } else {
                    "Nyquist".into()
                }
            ));
        }
        let regions: Vec<String> = ch
            .regions
            .iter()
            .filter(|r| r.rms_ratio >= 1.3)
            .take(3)
            .map(|r| format!("{} ×{:.1}", r.name, r.rms_ratio))
            .collect();
        if !regions.is_empty() {
            parts.push(format!("regions {}", regions.join(", ")));
        }
        let windows: Vec<String> = ch.windows.iter().map(|w| w.name.clone()).collect();
        if !windows.is_empty() {
            parts.push(format!("windows {}", windows.join(", ")));
        }
        parts.join("; ")
    }
}

fn rms(x: impl Iterator<Item = f64>) -> f64 {
    let (s, n) = x.fold((0.0, 0usize), |(s, n), v| (s + v * v, n + 1));
    if n == 0 { 0.0 } else { (s / n as f64).sqrt() }
}

/// The `q` quantile of |x| (0 for no samples).
fn quantile(x: &[f64], q: f64) -> f64 {
    wheelid_core::effect::abs_quantile(x.iter().copied(), q)
}

/// Power per band of a series sampled every `dt` (periodogram).
fn band_power(x: &[f64], dt: f64) -> Vec<f64> {
    let n = x.len();
    let mut out = vec![0.0; BANDS.len()];
    let Some(power) = wheelid_core::signal::periodogram(x) else {
        return out;
    };
    for (k, p) in power.iter().enumerate().skip(1) {
        let f = k as f64 / (n as f64 * dt);
        let b = BANDS.iter().rposition(|&lo| f >= lo).unwrap_or(0);
        out[b] += p;
    }
    out
}

/// Measured channel `c` (v, ω) of a recording.
fn channel(rec: &Recording, c: usize) -> &[f64] {
    if c == 0 { &rec.v } else { &rec.w }
}

/// Command of channel `c` (v_ref, ω_ref) of a recording.
fn command(rec: &Recording, c: usize) -> &[f64] {
    if c == 0 { &rec.v_ref } else { &rec.w_ref }
}

/// The breakdown of the residuals on the samples where `keep` is true (the validation
/// blocks), concatenated over recordings; `max_lag` lags each side.
pub(crate) fn locate(
    recs: &[Recording],
    sim: &Outputs,
    keep: &[Vec<bool>],
    dt: f64,
    max_lag: usize,
) -> Location {
    let pick = |f: &dyn Fn(&Recording, usize, usize) -> f64| -> Vec<f64> {
        let mut out = Vec::new();
        for (r, (rec, m)) in recs.iter().zip(keep).enumerate() {
            out.extend((0..rec.len()).filter(|&k| m[k]).map(|k| f(rec, r, k)));
        }
        out
    };
    let meas = |c: usize| pick(&|rec, _, k| channel(rec, c)[k]);
    let resid = |c: usize| pick(&|rec, r, k| channel(rec, c)[k] - sim[r][c][k]);
    let cmd = |c: usize| pick(&|rec, _, k| command(rec, c)[k]);
    // Largest change of the commands over the last second, relative to their range.
    let back = (1.0 / dt).round().max(1.0) as usize;
    let scale: Vec<[f64; 2]> = recs
        .iter()
        .map(|r| [0, 1].map(|c| quantile(command(r, c), 0.99) + 1e-9))
        .collect();
    let change = pick(&|rec, r, k| {
        let k0 = k.saturating_sub(back);
        (0..2)
            .map(|c| {
                let u = command(rec, c);
                u[k0..=k]
                    .iter()
                    .fold(0.0f64, |a, x| a.max((x - u[k]).abs()))
                    / scale[r][c]
            })
            .sum()
    });
    let (v, w, vr, wr) = (meas(0), meas(1), cmd(0), cmd(1));
    let vw: Vec<f64> = v.iter().zip(&w).map(|(a, b)| (a * b).abs()).collect();
    let (vmax, wmax) = (quantile(&v, 0.99), quantile(&w, 0.99));
    let (w75, vw75, ch90) = (quantile(&w, 0.75), quantile(&vw, 0.75), {
        let mut c = change.clone();
        c.sort_by(f64::total_cmp);
        c.get((c.len() as f64 * 0.9) as usize)
            .copied()
            .unwrap_or(0.0)
    });
    let regions: Vec<Region<'_>> = vec![
        ("v > 0", Box::new(|k| v[k] > 0.0)),
        ("v < 0", Box::new(|k| v[k] < 0.0)),
        ("ω > 0", Box::new(|k| w[k] > 0.0)),
        ("ω < 0", Box::new(|k| w[k] < 0.0)),
        ("large |ω|", Box::new(|k| w[k].abs() >= w75 && w75 > 0.0)),
        (
            "large commanded change",
            Box::new(|k| change[k] >= ch90 && ch90 > 0.0),
        ),
        (
            "low speed",
            Box::new(|k| v[k].abs() < 0.1 * vmax && w[k].abs() < 0.1 * wmax),
        ),
        ("high v·ω", Box::new(|k| vw[k] >= vw75 && vw75 > 0.0)),
    ];
    let n = v.len();
    let residuals = [resid(0), resid(1)];
    let mut tests =
        residual::independence_all(&[&residuals[0], &residuals[1]], &[&vr, &wr], max_lag)
            .into_iter();
    let channels = (0..2)
        .map(|c| {
            let e = &residuals[c];
            let y = if c == 0 { &v } else { &w };
            let all = rms(e.iter().copied());
            let independence: Vec<Independence> = tests.next().unwrap_or_default();
            ChannelLocation {
                channel: ["v", "w"][c].into(),
                rms: all,
                whiteness: residual::whiteness(e, max_lag),
                peak_lag_s: independence
                    .iter()
                    .map(|t| t.peak_lag as f64 * dt)
                    .collect(),
                independence,
                bands: bands(e, y, dt),
                regions: shares(&regions, e, n, all),
                windows: windows(recs, sim, keep, c, all, dt),
            }
        })
        .collect();
    Location {
        max_lag,
        dt,
        channels,
    }
}

/// A region of the operating space: its name and which samples are in it.
type Region<'a> = (&'a str, Box<dyn Fn(usize) -> bool + 'a>);

/// The residual `e`'s share of its power in each of [`BANDS`], and its power over the
/// measured signal `y`'s there (periodograms at sample period `dt` \[s\]).
fn bands(e: &[f64], y: &[f64], dt: f64) -> Vec<Band> {
    let (pe, py) = (band_power(e, dt), band_power(y, dt));
    let total: f64 = pe.iter().sum::<f64>().max(1e-300);
    (0..BANDS.len())
        .map(|b| Band {
            from_hz: BANDS[b],
            to_hz: BANDS.get(b + 1).copied().unwrap_or(0.5 / dt),
            residual_share: pe[b] / total,
            error_to_signal: pe[b] / py[b].max(1e-300),
        })
        .collect()
}

/// The residual `e`'s RMS in each region with at least 10 of the `n` samples, over its RMS
/// `all` everywhere, largest first.
fn shares(regions: &[Region<'_>], e: &[f64], n: usize, all: f64) -> Vec<Share> {
    let mut shares: Vec<Share> = regions
        .iter()
        .filter_map(|(name, f)| {
            let idx: Vec<usize> = (0..n).filter(|&k| f(k)).collect();
            (idx.len() >= 10 && all > 0.0).then(|| Share {
                name: (*name).into(),
                fraction: idx.len() as f64 / n as f64,
                rms_ratio: rms(idx.iter().map(|&k| e[k])) / all,
            })
        })
        .collect();
    shares.sort_by(|a, b| b.rms_ratio.total_cmp(&a.rms_ratio));
    shares
}

/// The (at most three) windows of the kept samples where channel `c`'s residual RMS is at
/// least 1.5 times the RMS everywhere; windows are a twentieth of a recording, at least 5 s.
fn windows(
    recs: &[Recording],
    sim: &Outputs,
    keep: &[Vec<bool>],
    c: usize,
    all: f64,
    dt: f64,
) -> Vec<Share> {
    let total: usize = keep.iter().flatten().filter(|&&b| b).count();
    let mut out = Vec::new();
    for (r, (rec, m)) in recs.iter().zip(keep).enumerate() {
        let len = ((rec.len() / 20).max((5.0 / dt) as usize)).max(1);
        let y = if c == 0 { &rec.v } else { &rec.w };
        let name = rec.source.file_name().map_or_else(
            || rec.source.display().to_string(),
            |s| s.to_string_lossy().into(),
        );
        let mut k0 = 0;
        while k0 < rec.len() {
            let k1 = (k0 + len).min(rec.len());
            let idx: Vec<usize> = (k0..k1).filter(|&k| m[k]).collect();
            if idx.len() * 2 >= len && all > 0.0 {
                let ratio = rms(idx.iter().map(|&k| y[k] - sim[r][c][k])) / all;
                out.push(Share {
                    name: format!("{name} {:.0}–{:.0} s", rec.t[k0], rec.t[k1 - 1]),
                    fraction: idx.len() as f64 / total.max(1) as f64,
                    rms_ratio: ratio,
                });
            }
            k0 = k1;
        }
    }
    out.sort_by(|a, b| b.rms_ratio.total_cmp(&a.rms_ratio));
    out.retain(|s| s.rms_ratio >= 1.5);
    out.truncate(3);
    out
}
