//! The markdown report of a batch (part of the issue-15 harness, `main.rs`): confusion
//! matrices, how the effects were realised, the share exactly right with Clopper–Pearson
//! intervals, false alarms, masked pairs, magnitudes and times.

use super::*;

/// Two-sided 95 % Clopper–Pearson interval of x successes in n trials.
pub fn clopper_pearson(x: usize, n: usize) -> (f64, f64) {
    if n == 0 {
        return (0.0, 1.0);
    }
    let (xf, nf) = (x as f64, n as f64);
    let q = |a: f64, b: f64, p: f64| Beta::new(a, b).map_or(f64::NAN, |d| d.inverse_cdf(p));
    let lo = if x == 0 {
        0.0
    } else {
        q(xf, nf - xf + 1.0, 0.025)
    };
    let hi = if x == n {
        1.0
    } else {
        q(xf + 1.0, nf - xf, 0.975)
    };
    (lo, hi)
}

fn pct(x: usize, n: usize) -> String {
    if n == 0 {
        return "—".into();
    }
    let (lo, hi) = clopper_pearson(x, n);
    format!(
        "{x}/{n} = {:.1} % [{:.1}, {:.1}]",
        100.0 * x as f64 / n as f64,
        100.0 * lo,
        100.0 * hi
    )
}

fn median(x: &mut [f64]) -> f64 {
    if x.is_empty() {
        return f64::NAN;
    }
    x.sort_by(f64::total_cmp);
    let n = x.len();
    if n % 2 == 1 {
        x[n / 2]
    } else {
        0.5 * (x[n / 2 - 1] + x[n / 2])
    }
}

/// A markdown confusion matrix of `recs` (rows: true effects incl. `clean`, a pair counting in
/// both its rows; columns: each named candidate, `nothing`, `unexplained`), with the rows' runs,
/// exactly-right counts and mean validation fits.
fn confusion(out: &mut String, recs: &[&Record], title: &str) {
    if recs.is_empty() {
        return;
    }
    let mut cols: BTreeSet<String> = wheelid::models::Candidate::names()
        .into_iter()
        .map(String::from)
        .collect();
    for r in recs {
        cols.extend(r.named.iter().cloned());
    }
    let cols: Vec<String> = cols.into_iter().collect();
    let mut rows: Vec<String> = vec!["clean".into()];
    rows.extend(effect_names().into_iter().map(String::from));
    let _ = writeln!(out, "\n### Confusion matrix — {title}\n");
    let _ = writeln!(
        out,
        "Rows: true effect (a pair counts in both its rows); columns: runs naming that candidate \
         (a run naming two counts in two columns), naming nothing, leaving something unexplained; \
         failed runs are left out.\n"
    );
    let mut head = String::from("| true \\ named | runs | right |");
    let mut rule = String::from("| --- | ---: | ---: |");
    for c in cols
        .iter()
        .map(String::as_str)
        .chain(["nothing", "unexplained"])
    {
        let _ = write!(head, " {c} |");
        rule.push_str(" ---: |");
    }
    head.push_str(" fit v nominal→final | fit ω nominal→final |");
    rule.push_str(" ---: | ---: |");
    let _ = writeln!(out, "{head}\n{rule}");
    for row in &rows {
        let in_row: Vec<&&Record> = recs
            .iter()
            .filter(|r| {
                r.error.is_none()
                    && (if row == "clean" {
                        r.truth.is_empty()
                    } else {
                        r.truth.contains(row)
                    })
            })
            .collect();
        if in_row.is_empty() {
            continue;
        }
        let n = in_row.len();
        let right = in_row.iter().filter(|r| r.exactly_right).count();
        let mut line = format!("| {row} | {n} | {right} |");
        for c in &cols {
            let k = in_row.iter().filter(|r| r.named.contains(c)).count();
            let _ = write!(
                line,
                " {} |",
                if k == 0 { ".".into() } else { k.to_string() }
            );
        }
        let nothing = in_row.iter().filter(|r| r.named.is_empty()).count();
        let unexpl = in_row.iter().filter(|r| r.unexplained.is_some()).count();
        let mean = |f: &dyn Fn(&Record) -> f64| in_row.iter().map(|r| f(r)).sum::<f64>() / n as f64;
        let _ = writeln!(
            line,
            " {nothing} | {unexpl} | {:.1}→{:.1} | {:.1}→{:.1} |",
            mean(&|r| r.fit_nominal.v),
            mean(&|r| r.fit_final.v),
            mean(&|r| r.fit_nominal.w),
            mean(&|r| r.fit_final.w)
        );
        out.push_str(&line);
    }
}

