//! Step 5 of the diagnosis: screen the nominees — where each fit starts ([`Search`]) and
//! the training cost there, which orders the fits.

use super::*;

/// Where a candidate's fit starts: θ, bounds, held parameters, and the training cost there
/// (the screen that orders the fits).
#[derive(Clone)]
pub(super) struct Start {
    pub(super) theta: Vec<f64>,
    pub(super) bounds: Vec<(f64, f64)>,
    pub(super) pinned: Vec<usize>,
    pub(super) cost: f64,
}

/// The start of `nominee`'s fit from its fingerprint's guess: dead times by a grid, Gauss–
/// Newton steps shortened by a line search, inactive channels held at their null. `Err` if the
/// guess is no such physics.
pub(super) fn start_candidate(
    data: &Data,
    cur: &Current,
    nominee: &Nominee,
) -> std::result::Result<Start, String> {
    let c = nominee.pattern.candidate;
    let mut cands = cur.candidates.clone();
    cands.push(c);
    let model = data.model(&cands);
    let base = cur.theta.len();
    let (t_lo, t_hi) = data.span();
    let margin = 0.05 * (t_hi - t_lo);
    let mut bounds = model_bounds(&cur.candidates, (t_lo + margin, t_hi - margin));
    let cb = c.effect().bounds((t_lo + margin, t_hi - margin));
    let search = c.effect().search();
    let guess = inside(&nominee.pattern.guess, &cb);
    // A friction or a loss that the residual asks to be negative is no such physics.
    if c.effect().channels() == (EffectChannels::Each { positive: true })
        && nominee.pattern.inactive.len() == 2
    {
        return Err(format!(
            "its pattern asks for negative {} and {} ({:.3e}, {:.3e})",
            c.params()[0].name,
            c.params()[1].name,
            nominee.pattern.guess[0],
            nominee.pattern.guess[1]
        ));
    }
    let frame = data.frame();
    let mut theta = cur.theta.clone();
    theta.extend_from_slice(&guess);
    let training_cost = |th: &[f64]| {
        simulate_all(&model, th, &data.recs, &cur.initial)
            .map_or(f64::INFINITY, |y| frame.residuals(&y).norm_squared())
    };
    // A Gauss–Newton step from the null can overshoot far (a pattern nearly absorbed by θ):
    // it is shortened to the best of a few fractions by the training cost.
    if matches!(search, Search::Smooth | Search::ChangeTime) {
        shorten_step(&mut theta, cur, nominee, base, &training_cost);
    }
    // A force linear in its one parameter enters the regression as one more column: θ1…θ6 and
    // the parameter by least squares together, the better start kept (a strong effect
    // distorts the nominal θ far from where the fit of the extended model can reach).
    if let Some(joint) = joint_regression(data, c, base, &theta)
        && training_cost(&joint) < training_cost(&theta)
    {
        theta = joint;
    }
    // A limit's probe level is a rough reading of the data: scaled on a grid first (its
    // least cost kept: the start's, unless θ moves after it).
    let mut screened = None;
    if search.is_limit() {
        let (scaled, cost) = scaled_limit(&theta, cur, nominee, &training_cost);
        theta = scaled;
        screened = Some((theta.clone(), cost));
    }
    // A dead time is searched on a grid first: its cost has many local minima.
    if search == Search::DeadTime {
        theta[base] = dead_time_grid(&theta, base, data.dt, &training_cost);
    }
    bounds.extend(cb);
    let mut pinned = cur.pinned.clone();
    for &j in &nominee.pattern.inactive {
        pinned.push(base + j);
        theta[base + j] = c.effect().null(&cur.theta, 0.0)[j];
    }
    if let Some(reason) = idle_limit(&data.recs, c, &theta[base..], |j| {
        pinned.contains(&(base + j))
    }) {
        return Err(reason);
    }
    // A change time is not fitted by gradient: the training cost is flat while it sweeps a
    // validation block. It is held, θ fitted, then the time scanned on a fine grid with that θ
    // (the middle of the flat minimum taken), and θ fitted again if it moved.
    if search == Search::ChangeTime {
        pinned.push(base);
    }
    let cost = match screened {
        Some((th, cost)) if same_bits(&th, &theta) => cost,
        _ => training_cost(&theta),
    };
    Ok(Start {
        theta,
        bounds,
        pinned,
        cost,
    })
}

/// `guess` moved inside the candidate's bounds `cb` by a thousandth of their span (10⁻⁶ where
/// a bound is infinite); a value without a bound is kept as it is.
fn inside(guess: &[f64], cb: &[(f64, f64)]) -> Vec<f64> {
    let mut out = guess.to_vec();
    for (g, &(lo, hi)) in out.iter_mut().zip(cb) {
        let span = if hi.is_finite() && lo.is_finite() {
            1e-3 * (hi - lo)
        } else {
            1e-6
        };
        *g = g.clamp(lo + span, hi - span);
    }
    out
}

