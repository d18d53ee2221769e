//! The regressor of Laut 2011 eq. 4.1–4.2, shared by both parameterizations:
//!
//! ```text
//! v_ref = [ v̇  −ω²  v ] · [θ1 θ3 θ4]ᵀ
//! ω_ref = [ ω̇  v·ω  ω ] · [θ2 θ5 θ6]ᵀ
//! ```
//!
//! With the conditioning of `wheelid_core::condition`, every column and the command are passed
//! through the same zero-phase filter F: F(v_ref) = θ1·d/dt F(v) − θ3·F(ω²) + θ4·F(v), which
//! holds exactly for noise-free data (F is linear and commutes with d/dt).

use nalgebra::{DMatrix, DVector};
use wheelid_core::{ChannelInfo, ChannelRegression, Conditioned, ParamInfo, Result};

/// The six parameters of eq. 2.19, with the units of Martins' model library.
pub const PARAMS: [ParamInfo; 6] = [
    ParamInfo {
        name: "theta1",
        unit: "s",
        description: "forward inertia time constant (mass, actuator inertia, PD gains)",
    },
    ParamInfo {
        name: "theta2",
        unit: "s",
        description: "rotational inertia time constant (I_z + m b², actuator inertia, PD gains)",
    },
    ParamInfo {
        name: "theta3",
        unit: "s·m/rad²",
        description: "centripetal coupling ω² → v (mass × centre-of-mass offset b)",
    },
    ParamInfo {
        name: "theta4",
        unit: "-",
        description: "forward damping: v_ref/v in steady state (≈ 1)",
    },
    ParamInfo {
        name: "theta5",
        unit: "s/m",
        description: "coupling v·ω → ω (mass × centre-of-mass offset b)",
    },
    ParamInfo {
        name: "theta6",
        unit: "-",
        description: "rotational damping: ω_ref/ω in steady state (≈ 1)",
    },
];

/// The two channels: v uses (θ1, θ3, θ4), ω uses (θ2, θ5, θ6).
pub const CHANNELS: [ChannelInfo; 2] = [
    ChannelInfo {
        name: "v",
        command: "v_ref",
        params: &[0, 2, 3],
    },
    ChannelInfo {
        name: "w",
        command: "w_ref",
        params: &[1, 4, 5],
    },
];

/// Builds the two filtered regressions of eq. 4.2 from conditioned data, on the rows of
/// [`Conditioned::valid_range`]: [`regression_blocks`]' blocks stacked.
///
/// # Errors
/// [`wheelid_core::Error::TooShort`] if the recording is shorter than the filter padding.
pub fn regression(data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
    let mut blocks = Vec::new();
    regression_blocks(data, &mut |b| {
        blocks.push(b);
        Ok(())
    })?;
    Ok(ChannelRegression::stack(blocks))
}

/// A block input ([`wheelid_core::signal::BlockInput`]) filling samples with `f(k)`.
fn fill(f: impl Fn(usize) -> f64 + Sync) -> impl Fn(usize, &mut [f64]) + Sync {
    move |start, out| {
        for (o, k) in out.iter_mut().zip(start..) {
            *o = f(k);
        }
    }
}

/// Neighbours each side that the derivative stencils need (`Central4`: two).
const STENCIL_HALO: usize = 2;

