//! The physics truth of a run (part of the issue-15 harness, `main.rs`): the random
//! excitation and the effects' magnitudes drawn per seed, where the limits would bind, and
//! each named effect's parameters against the truth.

use super::*;

/// splitmix64: a small, well-mixed generator (the root package has no `rand`).
pub fn splitmix64(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = x;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A uniform number in [0, 1) for (seed, stream, draw): stream = the effect's index in
/// [`TRUTH`], so each effect's magnitude depends on the seed only, not on the case.
pub fn uniform(seed: u64, stream: u64, draw: u64) -> f64 {
    let h = splitmix64(splitmix64(splitmix64(seed) ^ stream.wrapping_mul(0x100_0001)) ^ draw);
    (h >> 11) as f64 / (1u64 << 53) as f64
}

/// The excitation of a run: the physics excitation rule, [`PhysicalProfile::random_multisine`]
/// seeded by the seed.
///
/// # Errors
/// Invalid multisine settings.
pub fn excitation(p: &PhysicalProfile, seed: u64) -> Result<Excitation> {
    Ok(p.random_multisine(seed)?)
}

/// What the excitation demands of the clean robot, per host period, estimated from the map's
/// θ (v and ω follow their commands through first-order lags θ1/θ4, θ2/θ6 under the
/// zero-order-held commands) and the rigid body: wheel forces F_r,l = m v̇/2 ± I ω̇/d
/// (I = I_z + m b² about the axle centre), torques r F + I_e ω̇_i + B_e ω_i, voltages
/// k_b ω_i + R_a τ_i/k_a, friction coefficients |(F_i, m v ω/2)| / (m g (1 − b/x_c)/2). The
/// peaks are at the start of each period (the largest acceleration after a command step).
#[derive(Debug, Clone)]
pub struct Demand {
    /// |Δv_ref|/Δ per period [m/s²].
    pub slope_v: Vec<f64>,
    /// |Δω_ref|/Δ per period [rad/s²].
    pub slope_w: Vec<f64>,
    /// Peak |voltage| over both wheels per period \[V\].
    pub volts: Vec<f64>,
    /// Peak friction coefficient needed over both wheels per period [-].
    pub mu: Vec<f64>,
}

/// [`Demand`] of excitation `exc` on `p` over `duration` seconds; with `rate` (a rate
/// limit's (v̇, ω̇) maxima) the voltages and friction coefficients are those under the
/// setpoints it slews (ten sub-steps a period, the peak of each period kept): a clamp or a
/// floor drawn from the unlimited demand would never bind behind the limit.
pub fn demand(
    p: &PhysicalProfile,
    exc: &Excitation,
    duration: f64,
    rate: Option<(f64, f64)>,
) -> Demand {
    let th = p.theta();
    let dt = p.period_s;
    let (tau_v, tau_w) = (th[0] / th[3], th[1] / th[5]);
    let i_ax = p.i_z + p.m * p.b * p.b;
    let n_wheels = p.m * 9.81 * p.wheel_load_share() / 2.0;
    let n = (duration / dt).floor() as usize;
    let (mut v, mut w) = (0.0, 0.0);
    let mut prev = exc.at(0.0);
    let mut out = Demand {
        slope_v: Vec::with_capacity(n),
        slope_w: Vec::with_capacity(n),
        volts: Vec::with_capacity(n),
        mu: Vec::with_capacity(n),
    };
    // The setpoints the robot's loop sees (the commands, or slewed by the rate limit).
    let mut set = (0.0, 0.0);
    let subs = if rate.is_some() { 10 } else { 1 };
    let h = dt / subs as f64;
    for k in 0..n {
        let (vr, wr) = exc.at(k as f64 * dt);
        out.slope_v.push((vr - prev.0).abs() / dt);
        out.slope_w.push((wr - prev.1).abs() / dt);
        prev = (vr, wr);
        let (mut volts, mut mu) = (0.0f64, 0.0f64);
        for _ in 0..subs {
            set = match rate {
                Some((a_v, a_w)) => (
                    set.0 + (vr - set.0).clamp(-a_v * h, a_v * h),
                    set.1 + (wr - set.1).clamp(-a_w * h, a_w * h),
                ),
                None => (vr, wr),
            };
            let (v_ss, w_ss) = (set.0 / th[3], set.1 / th[5]);
            let (dv, dw) = ((v_ss - v) / tau_v, (w_ss - w) / tau_w);
            for s in [1.0, -1.0] {
                let spin = (v + s * p.d * w / 2.0) / p.r;
                let acc = (dv + s * p.d * dw / 2.0) / p.r;
                let force = p.m * dv / 2.0 + s * i_ax * dw / p.d;
                let torque = p.r * force + p.i_e * acc + p.b_e * spin;
                volts = volts.max((p.k_b * spin + p.r_a * torque / p.k_a).abs());
                mu = mu.max(force.hypot(p.m * v * w / 2.0) / n_wheels);
            }
            v = v_ss + (v - v_ss) * (-h / tau_v).exp();
            w = w_ss + (w - w_ss) * (-h / tau_w).exp();
        }
        out.volts.push(volts);
        out.mu.push(mu);
    }
    out
}

/// The q-quantile of `x` (nearest rank).
pub fn quantile(x: &[f64], q: f64) -> f64 {
    let mut s: Vec<f64> = x.iter().copied().filter(|v| v.is_finite()).collect();
    if s.is_empty() {
        return f64::NAN;
    }
    s.sort_by(f64::total_cmp);
    let i = ((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1);
    s[i]
}

/// Share of `x` above `level`.
fn share_above(x: &[f64], level: f64) -> f64 {
    x.iter().filter(|&&v| v > level).count() as f64 / x.len().max(1) as f64
}

/// Steady losses of speed per N·m of dry friction in each wheel joint, from the drive's torque
/// balance (rigid body, no load): (Δv [m/s] driving straight, Δω [rad/s] turning on the spot).
/// Wheel-PD: Δω_i = R_a F/(k_a (k_P + k_b) + R_a B_e) per wheel; v/ω-PD: Δv = R_a F/(k_a K_PT +
/// (k_a k_b + R_a B_e)/r), Δω = R_a F/(k_a K_PR + (k_a k_b + R_a B_e) d/(2r)).
pub fn friction_loss_per_nm(p: &PhysicalProfile) -> (f64, f64) {
    let back = p.k_a * p.k_b + p.r_a * p.b_e;
    match p.controller {
        Controller::WheelPd { k_p, .. } => {
            let dw_wheel = p.r_a / (p.k_a * k_p + back);
            (p.r * dw_wheel, 2.0 * p.r * dw_wheel / p.d)
        }
        Controller::VwPd { k_pt, k_pr, .. } => (
            p.r_a / (p.k_a * k_pt + back / p.r),
            p.r_a / (p.k_a * k_pr + back * p.d / (2.0 * p.r)),
        ),
    }
}

/// The effects of `spec` with magnitudes drawn from its seed, and per effect its settings and
/// predicted strength (for the records). Ranges (u: a uniform draw of the effect's stream):
///
/// | effect | magnitude |
/// | --- | --- |
/// | latency | (0.5 + 2.5u) host periods |
/// | sensor_delay | (0.5 + 2.5u) host periods |
/// | dead_band | (0.05 + 0.10u) × the median per-period peak voltage ([`Demand`]) |
/// | rate_limit | (0.2 + 0.3u) × the 95th percentile of the command's slope \|Δu\|/Δ, v and ω alike |
/// | voltage_clamp | the (0.80 + 0.15u)-quantile of the per-period peak voltage ([`Demand`]; behind a rate limit, under the setpoints it slews): binds in ~5–20 % of the periods |
/// | gain_sag | fraction 0.1 + 0.2u lost by the run's end |
/// | gain_decay | τ such that 0.1 + 0.2u is lost by the run's end |
/// | amp_gain_right | 0.90 + 0.05u or 1.05 + 0.05u (even/odd second draw) |
/// | tyre_radius_right | 1.02 + 0.03u |
/// | dry_friction_nm | the torque whose steady loss driving straight is (3 + 7u) % of v_amp = 0.3 v_max ([`friction_loss_per_nm`]) |
/// | floor_mu | (0.4 + 0.2u) × the 95th percentile of the per-period peak friction coefficient needed ([`Demand`]; behind a rate limit, under the setpoints it slews; the estimate runs high: the Khepera-like robot slips on ~5–20 % of the rows) |
/// | payload | (0.3 + 0.7u) m, set down at (30 + 40u) % of the run, (0.25 + 0.5u) x_caster ahead of the axle, a cube of side d/3 |
///
/// # Errors
/// An unknown effect name.
#[allow(clippy::type_complexity)]
pub fn draw_effects(
    p: &PhysicalProfile,
    exc: &Excitation,
    spec: &RunSpec,
) -> Result<(PhysicsEffects, BTreeMap<String, BTreeMap<String, f64>>)> {
    let mut fx = PhysicsEffects::default();
    let mut params = BTreeMap::new();
    let need_demand = spec.effects.iter().any(|e| {
        matches!(
            *e,
            "rate_limit" | "voltage_clamp" | "floor_mu" | "dead_band"
        )
    });
    let dem = need_demand.then(|| demand(p, exc, spec.duration_s, None));
    // Behind a rate limit a clamp or a floor is drawn from the demand the limit leaves.
    let mut limited: Option<Demand> = None;
    for &name in &spec.effects {
        let stream = TRUTH
            .iter()
            .position(|(e, _)| *e == name)
            .with_context(|| format!("unknown physics effect {name}"))? as u64;
        let u = |k| uniform(spec.seed, stream, k);
        let mut m = BTreeMap::new();
        let drawn = match dem.as_ref() {
            Some(d)
                if matches!(
                    name,
                    "rate_limit" | "voltage_clamp" | "floor_mu" | "dead_band"
                ) =>
            {
                let d = match (name, fx.rate_limit) {
                    ("rate_limit", _) | (_, None) => d,
                    (_, Some(r)) => &*limited.get_or_insert_with(|| {
                        demand(p, exc, spec.duration_s, Some((r.v_accel, r.w_accel)))
                    }),
                };
                draw_demanded(name, p, d, &u, &mut fx, &mut m)
            }
            _ => draw_plain(name, p, spec.duration_s, &u, &mut fx, &mut m),
        };
        if !drawn {
            bail!("unknown physics effect {name}");
        }
        params.insert(name.to_string(), m);
    }
    Ok((fx, params))
}

/// Draws a rate limit, voltage clamp, dead band or floor friction `name` (table of
/// [`draw_effects`]) from
/// the demand `d` (for a clamp or a floor behind a rate limit, the demand the limit leaves) and
/// the uniform draws `u`, into `fx` and its reported magnitudes `m`; false for another name.
fn draw_demanded(
    name: &str,
    p: &PhysicalProfile,
    d: &Demand,
    u: &dyn Fn(u64) -> f64,
    fx: &mut PhysicsEffects,
    m: &mut BTreeMap<String, f64>,
) -> bool {
    match name {
        "rate_limit" => {
            let frac = 0.2 + 0.3 * u(0);
            let (sv, sw) = (quantile(&d.slope_v, 0.95), quantile(&d.slope_w, 0.95));
            let (a_v, a_w) = (frac * sv, frac * sw);
            fx.rate_limit = Some(RateLimit {
                v_accel: a_v,
                w_accel: a_w,
            });
            m.insert("v_accel".into(), a_v);
            m.insert("w_accel".into(), a_w);
            m.insert("fraction_of_p95_slope".into(), frac);
            m.insert("binds_share_v".into(), share_above(&d.slope_v, a_v));
            m.insert("binds_share_w".into(), share_above(&d.slope_w, a_w));
        }
        "voltage_clamp" => {
            let q = 0.80 + 0.15 * u(0);
            let volts = quantile(&d.volts, q);
            fx.voltage_clamp = Some(volts);
            m.insert("volts".into(), volts);
            // In the effort_clamp's units (its module docs): V r/k_P, V/K_PT.
            let effort = match p.controller {
                Controller::WheelPd { k_p, .. } => volts * p.r / k_p,
                Controller::VwPd { k_pt, .. } => volts / k_pt,
            };
            m.insert("effort_max".into(), effort);
            // The loop's derivative term (`derivative_s`): k_D/k_P; K_DT/K_PT (K_DR/K_PR the ω
            // loop's, about the same on the Pioneer-like profile).
            let derivative = match p.controller {
                Controller::WheelPd { k_p, k_d } => k_d / k_p,
                Controller::VwPd { k_pt, k_dt, .. } => k_dt / k_pt,
            };
            m.insert("derivative_s".into(), derivative);
            m.insert("quantile".into(), q);
            m.insert("binds_share".into(), share_above(&d.volts, volts));
        }
        "dead_band" => {
            let frac = 0.05 + 0.10 * u(0);
            let volts = frac * quantile(&d.volts, 0.5);
            fx.dead_band_v = Some(volts);
            m.insert("volts".into(), volts);
            m.insert("fraction_of_median_peak".into(), frac);
            // In effort units (as the clamp's): V r/k_P, V/K_PT.
            let effort = match p.controller {
                Controller::WheelPd { k_p, .. } => volts * p.r / k_p,
                Controller::VwPd { k_pt, .. } => volts / k_pt,
            };
            m.insert("effort_dead".into(), effort);
        }
        "floor_mu" => {
            let frac = 0.4 + 0.2 * u(0);
            let mu = frac * quantile(&d.mu, 0.95);
            fx.floor_mu = Some(mu);
            m.insert("mu".into(), mu);
            m.insert("fraction_of_p95_demand".into(), frac);
            m.insert("slips_share".into(), share_above(&d.mu, mu));
        }
        _ => return false,
    }
    true
}

/// Draws physics effect `name` that needs no demand (table of [`draw_effects`]) for a run of
/// `duration_s` \[s\] from the uniform draws `u`, into `fx` and its reported magnitudes `m`;
/// false for another name.
fn draw_plain(
    name: &str,
    p: &PhysicalProfile,
    duration_s: f64,
    u: &dyn Fn(u64) -> f64,
    fx: &mut PhysicsEffects,
    m: &mut BTreeMap<String, f64>,
) -> bool {
    match name {
        "latency" => {
            let periods = 0.5 + 2.5 * u(0);
            fx.latency_s = Some(periods * p.period_s);
            m.insert("latency_s".into(), periods * p.period_s);
            m.insert("periods".into(), periods);
        }
        "sensor_delay" => {
            let periods = 0.5 + 2.5 * u(0);
            fx.sensor_delay_s = Some(periods * p.period_s);
            m.insert("sensor_delay_s".into(), periods * p.period_s);
            m.insert("periods".into(), periods);
        }
        "gain_sag" => {
            let f = 0.1 + 0.2 * u(0);
            fx.gain_sag = Some(f);
            m.insert("fraction".into(), f);
            m.insert("rate_per_s".into(), -f / duration_s);
        }
        "gain_decay" => {
            let f = 0.1 + 0.2 * u(0);
            let tau = duration_s / -(1.0 - f).ln();
            fx.gain_decay_tau_s = Some(tau);
            m.insert("tau_s".into(), tau);
            m.insert("fraction_lost".into(), f);
            // The mean rate over the run (a straight line through e^(−t/τ)'s ends).
            m.insert("rate_per_s".into(), -f / duration_s);
        }
        "amp_gain_right" => {
            let g = if u(1) < 0.5 {
                0.90 + 0.05 * u(0)
            } else {
                1.05 + 0.05 * u(0)
            };
            fx.amp_gain_right = Some(g);
            m.insert("gain".into(), g);
        }
        "tyre_radius_right" => {
            let f = 1.02 + 0.03 * u(0);
            fx.tyre_radius_right = Some(f);
            m.insert("factor".into(), f);
        }
        "dry_friction" => {
            let share = 0.03 + 0.07 * u(0);
            let (dv, dw) = friction_loss_per_nm(p);
            let f = share * 0.3 * p.v_max / dv;
            fx.dry_friction_nm = Some(f);
            m.insert("torque_nm".into(), f);
            m.insert("loss_share_of_v_amp".into(), share);
            m.insert("steady_loss_v".into(), f * dv);
            m.insert("steady_loss_w".into(), f * dw);
        }
        "payload" => {
            let pl = Payload {
                mass_kg: (0.3 + 0.7 * u(0)) * p.m,
                at_s: (0.3 + 0.4 * u(1)) * duration_s,
                x_m: (0.25 + 0.5 * u(2)) * p.caster_x,
                size_m: p.d / 3.0,
            };
            fx.payload = Some(pl);
            m.insert("mass_kg".into(), pl.mass_kg);
            m.insert("at_s".into(), pl.at_s);
            m.insert("x_m".into(), pl.x_m);
            m.insert("size_m".into(), pl.size_m);
            m.insert("theta1_loaded_map".into(), pl.loaded(p).theta()[0]);
        }
        _ => return false,
    }
    true
}

/// Magnitude comparisons for every true effect of a run: latency vs `delay_s`; rate limits vs
/// `v_accel_max`, `w_accel_max` (a channel held at its null, ≥ 10⁵, is skipped); the right
/// amplifier's gain or tyre factor vs `ratio` (error of the deviation from 1); dry friction vs
/// `v_coulomb`, `w_coulomb`, `wheel_friction`'s `c_wheel` and `vw_friction`'s `c_v`, `c_w`
/// (the map's θ4, θ6 × the closed-form steady loss, [`friction_loss_per_nm`];
/// `coulomb_friction` acts on v and ω, not
/// per wheel, so its values are a looser match); payload time vs `time_s` and the loaded map's θ1 vs
/// `theta1_after`; a slippery floor's μ g (1 − b/x_c) (the driven wheels' share of the weight)
/// vs `accel_max` and μ (r + 2 I_e/(m r))/x_c (the moment balance of
/// `PhysicalProfile::load_transfer_per_force`) vs `load_transfer`, beside a payload each also
/// loaded ([`truth_after`]: an estimate between the two values is exact, one beyond them is
/// compared with the nearer). Everything else is `n/a`.
pub fn magnitudes(
    p: &PhysicalProfile,
    truth: &BTreeMap<String, BTreeMap<String, f64>>,
    named: &BTreeMap<String, BTreeMap<String, f64>>,
) -> Vec<Magnitude> {
    let mut out = Vec::new();
    let truth_of = |e: &str| truth.get(e);
    for (effect, t) in truth {
        let est = |param: &str| {
            acceptable(effect)
                .iter()
                .find_map(|c| named.get(*c).and_then(|m| m.get(param)).copied())
        };
        let Some(pairs) = comparisons(effect, p, t, truth) else {
            out.push(Magnitude {
                effect: effect.clone(),
                quantity: "n/a".into(),
                truth: None,
                estimate: None,
                truth_after: None,
                rel_error: None,
            });
            continue;
        };
        for (quantity, truth, param, ratio) in pairs {
            let estimate = est(param).filter(|x| x.is_finite() && x.abs() < 1e5);
            let after = truth_after(effect, param, p, t, truth_of("payload"));
            let rel_error = estimate.map(|e| {
                if ratio {
                    ((e - 1.0) - (truth - 1.0)) / (truth - 1.0)
                } else {
                    // Between the values before and after a payload: no error; beyond them,
                    // from the nearer one.
                    let (lo, hi) = after.map_or((truth, truth), |a| (truth.min(a), truth.max(a)));
                    let nearest = e.clamp(lo, hi);
                    (e - nearest) / nearest
                }
            });
            out.push(Magnitude {
                effect: effect.clone(),
                quantity: quantity.into(),
                truth: Some(truth),
                truth_after: after,
                estimate,
                rel_error,
            });
        }
    }
    out
}

/// A slippery floor's true `param` (`accel_max`, `load_transfer`) once the run's `payload`
/// (its drawn values) is on: the loaded statics' μ g (1 − b'/x_c) and the loaded moment
/// balance μ (r + m_p s/(2 m') + 2 I_e/(m' r))/x_c ([`Payload::load_transfer_per_force`]: the
/// cube lifts the centre of mass). The fit gives one value for the whole run; before the
/// report of 1117–1120 the floor's values beside a payload were compared with the unloaded
/// robot's alone, and its load transfer came out 5–35 % above them, 15 % below to 7 % above
/// the loaded one. `None` for anything else.
fn truth_after(
    effect: &str,
    param: &str,
    p: &PhysicalProfile,
    t: &BTreeMap<String, f64>,
    payload: Option<&BTreeMap<String, f64>>,
) -> Option<f64> {
    if effect != "floor_mu" {
        return None;
    }
    let g = |m: &BTreeMap<String, f64>, k: &str| m.get(k).copied();
    let payload = payload?;
    let pl = Payload {
        mass_kg: g(payload, "mass_kg")?,
        at_s: g(payload, "at_s")?,
        x_m: g(payload, "x_m")?,
        size_m: g(payload, "size_m")?,
    };
    let mu = g(t, "mu")?;
    match param {
        "accel_max" => Some(mu * 9.81 * pl.loaded(p).wheel_load_share()),
        "load_transfer" => Some(mu * pl.load_transfer_per_force(p)),
        _ => None,
    }
}

/// What [`magnitudes`] compares for true `effect` (its drawn values `t` on profile `p`):
/// (quantity, true value, the named candidate's parameter, compared as a ratio's deviation
/// from 1), or `None` where nothing is (`n/a`).
fn comparisons(
    effect: &str,
    p: &PhysicalProfile,
    t: &BTreeMap<String, f64>,
    all: &BTreeMap<String, BTreeMap<String, f64>>,
) -> Option<Vec<(&'static str, f64, &'static str, bool)>> {
    let th = p.theta();
    let g = |k: &str| t.get(k).copied().unwrap_or(f64::NAN);
    let (loss_v, loss_w) = (th[3] * g("steady_loss_v"), th[5] * g("steady_loss_w"));
    Some(match effect {
        "latency" => vec![("latency_s vs delay_s", g("latency_s"), "delay_s", false)],
        "dead_band" => vec![(
            "V r/k_P (V/K_PT) vs effort_dead",
            g("effort_dead"),
            "effort_dead",
            false,
        )],
        "sensor_delay" => vec![(
            "sensor_delay_s vs delay_s",
            g("sensor_delay_s"),
            "delay_s",
            false,
        )],
        "rate_limit" => vec![
            ("v_accel vs v_accel_max", g("v_accel"), "v_accel_max", false),
            ("w_accel vs w_accel_max", g("w_accel"), "w_accel_max", false),
        ],
        // Both batteries at once are one drive gain, (1 − f_s t/T) e^(−t/τ): one drift whose
        // mean rate loses 1 − (1 − f_s)(1 − f_d) over the run (the method holds one effect
        // of a quantity; each battery's own rate was compared with it until 1117–1120's
        // report, 35–150 % off where the combined one is 1–9 %).
        "gain_sag" | "gain_decay" => match (all.get("gain_sag"), all.get("gain_decay")) {
            (Some(sag), Some(decay)) => {
                let kept = |m: &BTreeMap<String, f64>, k: &str| {
                    1.0 - m.get(k).copied().unwrap_or(f64::NAN)
                };
                let lost = 1.0 - kept(sag, "fraction") * kept(decay, "fraction_lost");
                // 1/T from this battery's own −f/T.
                let own = if effect == "gain_sag" {
                    "fraction"
                } else {
                    "fraction_lost"
                };
                let per_s = -g("rate_per_s") / g(own);
                vec![(
                    "−(1 − (1 − f_sag)(1 − f_decay))/T (both) vs rate_per_s",
                    -lost * per_s,
                    "rate_per_s",
                    false,
                )]
            }
            _ => vec![(
                "−fraction/T vs rate_per_s",
                g("rate_per_s"),
                "rate_per_s",
                false,
            )],
        },
        "voltage_clamp" => vec![(
            "V r/k_P (V/K_PT) vs effort_max",
            g("effort_max"),
            "effort_max",
            false,
        )],
        "amp_gain_right" => vec![("gain vs right_gain (−1)", g("gain"), "right_gain", true)],
        "tyre_radius_right" => vec![
            (
                "factor vs right_radius (−1)",
                g("factor"),
                "right_radius",
                true,
            ),
            ("factor vs ratio (−1)", g("factor"), "ratio", true),
        ],
        "dry_friction" => vec![
            ("θ4·Δv vs v_coulomb", loss_v, "v_coulomb", false),
            ("θ6·Δω vs w_coulomb", loss_w, "w_coulomb", false),
            ("θ4·Δv vs c_wheel", loss_v, "c_wheel", false),
            ("θ4·Δv vs c_v", loss_v, "c_v", false),
            ("θ6·Δω vs c_w", loss_w, "c_w", false),
        ],
        // The driven wheels carry the weight less the caster's share b/x_c: the floor
        // passes at most μ g (1 − b/x_c). Accelerating moves the load F (r + 2 I_e/(m r))/x_c
        // onto them (`PhysicalProfile::load_transfer_per_force`, borne out by the engine's
        // contact forces).
        "floor_mu" => vec![
            (
                "μ g (1 − b/x_c) vs accel_max",
                g("mu") * 9.81 * p.wheel_load_share(),
                "accel_max",
                false,
            ),
            (
                "μ (r + 2 I_e/(m r))/x_c vs load_transfer",
                g("mu") * p.load_transfer_per_force(),
                "load_transfer",
                false,
            ),
        ],
        "payload" => vec![
            ("at_s vs time_s", g("at_s"), "time_s", false),
            (
                "loaded θ1 vs theta1_after",
                g("theta1_loaded_map"),
                "theta1_after",
                false,
            ),
        ],
        _ => return None,
    })
}