/// How each effect was realised on the single runs: its visibility against the clean twin, the
/// predicted binding share (limits, clamp, floor) and the runs the backend did not realise
/// physically.
fn realised(out: &mut String, recs: &[&Record]) {
    let singles: Vec<&&Record> = recs.iter().filter(|r| r.kind == "single").collect();
    if singles.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "\n### Effects as realised (single runs)\n\nVisibility: RMS(run − clean run of the same \
         seed)/RMS(clean about its mean), per channel, median (min–max) [%]; predicted share: \
         where a limit, the clamp or the floor was predicted to bind (median); unphysical: the \
         chassis outran its wheels (pose speed > 1.5 × the encoders' largest |v|).\n\n\
         | effect | runs | visibility v | visibility ω | predicted share | unphysical |\n\
         | --- | ---: | ---: | ---: | ---: | ---: |"
    );
    for effect in effect_names() {
        let rs: Vec<&&&Record> = singles.iter().filter(|r| r.truth == [effect]).collect();
        if rs.is_empty() {
            continue;
        }
        let spread = |f: &dyn Fn(&Record) -> f64| {
            let mut x: Vec<f64> = rs.iter().map(|r| f(r)).collect();
            let (lo, hi) = (
                x.iter().copied().fold(f64::INFINITY, f64::min),
                x.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            );
            format!("{:.2} ({lo:.2}–{hi:.2})", median(&mut x))
        };
        let mut shares: Vec<f64> = rs
            .iter()
            .filter_map(|r| {
                let m = r.truth_params.get(effect)?;
                ["binds_share", "binds_share_v", "slips_share"]
                    .iter()
                    .find_map(|k| m.get(*k).copied())
            })
            .collect();
        let share = if shares.is_empty() {
            "—".to_string()
        } else {
            format!("{:.0} %", 100.0 * median(&mut shares))
        };
        let _ = writeln!(
            out,
            "| {effect} | {} | {} | {} | {share} | {} |",
            rs.len(),
            spread(&|r| r.visibility.v),
            spread(&|r| r.visibility.w),
            rs.iter().filter(|r| r.unphysical).count()
        );
    }
}

/// The markdown report of `recs` (`wall_s`: the whole run's wall time).
pub fn report(recs: &[Record], wall_s: f64) -> String {
    let mut out = String::new();
    header(&mut out, recs, wall_s);
    let ok: Vec<&Record> = recs.iter().filter(|r| r.error.is_none()).collect();
    let singles: Vec<&Record> = ok.iter().copied().filter(|r| r.kind != "pair").collect();
    let pairs: Vec<&Record> = ok.iter().copied().filter(|r| r.kind == "pair").collect();
    confusion(&mut out, &singles, "single effects and clean runs");
    confusion(&mut out, &pairs, "pairs");
    realised(&mut out, &singles);
    exactly_right(&mut out, recs);
    false_alarms(&mut out, &ok);
    magnitudes(&mut out, &ok);
    out
}

/// The report's title, counts and times, and one line per failed run.
fn header(out: &mut String, recs: &[Record], wall_s: f64) {
    let ok: Vec<&Record> = recs.iter().filter(|r| r.error.is_none()).collect();
    let failed = recs.len() - ok.len();
    let count = |k: &str| recs.iter().filter(|r| r.kind == k).count();
    let _ = writeln!(out, "## Diagnosis on the rigid-body backend\n");
    let _ = writeln!(
        out,
        "{} runs ({} clean, {} single, {} pairs), {failed} failed, {} not realised physically; wall time {:.1} s; per run: \
         simulation {:.2} s, diagnosis {:.2} s on average (max {:.1} s).",
        recs.len(),
        count("clean"),
        count("single"),
        count("pair"),
        recs.iter().filter(|r| r.unphysical).count(),
        wall_s,
        ok.iter().map(|r| r.simulate_s).sum::<f64>() / ok.len().max(1) as f64,
        ok.iter().map(|r| r.diagnose_s).sum::<f64>() / ok.len().max(1) as f64,
        ok.iter()
            .map(|r| r.simulate_s + r.diagnose_s)
            .fold(0.0, f64::max)
    );
    for r in recs.iter().filter(|r| r.error.is_some()) {
        let _ = writeln!(
            out,
            "- FAILED {} {} {} seed {}: {}",
            r.profile,
            r.timing,
            r.case,
            r.seed,
            r.error.as_deref().unwrap_or("")
        );
    }
}