/// The regressions of [`regression`], built block by block from
/// [`Conditioned::smooth_blocks`] and handed to `sink` (one [`ChannelRegression`] per
/// channel, v then ω, a block's rows in [`Conditioned::valid_range`]): the six filtered
/// signals (v, ω, −ω², v·ω, v_ref, ω_ref) are never held whole, and each block's derivatives
/// are those of the whole signal (the stencil reads the block's halo).
///
/// # Errors
/// As [`regression`]; the first error of `sink`.
pub fn regression_blocks(
    data: &Conditioned<'_>,
    sink: &mut dyn FnMut(Vec<ChannelRegression>) -> Result<()>,
) -> Result<()> {
    let keep = data.valid_range();
    // Each input fills a block's samples from the recording (aligned as it goes).
    let v = fill(|k| data.v_at(k));
    let w = fill(|k| data.w_at(k));
    let w2 = fill(|k| -data.w_at(k) * data.w_at(k));
    let vw = fill(|k| data.v_at(k) * data.w_at(k));
    let v_ref = fill(|k| data.v_ref_at(k));
    let w_ref = fill(|k| data.w_ref_at(k));
    let inputs: [wheelid_core::signal::BlockInput<'_>; 6] = [&v, &w, &w2, &vw, &v_ref, &w_ref];
    data.smooth_blocks(inputs, STENCIL_HALO, |block| {
        let rows = block.rows.start.max(keep.start)..block.rows.end.min(keep.end);
        if rows.is_empty() {
            return Ok(());
        }
        let [vf, wf, w2f, vwf, yv, yw] = block.signals;
        let dv = data.differentiate(vf)?;
        let dw = data.differentiate(wf)?;
        // Row k of the whole signal is element k − offset of the block's slices.
        let local = rows.start - block.offset..rows.end - block.offset;
        let channel = |i: usize, cols: [&[f64]; 3], y: &[f64]| {
            let mut x = Vec::with_capacity(3 * local.len());
            for c in cols {
                x.extend_from_slice(&c[local.clone()]);
            }
            ChannelRegression {
                channel: CHANNELS[i].name,
                params: CHANNELS[i].params.to_vec(),
                x: DMatrix::from_vec(local.len(), 3, x),
                y: DVector::from_row_slice(&y[local.clone()]),
            }
        };
        sink(vec![
            channel(0, [&dv, w2f, vf], yv),
            channel(1, [&dw, vwf, wf], yw),
        ])
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use wheelid_core::condition::{ConditionSettings, condition};
    use wheelid_core::{Recording, Timing};

    /// A 200,003-sample window-averaged recording with zero-order-held commands (three
    /// blocks of the default plan at 50 Hz and f_c = 2 Hz): the blocked regression equals the
    /// one built from whole filtered signals as the thesis describes (filter every column,
    /// then differentiate), row by row.
    #[test]
    fn blocks_stack_to_the_regression_of_whole_filtered_signals() {
        let n = 200_003;
        let dt = 0.02;
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let wave = |k: usize, a: f64, b: f64| {
            let s = k as f64 * dt;
            0.3 * (a * s).sin() + 0.1 * (b * s).cos() + 0.01 * (((k * 7919) % 97) as f64 / 97.0)
        };
        let col = |a, b| (0..n).map(|k| wave(k, a, b)).collect::<Vec<f64>>();
        let mut rec = Recording::new(
            "r.csv",
            t,
            col(0.7, 3.1),
            col(1.3, 2.2),
            col(0.69, 3.0),
            col(1.31, 2.1),
        )
        .expect("valid");
        rec.set_timing(Timing::WindowEnd);
        let data = condition(&rec, None, 2.0, &ConditionSettings::default()).expect("conditions");
        let keep = data.valid_range();
        assert!(keep.len() > 2 * (1 << 16), "more than one block");
        let mut blocks = 0;
        let mut got: Vec<Vec<ChannelRegression>> = Vec::new();
        regression_blocks(&data, &mut |b| {
            blocks += 1;
            got.push(b);
            Ok(())
        })
        .expect("regresses");
        assert!(blocks >= 3, "{blocks} blocks");
        let got = ChannelRegression::stack(got);
        // The whole-signal reference.
        let (v, w) = (data.v(), data.w());
        let w2: Vec<f64> = w.iter().map(|w| -w * w).collect();
        let vw: Vec<f64> = v.iter().zip(w).map(|(v, w)| v * w).collect();
        let f = |x: &[f64]| data.smooth(x).expect("smooths");
        let (vf, wf) = (f(v), f(w));
        let want = [
            [
                data.differentiate(&vf).expect("d"),
                f(&w2),
                vf,
                f(data.v_ref()),
            ],
            [
                data.differentiate(&wf).expect("d"),
                f(&vw),
                wf,
                f(data.w_ref()),
            ],
        ];
        for (ch, cols) in want.iter().enumerate() {
            let r = &got[ch];
            assert_eq!(r.y.len(), keep.len());
            let scale = cols.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
            for (i, k) in keep.clone().enumerate() {
                for (j, col) in cols[..3].iter().enumerate() {
                    let d = (r.x[(i, j)] - col[k]).abs();
                    assert!(
                        d <= 1e-12 * scale,
                        "channel {ch} row {k} column {j}: off by {d}"
                    );
                }
                assert!((r.y[i] - cols[3][k]).abs() <= 1e-12 * scale);
            }
        }
    }
}
