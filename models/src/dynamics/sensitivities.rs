//! The free run's output sensitivities to (θ1…θ6, v0, ω0) by the forward sensitivity equations
//! of the module doc of [`super`], integrated alongside the state by the same sub-steps; on long
//! recordings in two column groups on two threads (the same numbers).

use nalgebra::DMatrix;
use wheelid_core::{Recording, Result, Sensitivities};

use super::{Planner, Setup, etdrk4_step, for_each_substep, rk4_step, setup};

/// Number of sensitivity columns: θ1…θ6, then v0, ω0.
const NS: usize = 8;
/// The columns in the order they are integrated: (θ1, θ2, θ3, v0), (θ4, θ5, θ6, ω0) — each
/// half one thread's on a long recording, with its initial-state column last, where it is
/// dropped once it has decayed to exactly zero.
const ORDER: [usize; NS] = [0, 1, 2, 6, 3, 4, 5, 7];
/// Columns per thread when a long recording's sensitivities are split in two.
const HALF: usize = NS / 2;
/// Samples from which the sensitivity columns are integrated on two threads (each carries the
/// state and half the columns; the results are the same bit for bit, see
/// [`integrate_columns`]).
const SPLIT_SAMPLES: usize = 20_000;

/// Derivative of the augmented state z = (v, ω, S) for commands u, where S holds the `M`
/// sensitivity columns `OFF … OFF + M − 1` of [`ORDER`] (constants, so that each column's
/// explicit term is chosen when compiling, not per stage), row-major (∂v/∂p…, ∂ω/∂p…).
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
        match ORDER[OFF + j] {
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

/// Integrates (v, ω) with the sensitivity columns `OFF … OFF + M − 1` of [`ORDER`] (state
/// length Z = 2 + 2M) by the sub-steps of [`simulate`](super::simulate), from state `z` at
/// sample `from`, handing each sample's (v, ω, S) — window averages when the recording has
/// them — to `sink(k, z, M)`. With `drop_dead`, stops after the first sample at which the
/// last column (an initial state's: its equation has no explicit term) is exactly zero in
/// both components and returns that sample and the state: the column stays exactly zero from
/// there on (RK4 of a homogeneous linear equation from 0), so the caller goes on without it.
fn integrate_columns<const M: usize, const Z: usize, const OFF: usize>(
    setup: &Setup,
    rec: &Recording,
    (from, mut z): (usize, [f64; Z]),
    drop_dead: bool,
    sink: &mut impl FnMut(usize, &[f64], usize),
) -> Option<(usize, [f64; Z])> {
    let Setup {
        th, n, hold, avg, ..
    } = *setup;
    if from == 0 {
        sink(0, &z, M);
    }
    let inv = [1.0 / th[0], 1.0 / th[1]];
    let f = |z: &[f64; Z], u: (f64, f64)| augmented_rhs::<M, Z, OFF>(&th, inv, z, u);
    let planner = Planner::new(&th);
    for k in from.max(1)..n {
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
            sink(k, &q.map(|x| x / span), M);
        } else {
            sink(k, &z, M);
        }
        if drop_dead && z[2 + M - 1] == 0.0 && z[2 + 2 * M - 1] == 0.0 {
            return Some((k + 1, z));
        }
    }
    None
}

/// The state at sample `k` of a group of M columns without its last (M − 1 columns, Z1 =
/// Z − 2 values).
fn without_last<const Z: usize, const Z1: usize>(z: &[f64; Z], m: usize) -> [f64; Z1] {
    let mut out = [0.0; Z1];
    out[..1 + m].copy_from_slice(&z[..1 + m]);
    out[1 + m..].copy_from_slice(&z[2 + m..Z - 1]);
    out
}

