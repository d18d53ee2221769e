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
/// [`Conditioned::valid_range`].
///
/// # Errors
/// [`wheelid_core::Error::TooShort`] if the recording is shorter than the filter padding.
pub fn regression(data: &Conditioned<'_>) -> Result<Vec<ChannelRegression>> {
    let keep = data.valid_range();
    let n = keep.len();
    let w2: Vec<f64> = data.w.iter().map(|w| -w * w).collect();
    let vw: Vec<f64> = data.v.iter().zip(&data.w).map(|(v, w)| v * w).collect();
    let [vf, wf, w2f, vwf, yv, yw]: [Vec<f64>; 6] = data
        .smooth_all(&[&data.v, &data.w, &w2, &vw, &data.v_ref, &data.w_ref])?
        .try_into()
        .map_err(|_| wheelid_core::Error::InvalidSetting("six filtered signals".into()))?;
    drop((w2, vw));
    let dv = data.differentiate(&vf)?;
    let dw = data.differentiate(&wf)?;
    // Each channel's signals are dropped once its rows are built (a 1e6-row run holds one
    // channel's filtered signals less at its peak).
    // X is column-major: its columns' kept rows end to end; y is kept in place.
    let channel = |i: usize, cols: [Vec<f64>; 3], mut y: Vec<f64>| {
        let mut x = Vec::with_capacity(3 * n);
        for c in cols {
            x.extend_from_slice(&c[keep.clone()]);
        }
        y.truncate(keep.end);
        y.drain(..keep.start);
        ChannelRegression {
            channel: CHANNELS[i].name,
            params: CHANNELS[i].params.to_vec(),
            x: DMatrix::from_vec(n, 3, x),
            y: DVector::from_vec(y),
        }
    };
    let v = channel(0, [dv, w2f, vf], yv);
    Ok(vec![v, channel(1, [dw, vwf, wf], yw)])
}