/// A limit's start `theta` (the model in hand's parameters, then the nominee's) scaled on
/// [`level_grid`] over its probed levels (a limit may have a parameter that is no level, as
/// a mix); the probe simulated its fractions of the level, so a scale whose θ is one of them
/// to the bit has its cost already. Returns the scaled θ and its training cost.
fn scaled_limit(
    theta: &[f64],
    cur: &Current,
    nominee: &Nominee,
    training_cost: &(dyn Fn(&[f64]) -> f64 + Sync),
) -> (Vec<f64>, f64) {
    let base = cur.theta.len();
    let active: Vec<usize> = (nominee.pattern.param_of_col.iter().copied())
        .filter(|j| !nominee.pattern.inactive.contains(j))
        .collect();
    let probed = |th: &[f64]| {
        let (held, own) = th.split_at(base.min(th.len()));
        let same = |(vals, _): &&(Vec<f64>, f64)| same_bits(own, vals);
        same_bits(held, &cur.theta)
            .then(|| nominee.pattern.probed.iter().find(same).map(|&(_, c)| c))
            .flatten()
    };
    level_grid(theta, base, &active, training_cost, &probed)
}

/// Why a limit `c` whose screened start (its parameters `levels`, those `held` left out) binds
/// on no sample of `recs` in any channel it acts on ([`wheelid_core::Effect::binding`]) is not
/// fitted; `None` for a limit that binds somewhere, or an effect that is no limit. The level
/// grid found no level at which it acts, and a fit from there has no gradient in its levels
/// but through the shortened-lag start of a rate limit ([`fit_candidate`]). On the six tuning
/// seeds (singles and clean in three conventions, window-end pairs) 271 such starts were
/// fitted for 1 828 s of diagnosis (a rate limit beside a traction limit: 38 s a fit); 256
/// were refused, 15 passed as a rival of a dead time and lost to it; without them every
/// run names the same effects with the same parameters and fits.
fn idle_limit(
    recs: &[Recording],
    c: Candidate,
    levels: &[f64],
    held: impl Fn(usize) -> bool,
) -> Option<String> {
    let bound = (0..c.params().len())
        .filter(|&j| !held(j))
        .map(|j| c.effect().binding(recs, j, levels[j]))
        .collect::<Option<Vec<f64>>>()?;
    (!bound.is_empty() && bound.iter().all(|&f| f == 0.0)).then(|| {
        "not fitted: at its screened start it binds on no sample (the level grid found no \
         level at which it acts)"
            .into()
    })
}

/// A Gauss–Newton step from the null can overshoot far (a pattern nearly absorbed by θ): the
/// candidate's parameters in `theta` moved to the best of a few fractions of the step by
/// `cost` (inactive channels stay at their null).
fn shorten_step(
    theta: &mut [f64],
    cur: &Current,
    nominee: &Nominee,
    base: usize,
    cost: &dyn Fn(&[f64]) -> f64,
) {
    let c = nominee.pattern.candidate;
    let null = c.effect().null(&cur.theta, theta[base]);
    let step: Vec<f64> = (0..null.len())
        .map(|j| {
            if nominee.pattern.inactive.contains(&j) {
                0.0
            } else {
                theta[base + j] - null[j]
            }
        })
        .collect();
    let mut best = (f64::INFINITY, 1.0);
    for frac in [1.0, 0.5, 0.25, 0.1, 0.03, 0.01] {
        let mut th = theta.to_vec();
        for j in 0..null.len() {
            th[base + j] = null[j] + frac * step[j];
        }
        let c = cost(&th);
        if c < best.0 {
            best = (c, frac);
        }
    }
    for j in 0..null.len() {
        theta[base + j] = null[j] + best.1 * step[j];
    }
}

