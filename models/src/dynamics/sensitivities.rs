//! The free run's output sensitivities to (θ1…θ6, v0, ω0) by the forward sensitivity equations
//! of the module doc of [`super`], integrated alongside the state by the same sub-steps; on long
//! recordings in two column groups on two threads (the same numbers).

use nalgebra::DMatrix;
use wheelid_core::{Recording, Result, Sensitivities};

use super::{Planner, Setup, etdrk4_step, for_each_substep, rk4_step, setup};

/// Number of sensitivity columns: θ1…θ6, then v0, ω0.
const NS: usize = 8;
/// Columns per thread when a long recording's sensitivities are split in two.
const HALF: usize = NS / 2;
/// Samples from which the sensitivity columns are integrated on two threads (each carries the
/// state and half the columns; the results are the same bit for bit, see
/// [`integrate_columns`]).
const SPLIT_SAMPLES: usize = 20_000;

/// Derivative of the augmented state z = (v, ω, S) for commands u, where S holds the `M`
/// sensitivity columns `OFF … OFF + M − 1` (constants, so that each column's explicit term is
/// chosen when compiling, not per stage) of (θ1…θ6, v0, ω0), row-major (∂v/∂p…, ∂ω/∂p…).
/// Each column's derivative depends only on (v, ω) and itself, so any split of the columns
/// gives the same numbers.
#[inline]
fn augmented_rhs<const M: usize, const Z: usize, const OFF: usize>(
    theta: &[f64; 6],
    inv: [f64; 2],
    z: &[f64; Z],
    u: (f64, f64),
) -> [f64; Z] {
    let [_, _, t3, t4, t5, t6] = *theta;
    let [i1, i2] = inv;
    let (v, w) = (z[0], z[1]);
    let (dv, dw) = (
        (t3 * w * w - t4 * v + u.0) * i1,
        (-t5 * v * w - t6 * w + u.1) * i2,
    );
    let a = [
        [-t4 * i1, 2.0 * t3 * w * i1],
        [-t5 * w * i2, -(t5 * v + t6) * i2],
    ];
    let mut out = [0.0; Z];
    out[0] = dv;
    out[1] = dw;
    for j in 0..M {
        let (sv, sw) = (z[2 + j], z[2 + M + j]);
        out[2 + j] = a[0][0] * sv + a[0][1] * sw;
        out[2 + M + j] = a[1][0] * sv + a[1][1] * sw;
        // The explicit ∂f/∂θ of eq. 2.19 (module doc), for the columns this group holds.
        match OFF + j {
            0 => out[2 + j] += -dv * i1,
            1 => out[2 + M + j] += -dw * i2,
            2 => out[2 + j] += w * w * i1,
            3 => out[2 + j] += -v * i1,
            4 => out[2 + M + j] += -v * w * i2,
            5 => out[2 + M + j] += -w * i2,
            _ => {}
        }
    }
    out
}

/// Integrates (v, ω) with the sensitivity columns `OFF … OFF + M − 1` (state length Z =
/// 2 + 2M) by the sub-steps of [`simulate`], handing each sample's (v, ω, S) — window
/// averages when the recording has them — to `sink(k, z)`.
fn integrate_columns<const M: usize, const Z: usize, const OFF: usize>(
    setup: &Setup,
    rec: &Recording,
    mut sink: impl FnMut(usize, &[f64; Z]),
) {
    let Setup {
        th,
        v0,
        w0,
        n,
        hold,
        avg,
    } = *setup;
    let mut z = [0.0; Z];
    z[0] = v0;
    z[1] = w0;
    // ∂v/∂v0 and ∂ω/∂ω0 start at 1, where this group holds them.
    if (OFF..OFF + M).contains(&6) {
        z[2 + 6 - OFF] = 1.0;
    }
    if (OFF..OFF + M).contains(&7) {
        z[2 + M + 7 - OFF] = 1.0;
    }
    sink(0, &z);
    let inv = [1.0 / th[0], 1.0 / th[1]];
    let f = |z: &[f64; Z], u: (f64, f64)| augmented_rhs::<M, Z, OFF>(&th, inv, z, u);
    let planner = Planner::new(&th);
    for k in 1..n {
        let mut q = [0.0; Z];
        let span = for_each_substep(rec, k, hold, &planner, |u0, u1, h, exponential| {
            if exponential {
                let lin = [-th[3] * inv[0], -(th[4] * z[0] + th[5]) * inv[1]];
                etdrk4_step(f, lin, &mut z, &mut q, u0, u1, h);
            } else {
                rk4_step(f, &mut z, &mut q, u0, u1, h);
            }
        });
        if avg {
            // As the free run divides, so that its outputs are these bit for bit.
            sink(k, &q.map(|x| x / span));
        } else {
            sink(k, &z);
        }
    }
}

