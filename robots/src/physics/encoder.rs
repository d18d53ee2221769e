//! The wheel encoders: what the host reads of each wheel.
//!
//! An encoder counts whole ticks of the wheel's angle relative to the chassis (it sees the
//! wheel, not the body: a slipping wheel is counted as turning):
//!
//! ```text
//! angle reported = ⌊a / q⌋ · q,   q = 2π / ticks_per_rev       (quantisation on)
//! angle reported = a                                            (off: exact angles)
//! ```
//!
//! and the host may add white noise of standard deviation σ [m/s] to each wheel speed it
//! reports (r·ω_i + n_i), drawn from its own seeded stream.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rand_distr::{Distribution, Normal};
use wheelid_core::{Error, Result};

/// Quantisation and noise of the two wheel encoders.
#[derive(Debug, Clone)]
pub struct Encoders {
    /// Angle of one tick \[rad\], or `None` for exact angles.
    tick: Option<f64>,
    noise: Option<(ChaCha8Rng, Normal<f64>)>,
}

impl Encoders {
    /// Encoders of `ticks_per_rev` ticks per revolution (quantising when `quantise`), with
    /// white noise of standard deviation `noise_std` [m/s] on each reported wheel speed, drawn
    /// from a stream seeded by `seed`.
    ///
    /// # Errors
    /// [`Error::InvalidSetting`] if `ticks_per_rev` is not finite and positive (when
    /// quantising) or `noise_std` is negative or not finite.
    pub fn new(ticks_per_rev: f64, quantise: bool, noise_std: f64, seed: u64) -> Result<Self> {
        if quantise && !(ticks_per_rev.is_finite() && ticks_per_rev > 0.0) {
            return Err(Error::InvalidSetting(format!(
                "ticks_per_rev = {ticks_per_rev} must be finite and > 0"
            )));
        }
        if !(noise_std.is_finite() && noise_std >= 0.0) {
            return Err(Error::InvalidSetting(format!(
                "wheel_noise_std = {noise_std} must be ≥ 0"
            )));
        }
        let noise = if noise_std > 0.0 {
            let n =
                Normal::new(0.0, noise_std).map_err(|e| Error::InvalidSetting(e.to_string()))?;
            Some((ChaCha8Rng::seed_from_u64(seed.wrapping_add(0x5eed)), n))
        } else {
            None
        };
        Ok(Self {
            tick: quantise.then(|| 2.0 * std::f64::consts::PI / ticks_per_rev),
            noise,
        })
    }

    /// The angles (right, left) \[rad\] as the encoders report them.
    pub fn read(&self, angle: [f64; 2]) -> [f64; 2] {
        match self.tick {
            Some(q) => angle.map(|a| (a / q).floor() * q),
            None => angle,
        }
    }

    /// A reported wheel speed [m/s]: `rate` [rad/s] × `radius` \[m\], plus the noise if any.
    pub fn speed(&mut self, rate: f64, radius: f64) -> f64 {
        let n = match &mut self.noise {
            Some((rng, n)) => n.sample(rng),
            None => 0.0,
        };
        rate * radius + n
    }
}