/// θ1…θ6 and the parameter of a force effect linear in its one parameter
/// ([`wheelid_core::Effect::force`] at p = 1 as a regressor column), by weighted least squares
/// on the training samples with the measured accelerations:
/// u_v = θ1 v̇ − θ3 ω² + θ4 v − c φ_v, u_ω = θ2 ω̇ + θ5 v ω + θ6 ω − c φ_ω.
/// `None` for other effects, another candidate already in the model, or an unphysical answer.
fn joint_regression(data: &Data, c: Candidate, base: usize, theta: &[f64]) -> Option<Vec<f64>> {
    let e = c.effect();
    if !e.has_force() || c.params().len() != 1 || base != 6 {
        return None;
    }
    let d = data.track?;
    let mut rows: Vec<[f64; 7]> = Vec::new();
    let mut ys = Vec::new();
    for (r, rec) in data.recs.iter().enumerate() {
        for k in (0..rec.len()).filter(|&k| data.train[r][k]) {
            let (v, w) = (rec.v[k], rec.w[k]);
            let phi = e.force(&[1.0], v, w, d).f;
            let [wv, ww] = data.weight;
            let [av, aw] = [data.accel[r][0][k], data.accel[r][1][k]];
            rows.push([av * wv, 0.0, -w * w * wv, v * wv, 0.0, 0.0, -phi[0] * wv]);
            ys.push(rec.v_ref[k] * wv);
            rows.push([0.0, aw * ww, 0.0, 0.0, v * w * ww, w * ww, -phi[1] * ww]);
            ys.push(rec.w_ref[k] * ww);
        }
    }
    let x = DMatrix::from_fn(rows.len(), 7, |i, j| rows[i][j]);
    let y = nalgebra::DVector::from_vec(ys);
    let sol = x.svd(true, true).solve(&y, 1e-12).ok()?;
    let physical = [0, 1, 3, 5].iter().all(|&i| sol[i] > 0.0) && sol[6] >= 0.0;
    physical.then(|| {
        let mut th = theta.to_vec();
        th[..6].copy_from_slice(&sol.as_slice()[..6]);
        th[base] = sol[6];
        th
    })
}

/// A dead time (θ[base]) by `cost` on the guess and a geometric grid from half a sample `dt`
/// to 1.5 s (its cost has many local minima).
fn dead_time_grid(theta: &[f64], base: usize, dt: f64, cost: &dyn Fn(&[f64]) -> f64) -> f64 {
    let mut th = theta.to_vec();
    let mut best = (f64::INFINITY, theta[base]);
    let mut grid = vec![theta[base]];
    let mut d = 0.5 * dt;
    while d <= 1.5 {
        grid.push(d);
        d *= 1.4;
    }
    for d in grid {
        th[base] = d;
        let c = cost(&th);
        if c < best.0 {
            best = (c, d);
        }
    }
    best.1
}

/// θ with a limit's `active` channels (0: v, 1: ω) scaled: their level (θ[base + j], unless
/// it never binds) by `level`, their θ1 or θ2 (θ[j]) by `lag`.
pub(super) fn scaled(
    theta: &[f64],
    base: usize,
    active: &[usize],
    level: f64,
    lag: f64,
) -> Vec<f64> {
    let mut th = theta.to_vec();
    for &j in active {
        if th[base + j] < NEVER {
            th[base + j] *= level;
        }
        th[j] *= lag;
    }
    th
}

