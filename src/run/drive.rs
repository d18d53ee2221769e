//! Driving a robot (the first layer of a run): read, then send, once per period, with an
//! online estimator fed sample by sample where one is asked for, and the trace it leaves.

use std::path::Path;

use anyhow::{Context as _, Result, anyhow, bail};
use wheelid_core::{Recording, Robot, RobotError};

use crate::observer::Observer;
use crate::online::OnlineTheta;

/// The online estimate after every sample of a drive (n samples each).
#[derive(Debug, Clone, Default)]
pub struct OnlineTrace {
    /// Sample times \[s\].
    pub t: Vec<f64>,
    /// θ̂1…θ̂6 (NaN until a channel maps to θ).
    pub theta: Vec<[f64; 6]>,
    /// Their standard errors.
    pub std_err: Vec<[f64; 6]>,
    /// Change alarms of the v and ω channels at each sample.
    pub change: Vec<[bool; 2]>,
    /// With `stop_when = "accuracy"`: the target, and the time \[s\] it was reached (`None`:
    /// not within the run's duration).
    pub accuracy: Option<(f64, Option<f64>)>,
    /// The excitation's re-designs on the way (`[design]`), in order.
    pub redesigns: Vec<super::RedesignEvent>,
    /// With `accuracy_of = "batch"`: the batch checks on the way, in order.
    pub batch_checks: Vec<super::BatchCheck>,
    /// The estimator's form after its warm-up ([`crate::online::OnlineTheta::form`]).
    pub form: Option<crate::online::OnlineForm>,
}

impl OnlineTrace {
    /// Writes the trace as CSV: `t, theta1…theta6, se1…se6, change_v, change_w`.
    ///
    /// # Errors
    /// The file cannot be written (named).
    pub fn write_csv(&self, path: &Path) -> Result<()> {
        let write = || -> Result<()> {
            let mut w = csv::Writer::from_writer(Vec::new());
            let mut head = vec!["t".to_owned()];
            head.extend((1..=6).map(|i| format!("theta{i}")));
            head.extend((1..=6).map(|i| format!("se{i}")));
            head.extend(["change_v".into(), "change_w".into()]);
            w.write_record(&head)?;
            for k in 0..self.t.len() {
                let mut row = vec![self.t[k].to_string()];
                row.extend(self.theta[k].iter().map(|x| x.to_string()));
                row.extend(self.std_err[k].iter().map(|x| x.to_string()));
                row.extend(self.change[k].iter().map(|&c| u8::from(c).to_string()));
                w.write_record(&row)?;
            }
            let bytes = w.into_inner().map_err(|e| anyhow!("{}", e.error()))?;
            // Whole or not at all.
            wheelid_core::recording::write_atomic(path, &bytes)?;
            Ok(())
        };
        write().with_context(|| format!("writing {}", path.display()))
    }
}

/// Drives `robot` with `excitation` for `duration` seconds (`None`: until it has no more
/// data, as a replayed log):
/// read, then send, once per period; row k = (t_k, the command as the robot takes it, v_k,
/// ω_k, pose_k). Stops the robot at the end, also on error. Reports `driving`, samples done
/// of the samples planned (0: until the end of a log), to `observer` once per sample.
///
/// # Errors
/// The robot's errors; fewer than 10 samples.
pub fn drive(
    robot: &mut dyn Robot,
    excitation: &wheelid_robots::Excitation,
    duration: Option<f64>,
    observer: &dyn Observer,
) -> Result<Recording> {
    drive_online(robot, &mut excitation.clone(), duration, observer, None)
}

/// What a drive estimates on the way: the online estimator, the trace it leaves, and with
/// `accuracy_of = "batch"` the batch check that stops the drive ([`super::BatchStop`]).
pub struct Online {
    /// The recursive estimator, fed every sample.
    pub estimator: OnlineTheta,
    /// θ̂ after every sample, and with an accuracy target when it was reached.
    pub trace: OnlineTrace,
    /// With `accuracy_of = "batch"`: the drive stops on the batch answer's intervals instead
    /// of the online estimator's.
    pub batch: Option<super::BatchStop>,
}