/// Free-run simulation as [`simulate`](super::simulate), with the output sensitivities to θ (n × 6 per channel)
/// and to the initial state (n × 2 per channel), from the forward sensitivity equations in the
/// module doc, integrated by the same RK4 sub-steps. From `SPLIT_SAMPLES` (20,000) samples on, the
/// columns are integrated in two groups on two threads (each with its own copy of the state;
/// the same numbers).
///
/// # Errors
/// As [`simulate`](super::simulate).
pub fn simulate_with_sensitivities(
    theta: &[f64],
    rec: &Recording,
    initial: &[f64],
) -> Result<([Vec<f64>; 2], Sensitivities)> {
    let setup = setup(theta, rec, initial)?;
    Ok(if setup.n < SPLIT_SAMPLES {
        sensitivities_on_one_thread(&setup, rec)
    } else {
        sensitivities_on_two_threads(&setup, rec)
    })
}

/// Output columns: (v, ω), then per channel the θ columns (n × 6) and the initial-state
/// columns (n × 2).
type SensitivityColumns = ([Vec<f64>; 2], [DMatrix<f64>; 4]);

fn empty_columns(n: usize) -> SensitivityColumns {
    (
        [vec![0.0; n], vec![0.0; n]],
        [
            DMatrix::zeros(n, 6),
            DMatrix::zeros(n, 6),
            DMatrix::zeros(n, 2),
            DMatrix::zeros(n, 2),
        ],
    )
}

fn into_sensitivities((y, [tv, tw, iv, iw]): SensitivityColumns) -> ([Vec<f64>; 2], Sensitivities) {
    (
        y,
        Sensitivities {
            theta: vec![tv, tw],
            initial: vec![iv, iw],
        },
    )
}

/// All eight columns with the state, on the calling thread.
pub(super) fn sensitivities_on_one_thread(
    setup: &Setup,
    rec: &Recording,
) -> ([Vec<f64>; 2], Sensitivities) {
    let (mut y, [mut tv, mut tw, mut iv, mut iw]) = empty_columns(setup.n);
    integrate_columns::<NS, { 2 + 2 * NS }, 0>(setup, rec, |k, z| {
        y[0][k] = z[0];
        y[1][k] = z[1];
        for j in 0..NS {
            let (sv, sw) = (z[2 + j], z[2 + NS + j]);
            if j < 6 {
                tv[(k, j)] = sv;
                tw[(k, j)] = sw;
            } else {
                iv[(k, j - 6)] = sv;
                iw[(k, j - 6)] = sw;
            }
        }
    });
    into_sensitivities((y, [tv, tw, iv, iw]))
}

/// θ1…θ4 on one thread (with the outputs), θ5, θ6, v0, ω0 on another, each integrating its own
/// copy of the state: the numbers of [`sensitivities_on_one_thread`], bit for bit.
pub(super) fn sensitivities_on_two_threads(
    setup: &Setup,
    rec: &Recording,
) -> ([Vec<f64>; 2], Sensitivities) {
    let (mut y, [mut tv, mut tw, mut iv, mut iw]) = empty_columns(setup.n);
    {
        let (mut tv_a, mut tv_b) = tv.columns_range_pair_mut(0..HALF, HALF..6);
        let (mut tw_a, mut tw_b) = tw.columns_range_pair_mut(0..HALF, HALF..6);
        let (y, iv, iw) = (&mut y, &mut iv, &mut iw);
        rayon::join(
            || {
                integrate_columns::<HALF, { 2 + 2 * HALF }, 0>(setup, rec, |k, z| {
                    y[0][k] = z[0];
                    y[1][k] = z[1];
                    for j in 0..HALF {
                        tv_a[(k, j)] = z[2 + j];
                        tw_a[(k, j)] = z[2 + HALF + j];
                    }
                })
            },
            || {
                integrate_columns::<HALF, { 2 + 2 * HALF }, HALF>(setup, rec, |k, z| {
                    for j in 0..HALF {
                        let (sv, sw) = (z[2 + j], z[2 + HALF + j]);
                        if HALF + j < 6 {
                            tv_b[(k, j)] = sv;
                            tw_b[(k, j)] = sw;
                        } else {
                            iv[(k, HALF + j - 6)] = sv;
                            iw[(k, HALF + j - 6)] = sw;
                        }
                    }
                })
            },
        );
    }
    into_sensitivities((y, [tv, tw, iv, iw]))
}