/// A limit's level scaled by the best of a few factors (0.5…2) by `cost`, with its cost;
/// `known`: the cost at a θ where it has been computed already (the same θ to the bit, so
/// the simulation would give it again), `None` elsewhere.
pub(super) fn level_grid(
    theta: &[f64],
    base: usize,
    active: &[usize],
    cost: &(dyn Fn(&[f64]) -> f64 + Sync),
    known: &(dyn Fn(&[f64]) -> Option<f64> + Sync),
) -> (Vec<f64>, f64) {
    // One simulation per scale not known, on as many threads (an expensive model's start is
    // the last to finish while the other candidates' are done).
    let scales = [1.0, 0.5, 0.7, 0.85, 1.2, 1.5, 2.0];
    let costs: Vec<f64> = std::thread::scope(|sc| {
        let handles: Vec<_> = scales
            .iter()
            .map(|&f| {
                sc.spawn(move || {
                    let th = scaled(theta, base, active, f, 1.0);
                    known(&th).unwrap_or_else(|| cost(&th))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or(f64::INFINITY))
            .collect()
    });
    let mut best = (costs[0], 1.0);
    for (&c, &f) in costs.iter().zip(&scales).skip(1) {
        if c < best.0 {
            best = (c, f);
        }
    }
    (scaled(theta, base, active, best.1, 1.0), best.0)
}

/// Whether two parameter vectors are the same to the bit (a cost computed at one is the
/// other's).
pub(super) fn same_bits(a: &[f64], b: &[f64]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A setpoint rate limit binds where a command steps by more than the limit allows in one
    /// period: commands stepping by 0.1 m/s and 1 rad/s every 0.1 s need 1 m/s², 10 rad/s².
    #[test]
    fn a_limit_that_binds_nowhere_at_its_start_is_not_fitted() {
        let t: Vec<f64> = (0..40).map(|k| 0.1 * k as f64).collect();
        let v_ref: Vec<f64> = (0..40).map(|k| 0.1 * (k % 2) as f64).collect();
        let w_ref: Vec<f64> = (0..40).map(|k| (k % 2) as f64).collect();
        let rec = Recording::new("steps", t, v_ref.clone(), w_ref.clone(), v_ref, w_ref)
            .expect("valid recording");
        let recs = [rec];
        let rate = Candidate::ACCELERATION_LIMIT;
        let free = |_: usize| false;
        // Above what any step needs in both channels: idle.
        assert!(idle_limit(&recs, rate, &[1.5, 15.0], free).is_some());
        // Binding in ω only, or in v only: fitted.
        assert!(idle_limit(&recs, rate, &[1.5, 5.0], free).is_none());
        assert!(idle_limit(&recs, rate, &[0.5, 15.0], free).is_none());
        // A held channel does not count: ω binds but is held, v does not.
        assert!(idle_limit(&recs, rate, &[1.5, 5.0], |j| j == 1).is_some());
        // No limit: never idle.
        assert!(idle_limit(&recs, Candidate::INPUT_DELAY, &[0.1], free).is_none());
    }

    /// A limit probed at one level simulated its guesses themselves (`Pattern::probed`): each
    /// cost kept is the training cost simulated anew at that θ to the bit, so the level grid
    /// takes it where a scale lands on one. The simulator's Khepera III, 60 s, the velocity
    /// saturated.
    #[test]
    fn a_limit_probed_at_one_level_hands_its_cost_to_the_screen() {
        use wheelid_robots::effects::{Effects, VelocitySaturation};
        use wheelid_robots::{RobotProfile, SimSettings, simulate_recording};
        let robot = RobotProfile::khepera3();
        let exc = robot.multisine(3).expect("valid multisine");
        let effects = Effects {
            velocity_saturation: Some(VelocitySaturation {
                v_max: 0.35 * robot.v_max,
                w_max: 10.0 * robot.w_max,
            }),
            ..Effects::default()
        };
        let sim = SimSettings {
            duration_s: 60.0,
            seed: 3,
            effects,
            ..SimSettings::default()
        };
        let rec = simulate_recording(&robot, &exc, &sim).expect("simulates");
        let settings = DiagnoseSettings::default();
        let (data, fit) = prepare(&[rec], &wheelid_models::VwPd, &settings).expect("prepared");
        let mut cur = nominal_current(&data, &fit).expect("nominal simulates");
        cur.jacobian = None;
        let mut known = 0;
        for c in [Candidate::VELOCITY_SATURATION, Candidate::EFFORT_CLAMP] {
            let model = data.model(&[c]);
            for p in patterns(c, &data, &cur).expect("the limit acts") {
                assert!(p.probed.iter().any(|(g, _)| same_bits(g, &p.guess)));
                for (vals, cost) in &p.probed {
                    let th = [&cur.theta[..], &vals[..]].concat();
                    let anew = simulate_all(&model, &th, &data.recs, &cur.initial)
                        .map(|y| data.frame().residuals(&y).norm_squared())
                        .expect("simulates");
                    assert_eq!(
                        cost.to_bits(),
                        anew.to_bits(),
                        "{}: {cost} vs {anew}",
                        c.name()
                    );
                    known += 1;
                }
            }
        }
        // The saturation binds in v alone: one level, probed at three fractions, each pattern
        // carrying all three.
        assert!(known >= 9, "{known} probed costs");
    }

    /// The level grid simulates only the scales whose θ is not known: with the full level's
    /// and its 0.7 and 0.85 scales known (as a probe's fractions leave them), four of the seven
    /// scales are simulated, the known costs are used as given, and the least cost wins.
    #[test]
    fn the_level_grid_simulates_only_unknown_scales() {
        use std::sync::atomic::{AtomicUsize, Ordering};
        let theta = [0.3, 0.2, 0.0, 1.0, 0.0, 1.0, 0.4];
        let calls = AtomicUsize::new(0);
        // A cost least at level 0.4 × 0.7 (known, so only the known cost can make it win).
        let cost = |th: &[f64]| {
            calls.fetch_add(1, Ordering::Relaxed);
            (th[6] - 0.28).abs() + 1.0
        };
        let known_at = [1.0, 0.7, 0.85].map(|f| scaled(&theta, 6, &[0], f, 1.0));
        let known = |th: &[f64]| {
            known_at
                .iter()
                .position(|k| same_bits(k, th))
                .map(|i| [5.0, 0.5, 4.0][i])
        };
        let (best, c) = level_grid(&theta, 6, &[0], &cost, &known);
        assert_eq!(calls.load(Ordering::Relaxed), 4);
        assert_eq!(c, 0.5);
        assert!(same_bits(&best, &known_at[1]));
    }
}