/// The initial augmented state of the group `OFF … OFF + M − 1` of [`ORDER`]: (v0, ω0), and
/// ∂v/∂v0 = ∂ω/∂ω0 = 1 where the group holds them.
fn initial<const M: usize, const Z: usize, const OFF: usize>(setup: &Setup) -> [f64; Z] {
    let mut z = [0.0; Z];
    z[0] = setup.v0;
    z[1] = setup.w0;
    for j in 0..M {
        match ORDER[OFF + j] {
            6 => z[2 + j] = 1.0,
            7 => z[2 + M + j] = 1.0,
            _ => {}
        }
    }
    z
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

/// Writes sample `k` of all the columns (`z`: v, ω, then the `m` columns of [`ORDER`]) into
/// the outputs.
fn write_sample(
    (y, [tv, tw, iv, iw]): (&mut [Vec<f64>; 2], [&mut DMatrix<f64>; 4]),
    k: usize,
    z: &[f64],
    m: usize,
) {
    y[0][k] = z[0];
    y[1][k] = z[1];
    for j in 0..m {
        let (sv, sw) = (z[2 + j], z[2 + m + j]);
        match ORDER[j] {
            p @ 0..6 => {
                tv[(k, p)] = sv;
                tw[(k, p)] = sw;
            }
            p => {
                iv[(k, p - 6)] = sv;
                iw[(k, p - 6)] = sw;
            }
        }
    }
}

/// All eight columns with the state, on the calling thread.
pub(super) fn sensitivities_on_one_thread(
    setup: &Setup,
    rec: &Recording,
) -> ([Vec<f64>; 2], Sensitivities) {
    let (mut y, [mut tv, mut tw, mut iv, mut iw]) = empty_columns(setup.n);
    let z = initial::<NS, { 2 + 2 * NS }, 0>(setup);
    integrate_columns::<NS, { 2 + 2 * NS }, 0>(setup, rec, (0, z), false, &mut |k, z, m| {
        write_sample((&mut y, [&mut tv, &mut tw, &mut iv, &mut iw]), k, z, m);
    });
    into_sensitivities((y, [tv, tw, iv, iw]))
}

/// One thread's half of [`sensitivities_on_two_threads`]: the columns `OFF … OFF + 3` of
/// [`ORDER`], then, once its initial-state column has decayed to zero, the first three alone.
fn half<const OFF: usize>(
    setup: &Setup,
    rec: &Recording,
    sink: &mut impl FnMut(usize, &[f64], usize),
) {
    let z = initial::<HALF, { 2 + 2 * HALF }, OFF>(setup);
    if let Some((k, z)) =
        integrate_columns::<HALF, { 2 + 2 * HALF }, OFF>(setup, rec, (0, z), true, sink)
    {
        let z = without_last::<{ 2 + 2 * HALF }, { 2 * HALF }>(&z, HALF);
        integrate_columns::<{ HALF - 1 }, { 2 * HALF }, OFF>(setup, rec, (k, z), false, sink);
    }
}

/// θ1, θ2, θ3, v0 on one thread (with the outputs), θ4, θ5, θ6, ω0 on another, each
/// integrating its own copy of the state and dropping its initial-state column once that is
/// exactly zero: the numbers of [`sensitivities_on_one_thread`], bit for bit.
pub(super) fn sensitivities_on_two_threads(
    setup: &Setup,
    rec: &Recording,
) -> ([Vec<f64>; 2], Sensitivities) {
    let (mut y, [mut tv, mut tw, mut iv, mut iw]) = empty_columns(setup.n);
    {
        // Each thread writes its own columns: θ1–θ3 and v0, θ4–θ6 and ω0.
        let (mut tv_a, mut tv_b) = tv.columns_range_pair_mut(0..3, 3..6);
        let (mut tw_a, mut tw_b) = tw.columns_range_pair_mut(0..3, 3..6);
        let (mut iv_a, mut iv_b) = iv.columns_range_pair_mut(0..1, 1..2);
        let (mut iw_a, mut iw_b) = iw.columns_range_pair_mut(0..1, 1..2);
        let y = &mut y;
        rayon::join(
            || {
                half::<0>(setup, rec, &mut |k, z, m| {
                    y[0][k] = z[0];
                    y[1][k] = z[1];
                    for j in 0..m {
                        let (sv, sw) = (z[2 + j], z[2 + m + j]);
                        if j < 3 {
                            tv_a[(k, j)] = sv;
                            tw_a[(k, j)] = sw;
                        } else {
                            iv_a[(k, 0)] = sv;
                            iw_a[(k, 0)] = sw;
                        }
                    }
                })
            },
            || {
                half::<HALF>(setup, rec, &mut |k, z, m| {
                    for j in 0..m {
                        let (sv, sw) = (z[2 + j], z[2 + m + j]);
                        if j < 3 {
                            tv_b[(k, j)] = sv;
                            tw_b[(k, j)] = sw;
                        } else {
                            iv_b[(k, 0)] = sv;
                            iw_b[(k, 0)] = sw;
                        }
                    }
                })
            },
        );
    }
    into_sensitivities((y, [tv, tw, iv, iw]))
}