/// [`drive`] with the commands of `commands` (a fixed excitation, or one re-designed on the
/// way: [`super::Redesigner`]), feeding every sample to an online estimator as it comes and
/// keeping its θ̂ in its trace; the observer's message then carries θ̂1, θ̂2. Where the trace
/// carries an accuracy target (`stop_when = "accuracy"`), the drive stops at the first sample
/// at which the estimator is settled and its intervals are within it — or, with a batch check,
/// at the first check whose batch intervals are — and the trace says when (and lists the
/// checks).
///
/// # Errors
/// As [`drive`].
pub fn drive_online(
    robot: &mut dyn Robot,
    commands: &mut dyn super::CommandSource,
    duration: Option<f64>,
    observer: &dyn Observer,
    mut online: Option<&mut Online>,
) -> Result<Recording> {
    let dt = robot.period_s();
    if !(dt.is_finite() && dt > 0.0) {
        bail!("the robot's period {dt} s must be > 0");
    }
    let n = duration.map_or(usize::MAX, |d| (d / dt).round() as usize);
    let planned = duration.map_or(0, |_| n as u64);
    let mut cols: [Vec<f64>; 8] = std::array::from_fn(|_| Vec::with_capacity(n.min(1 << 20)));
    let mut t0 = None;
    let (name, timing) = (robot.name().to_owned(), robot.timing());
    let result = (|| -> Result<()> {
        for k in 0..n {
            let o = match robot.read() {
                Ok(o) => o,
                Err(RobotError::Ended) => break,
                Err(e) => return Err(e.into()),
            };
            let t0 = *t0.get_or_insert(o.t);
            let estimator = online.as_ref().map(|on| &on.estimator);
            let (v_ref, w_ref) = commands.command(o.t - t0, estimator, &o);
            let (v_ref, w_ref) = robot.send(v_ref, w_ref)?;
            for (c, x) in cols.iter_mut().zip([
                o.t,
                v_ref,
                w_ref,
                o.v,
                o.w,
                o.pose.x,
                o.pose.y,
                o.pose.heading,
            ]) {
                c.push(x);
            }
            let Some(on) = online.as_deref_mut() else {
                observer.progress("driving", k as u64 + 1, planned);
                continue;
            };
            let u = on.estimator.update(o.t, v_ref, w_ref, o.v, o.w);
            let th = on.estimator.theta();
            let trace = &mut on.trace;
            trace.t.push(o.t);
            trace.theta.push(th);
            trace.std_err.push(on.estimator.std_err());
            trace.change.push(u.change);
            let msg = format!("driving · online θ̂1 {:.4} θ̂2 {:.4}", th[0], th[1]);
            observer.progress(&msg, k as u64 + 1, planned);
            let Some((target, reached)) = &mut trace.accuracy else {
                continue;
            };
            let done = match &mut on.batch {
                Some(b) => b.poll(o.t - t0, || recording_of(&name, timing, cols.clone()).ok()),
                None => on.estimator.settled() && on.estimator.relative_half_width() <= *target,
            };
            if done {
                *reached = Some(o.t - t0);
                break;
            }
        }
        Ok(())
    })();
    let stopped = robot.stop();
    if let Some(on) = online
        && let Some(b) = &mut on.batch
    {
        on.trace.batch_checks = std::mem::take(&mut b.checks);
    }
    result?;
    stopped?;
    if cols[0].len() < 10 {
        bail!(
            "the robot gave {} samples; at least 10 are needed",
            cols[0].len()
        );
    }
    recording_of(&name, timing, cols)
}

/// The recording of a drive's rows (`t, v_ref, w_ref, v, ω, x, y, ψ`) from the robot `name`
/// under its stamping convention `timing` (unknown stays unsaid, and identification estimates
/// it), its commands held (zero-order hold).
///
/// # Errors
/// Rows a recording refuses (not increasing in time, not finite).
fn recording_of(
    name: &str,
    timing: Option<wheelid_core::Timing>,
    cols: [Vec<f64>; 8],
) -> Result<Recording> {
    let [t, v_ref, w_ref, v, w, x, y, phi] = cols;
    let mut rec = Recording::new(format!("{name} robot"), t, v_ref, w_ref, v, w)?;
    rec.x = Some(x);
    rec.y = Some(y);
    rec.phi = Some(phi);
    rec.set_meta("robot", name);
    rec.set_meta("command_hold", "zoh");
    if let Some(timing) = timing {
        rec.set_timing(timing);
    }
    Ok(rec)
}