/// The share exactly right by group (with intervals), and the pairs with a masked effect.
fn exactly_right(out: &mut String, recs: &[Record]) {
    let _ = writeln!(
        out,
        "\n### Exactly right\n\nNamed set = true set through the table TRUTH (clean: nothing \
         named and nothing unexplained); failed runs count as wrong. 95 % Clopper–Pearson.\n"
    );
    let _ = writeln!(out, "| group | exactly right |\n| --- | --- |");
    let right = |r: &Record| r.error.is_none() && r.exactly_right;
    let mut groups: Vec<(String, Vec<&Record>)> = vec![("all".into(), recs.iter().collect())];
    for kind in ["clean", "single", "pair"] {
        groups.push((
            format!("kind {kind}"),
            recs.iter().filter(|r| r.kind == kind).collect(),
        ));
    }
    let profiles: BTreeSet<&str> = recs.iter().map(|r| r.profile.as_str()).collect();
    for p in &profiles {
        groups.push((
            format!("profile {p}"),
            recs.iter().filter(|r| r.profile == *p).collect(),
        ));
    }
    let timings: BTreeSet<&str> = recs.iter().map(|r| r.timing.as_str()).collect();
    for t in &timings {
        groups.push((
            format!("convention {t}"),
            recs.iter().filter(|r| r.timing == *t).collect(),
        ));
    }
    groups.push((
        "physically realised runs".into(),
        recs.iter().filter(|r| !r.unphysical).collect(),
    ));
    if recs.iter().any(|r| r.kind == "single") {
        groups.push((
            "single effects that leave the nominal residual above the noise floor (> 1×) on a \
             channel"
                .into(),
            recs.iter()
                .filter(|r| r.kind == "single" && r.noise_ratio_nominal.iter().any(|&x| x > 1.0))
                .collect(),
        ));
    }
    if recs.iter().any(|r| r.kind == "pair") {
        groups.push((
            format!("pairs where both effects act (marginal visibility ≥ {MASKED_PERCENT} %)"),
            recs.iter()
                .filter(|r| r.kind == "pair" && r.masked.is_empty())
                .collect(),
        ));
        groups.push((
            "… and of two quantities the encoders can tell apart (not ONE_QUANTITY)".into(),
            recs.iter()
                .filter(|r| r.kind == "pair" && r.masked.is_empty() && !one_quantity(&r.truth))
                .collect(),
        ));
    }
    for (name, g) in &groups {
        if !g.is_empty() {
            let _ = writeln!(
                out,
                "| {name} | {} |",
                pct(g.iter().filter(|r| right(r)).count(), g.len())
            );
        }
    }
    let masked: Vec<&Record> = recs.iter().filter(|r| !r.masked.is_empty()).collect();
    if !masked.is_empty() {
        let _ = writeln!(
            out,
            "\nPairs with a masked effect (marginal visibility < {MASKED_PERCENT} % on both \
             channels; counted above in every group but the last two):\n"
        );
        for r in masked {
            let vis: Vec<String> = r
                .masked
                .iter()
                .map(|e| {
                    let m = r.marginal_visibility.get(e).copied().unwrap_or_default();
                    format!("{e} {:.3}/{:.3} %", m.v, m.w)
                })
                .collect();
            let _ = writeln!(
                out,
                "* {} {} {} seed {}: masked {}; named [{}]",
                r.profile,
                r.timing,
                r.case,
                r.seed,
                vis.join(", "),
                r.named.join(", ")
            );
        }
    }
}

/// False alarms on the clean runs among `ok`.
fn false_alarms(out: &mut String, ok: &[&Record]) {
    let clean: Vec<&Record> = ok.iter().copied().filter(|r| r.kind == "clean").collect();
    if !clean.is_empty() {
        let n = clean.len();
        let named = clean.iter().filter(|r| !r.named.is_empty()).count();
        let unexpl = clean.iter().filter(|r| r.unexplained.is_some()).count();
        let either = clean
            .iter()
            .filter(|r| !r.named.is_empty() || r.unexplained.is_some())
            .count();
        let mismatch = clean.iter().filter(|r| r.mismatch).count();
        let _ = writeln!(
            out,
            "\n### False alarms on clean runs (95 % Clopper–Pearson)\n\n| what | rate |\n| --- | --- |\n\
             | named an effect | {} |\n| left something unexplained | {} |\n| either (false alarm) | {} |\n\
             | declared a mismatch | {} |",
            pct(named, n),
            pct(unexpl, n),
            pct(either, n),
            pct(mismatch, n)
        );
    }
}

/// Magnitude errors per effect and quantity over `ok`.
fn magnitudes(out: &mut String, ok: &[&Record]) {
    let mut mags: BTreeMap<(String, String), (usize, Vec<f64>)> = BTreeMap::new();
    for r in ok {
        for m in &r.magnitudes {
            let e = mags
                .entry((m.effect.clone(), m.quantity.clone()))
                .or_default();
            e.0 += 1;
            if let Some(x) = m.rel_error {
                e.1.push(x.abs());
            }
        }
    }
    if !mags.is_empty() {
        let _ = writeln!(
            out,
            "\n### Magnitudes\n\nRelative error |estimate − truth|/truth over the runs whose \
             true effect was named by an acceptable candidate (ratios: of the deviation from 1).\n\n\
             | effect | quantity | runs | estimated | median error | within 20 % | worst |\n\
             | --- | --- | ---: | ---: | ---: | ---: | ---: |"
        );
        for ((effect, quantity), (n, errs)) in &mut mags {
            if quantity == "n/a" {
                let _ = writeln!(out, "| {effect} | n/a | {n} | — | n/a | n/a | n/a |");
                continue;
            }
            let k = errs.len();
            let within = errs.iter().filter(|&&x| x <= 0.2).count();
            let worst = errs.iter().copied().fold(f64::NAN, f64::max);
            let med = median(errs);
            let f = |x: f64| {
                if x.is_finite() {
                    format!("{:.1} %", 100.0 * x)
                } else {
                    "—".into()
                }
            };
            let _ = writeln!(
                out,
                "| {effect} | {quantity} | {n} | {k} | {} | {within}/{k} | {} |",
                f(med),
                f(worst)
            );
        }
    }
}
