//! Stopping a drive on the batch answer's intervals (issue 18, sequential identification;
//! `accuracy_of = "batch"` in a run config).
//!
//! The online estimator's intervals ([`crate::online::OnlineTheta::relative_half_width`])
//! are those of a recursive equation-error regression; the answer a run reports is the batch
//! identification of the whole drive (output error by default), whose intervals can be several
//! times narrower on the same data (a design that maximises the output-error information puts
//! its lines near the bandwidth, where the filtered regression learns θ1 slowly). With
//! `accuracy_of = "batch"` a run therefore identifies the recording so far every `every_s` of
//! drive time, on another thread, exactly as it will at the end, and stops at the first check
//! whose 95 % intervals of θ1, θ2, θ4, θ6 are within the target:
//!
//! ```text
//! w = max_{i ∈ {1,2,4,6}} 1.96 σ̂_i / |θ̂_i| ≤ accuracy
//! ```
//!
//! A check's answer is taken `lag_s` of drive time after it started (the drive waits for it
//! there if it is not done, so a simulated run is the same on any machine); the stop is at that
//! sample, and the recording keeps the samples driven meanwhile (the final identification uses
//! them all, so its intervals are at most the check's).

use std::sync::Arc;
use std::thread::JoinHandle;

use wheelid_core::Recording;

use crate::identify::Identification;

/// The identification a check runs on the recording so far (the run's own, with its model,
/// solver, estimators and settings).
pub type Identify = Arc<dyn Fn(&Recording) -> anyhow::Result<Identification> + Send + Sync>;

/// One batch check of a drive.
#[derive(Debug, Clone, PartialEq)]
pub struct BatchCheck {
    /// Drive time the check started \[s\] (the recording up to there was identified).
    pub started_s: f64,
    /// Samples identified.
    pub samples: usize,
    /// θ1, θ2, θ4, θ6 and the largest relative half-width of their 95 % intervals \[-\]; or
    /// why the identification gave none (the drive goes on).
    pub outcome: Result<([f64; 4], f64), String>,
}

/// A check running on another thread.
struct Pending {
    started_s: f64,
    samples: usize,
    handle: JoinHandle<anyhow::Result<Identification>>,
}

/// Stops a drive once the batch identification's intervals reach a target (module docs).
pub struct BatchStop {
    accuracy: f64,
    every_s: f64,
    lag_s: f64,
    identify: Identify,
    next_s: f64,
    pending: Option<Pending>,
    /// Every check so far, in order.
    pub checks: Vec<BatchCheck>,
}

/// The relative half-width of the 95 % intervals of θ1, θ2, θ4, θ6 of `id` (the first six
/// parameters of a model extending eq. 2.19) and those four θ.
///
/// # Errors
/// A model whose first six parameters are not θ1…θ6; an interval that is not finite.
pub fn half_width(id: &Identification) -> Result<([f64; 4], f64), String> {
    let names = id.param_names.iter().take(6).map(String::as_str);
    if !names.eq(["theta1", "theta2", "theta3", "theta4", "theta5", "theta6"]) {
        return Err(format!(
            "the model's parameters {:?} are not θ1…θ6 of eq. 2.19",
            id.param_names
        ));
    }
    let theta = [0, 1, 3, 5].map(|i| id.theta[i]);
    let w = [0, 1, 3, 5]
        .iter()
        .map(|&i| 1.96 * id.std_err[i] / id.theta[i].abs())
        .fold(0.0, f64::max);
    if w.is_finite() {
        Ok((theta, w))
    } else {
        Err(format!("an interval is not finite (θ̂ = {:?})", id.theta))
    }
}

impl BatchStop {
    /// Checks every `every_s` of drive time (the first at `every_s`), each answer taken
    /// `lag_s` after it started, aiming at `accuracy` (relative half-width of the 95 %
    /// intervals).
    ///
    /// # Errors
    /// `accuracy` not in (0, 1); not 0 < `lag_s` < `every_s`.
    pub fn new(
        accuracy: f64,
        every_s: f64,
        lag_s: f64,
        identify: Identify,
    ) -> anyhow::Result<Self> {
        if !(accuracy > 0.0 && accuracy < 1.0) {
            anyhow::bail!("accuracy = {accuracy} must be in (0, 1)");
        }
        if !(every_s.is_finite() && lag_s.is_finite() && lag_s > 0.0 && lag_s < every_s) {
            anyhow::bail!("every_s = {every_s} and lag_s = {lag_s} need 0 < lag_s < every_s");
        }
        Ok(Self {
            accuracy,
            every_s,
            lag_s,
            identify,
            next_s: every_s,
            pending: None,
            checks: Vec::new(),
        })
    }

    /// The target \[-\].
    pub fn accuracy(&self) -> f64 {
        self.accuracy
    }

    /// At drive time `t` \[s\]: takes a check's answer once its lag has passed (waiting for it
    /// if needed), and starts one on `so_far()` (the recording up to `t`) when one is due.
    /// Returns whether the last answer taken reached the target (then the drive stops).
    pub fn poll(&mut self, t: f64, so_far: impl FnOnce() -> Option<Recording>) -> bool {
        if let Some(reached) = self.take(t) {
            return reached;
        }
        if self.pending.is_none()
            && t >= self.next_s
            && let Some(rec) = so_far()
        {
            self.next_s = t + self.every_s;
            let identify = Arc::clone(&self.identify);
            let samples = rec.len();
            self.pending = Some(Pending {
                started_s: t,
                samples,
                handle: std::thread::spawn(move || identify(&rec)),
            });
        }
        false
    }

    /// The pending check's answer once due: whether it reached the target.
    fn take(&mut self, t: f64) -> Option<bool> {
        let due = self
            .pending
            .as_ref()
            .is_some_and(|p| t >= p.started_s + self.lag_s);
        let p = due.then(|| self.pending.take()).flatten()?;
        let outcome = match p.handle.join() {
            Ok(Ok(id)) => half_width(&id),
            Ok(Err(e)) => Err(format!("{e:#}")),
            Err(_) => Err("the identification panicked".into()),
        };
        let reached = matches!(outcome, Ok((_, w)) if w <= self.accuracy);
        self.checks.push(BatchCheck {
            started_s: p.started_s,
            samples: p.samples,
            outcome,
        });
        Some(reached)
    }
}

impl Drop for BatchStop {
    /// A check still running is waited for (it owns its copy of the recording).
    fn drop(&mut self) {
        if let Some(p) = self.pending.take() {
            let _ = p.handle.join();
        }
    }
}
