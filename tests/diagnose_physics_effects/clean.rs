//! Clean runs: no effect realised, nothing named, under every timing convention.

use super::support::*;

/// Clean rigid-body runs of both built-in profiles under every stamping convention (stated in
/// the metadata) declare no mismatch — nothing named, nothing unexplained (the first round's
/// tests may still flag structure that no candidate takes up: Khepera-like window_middle on
/// this seed; the model is then kept): window-middle stamps are restamped before the fit, and
/// residual structure at the 0.1 % level of a 99.9 % fit is no practical mismatch (before these
/// two changes, 5 of 6 such runs on tuning seed 1 left "unexplained" or named an effect).
/// Seed 401, not looked at before.
#[test]
fn clean_runs_under_every_convention_declare_nothing() {
    use wheelid::core::Timing;
    for p in [PhysicalProfile::khepera3(), PhysicalProfile::pioneer3dx()] {
        for timing in [Timing::Instant, Timing::WindowEnd, Timing::WindowMiddle] {
            let d = diagnosed(&p, 401, |s| s.timing = timing);
            let f = &d.nominal.channels;
            println!(
                "{} {}: fits v {:.2} %, ω {:.2} %, mismatch {}",
                p.name,
                timing.name(),
                f.v.fit_percent,
                f.w.fit_percent,
                d.mismatch
            );
            assert!(
                !d.mismatch && d.findings.is_empty() && d.unexplained.is_none(),
                "{} {}: {:?} {:?}",
                p.name,
                timing.name(),
                d.findings,
                d.unexplained
            );
            // The Khepera-like robot's window-averaged encoders (2764 ticks/rev, 20 ms) leave a
            // perfect model a residual of differenced tick counts, lag-1 autocorrelation −½.
            // The floor taken of the measured series counts that noise as white above
            // f_c = 0.3 f_N, so it errs high by √(((1 − a) + sin(πa)/π)/(1 − a)) = 1.17 at
            // a = 0.3: the residual is 0.85 × the floor (1.8 × when the floor was taken of the
            // conditioning's half-sample average, which halves such noise), and beyond the
            // noise the model explains all of v.
            if p.name == "khepera3" && timing != Timing::Instant {
                assert!(
                    (0.75..=1.0).contains(&f.v.noise_ratio),
                    "{}: v residual {:.2} × the floor",
                    timing.name(),
                    f.v.noise_ratio
                );
                assert!(f.v.fit_percent < 99.0 && f.v.noise_corrected_fit_percent > 99.9);
            }
        }
    }
}

/// A clean Pioneer-like run stamped at instants (clean seed 6346, the one false alarm of 600
/// clean runs in the declared report of 1113–1116, looked at after it): its heading, read
/// with the instantaneous speeds summed by the rectangle rule, turned the calmest chunks as a
/// right/left tyre ratio of 0.9722 ± 0.0053 (all chunks 1.0002 ± 0.0041), 5.3 of their
/// standard errors from all chunks', so the slip rule took them and a larger tyre was
/// *measured*, and an amplifier of 0.964 named beside it to cancel it in the dynamics. Summed
/// by the trapezoid, which closes instantaneous speeds' calm chunks far better
/// (`tyre_asymmetry::heading_ratio`), the heading reads 1.0022 ± 0.0004: nothing named.
#[test]
fn a_clean_run_stamped_at_instants_measures_no_tyre() {
    use wheelid::core::Timing;
    let (rec, model) = pioneer_recording(6346, |s| s.timing = Timing::Instant);
    let (d, _) = diagnosed_named(&rec, model.as_ref());
    assert!(
        !d.mismatch && d.findings.is_empty() && d.unexplained.is_none(),
        "{}",
        wheelid::report::diagnosis_text(&d)
    );
}
