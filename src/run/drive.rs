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

/// [`drive`] with the commands of `commands` (a fixed excitation, or one re-designed on the
/// way: [`super::Redesigner`]), feeding every sample to an online estimator as it comes and
/// keeping its θ̂ in `trace`; the observer's message then carries θ̂1, θ̂2. Where the trace carries an accuracy
/// target (`stop_when = "accuracy"`), the drive stops at the first sample at which the
/// estimator is settled and its intervals are within it, and the trace says when.
///
/// # Errors
/// As [`drive`].
pub fn drive_online(
    robot: &mut dyn Robot,
    commands: &mut dyn super::CommandSource,
    duration: Option<f64>,
    observer: &dyn Observer,
    mut online: Option<(&mut OnlineTheta, &mut OnlineTrace)>,
) -> Result<Recording> {
    let dt = robot.period_s();
    if !(dt.is_finite() && dt > 0.0) {
        bail!("the robot's period {dt} s must be > 0");
    }
    let n = duration.map_or(usize::MAX, |d| (d / dt).round() as usize);
    let planned = duration.map_or(0, |_| n as u64);
    let mut cols: [Vec<f64>; 8] = std::array::from_fn(|_| Vec::with_capacity(n.min(1 << 20)));
    let mut t0 = None;
    let result = (|| -> Result<()> {
        for k in 0..n {
            let o = match robot.read() {
                Ok(o) => o,
                Err(RobotError::Ended) => break,
                Err(e) => return Err(e.into()),
            };
            let t0 = *t0.get_or_insert(o.t);
            let estimator = online.as_ref().map(|(e, _)| &**e);
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
            match online.as_mut() {
                Some((est, trace)) => {
                    let u = est.update(v_ref, w_ref, o.v, o.w);
                    let th = est.theta();
                    trace.t.push(o.t);
                    trace.theta.push(th);
                    trace.std_err.push(est.std_err());
                    trace.change.push(u.change);
                    let msg = format!("driving · online θ̂1 {:.4} θ̂2 {:.4}", th[0], th[1]);
                    observer.progress(&msg, k as u64 + 1, planned);
                    if let Some((target, reached)) = &mut trace.accuracy
                        && est.settled()
                        && est.relative_half_width() <= *target
                    {
                        *reached = Some(o.t - t0);
                        break;
                    }
                }
                None => observer.progress("driving", k as u64 + 1, planned),
            }
        }
        Ok(())
    })();
    let stopped = robot.stop();
    result?;
    stopped?;
    let [t, v_ref, w_ref, v, w, x, y, phi] = cols;
    if t.len() < 10 {
        bail!("the robot gave {} samples; at least 10 are needed", t.len());
    }
    let mut rec = Recording::new(format!("{} robot", robot.name()), t, v_ref, w_ref, v, w)?;
    rec.x = Some(x);
    rec.y = Some(y);
    rec.phi = Some(phi);
    rec.set_meta("robot", robot.name());
    rec.set_meta("command_hold", "zoh");
    // The stamping convention as the backend knows it; unknown stays unsaid, and identification
    // estimates it.
    if let Some(timing) = robot.timing() {
        rec.set_timing(timing);
    }
    Ok(rec)
}
