//! A simulation resumed from another's state: the scan of a payload change's time
//! (`wheelid::diagnose` places it with every sample on 33 times across an interval, each a
//! simulation of the whole drive).
//!
//! Two runs of one model whose parameters differ only in the change's time t_s are one run
//! until the earlier of their changes: the merged grid, the state z = (v, ω) and the
//! rate-limited setpoint agree instant by instant, so the later run starts from the recorded
//! one's state at its last grid instant before the scanned interval. After both changes the
//! two follow one law from different states; the dynamics are contracting, and where their
//! state and setpoint agree to the last bit at an instant both grids share, everything after
//! it is the same computation on the same numbers, so the recorded run's values are taken
//! from there. The result is the whole simulation's to the bit; only the instants between
//! the resumption and the meeting are integrated.

use wheelid_core::{Error, Recording, Result, Simulation};

use super::{Cmd, Extended, to_samples};

/// A simulation's state at every instant of its merged grid, recorded by
/// [`Extended::traced`] for [`Extended::resumed`]: the grid, the values there (instants or
/// window averages, before they are read at the samples), the state (v, ω) \[m/s, rad/s\]
/// and the rate-limited setpoint.
#[derive(Clone)]
pub struct Trace(Taped<2, 0>);

impl std::fmt::Debug for Trace {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Trace")
            .field("instants", &self.0.grid.len())
            .finish()
    }
}

/// [`Trace`] of a pass with `N` states and `M` sensitivity columns.
#[derive(Clone)]
pub(super) struct Taped<const N: usize, const M: usize> {
    grid: Vec<f64>,
    values: [Vec<f64>; N],
    states: Vec<([f64; N], Cmd<M>)>,
}

/// What [`Extended::integrate_taped`] does beside integrating.
pub(super) enum Tape<'t, const N: usize, const M: usize> {
    /// Nothing.
    Off,
    /// Records the state at every grid instant.
    Record(Vec<([f64; N], Cmd<M>)>),
    /// Starts at instant `from` of `trace` (the grids agree up to it), and joins `trace` at
    /// the first shared instant after `join_after` \[s\] where the states agree to the bit.
    Resume {
        trace: &'t Taped<N, M>,
        from: usize,
        join_after: f64,
        /// The place in `trace` of the last instant compared.
        at: usize,
        /// The grid instant where the run joined the trace (None: it ran to the end).
        joined: Option<usize>,
    },
}

/// Bitwise equality of two states and setpoints (−0 ≠ +0, and a NaN equals itself: only the
/// same numbers count).
fn same<const N: usize, const M: usize>(a: &([f64; N], Cmd<M>), b: &([f64; N], Cmd<M>)) -> bool {
    fn bits<const N: usize, const M: usize>(
        x: &([f64; N], Cmd<M>),
    ) -> impl Iterator<Item = u64> + '_ {
        let c = &x.1;
        let values = x.0.iter().chain(&c.u).chain([&c.g]);
        values.chain(c.du.iter().flatten()).map(|v| v.to_bits())
    }
    a.1.live == b.1.live && bits(a).eq(bits(b))
}

impl<const N: usize, const M: usize> Tape<'_, N, M> {
    /// Before the loop over the grid, with the run's initial state: records it, or replaces
    /// it (and the values) by the trace's at the resumption; returns the first interval to
    /// integrate.
    pub(super) fn start(
        &mut self,
        grid: &[f64],
        z: &mut [f64; N],
        setpoint: &mut Cmd<M>,
        y: &mut [Vec<f64>; N],
    ) -> usize {
        match self {
            Tape::Off => 1,
            Tape::Record(states) => {
                states.reserve(grid.len());
                states.push((*z, *setpoint));
                1
            }
            Tape::Resume { trace, from, .. } => {
                (*z, *setpoint) = trace.states[*from];
                for (yc, tc) in y.iter_mut().zip(&trace.values) {
                    yc.clear();
                    yc.extend_from_slice(&tc[..=*from]);
                }
                *from + 1
            }
        }
    }

    /// After grid instant `i` (state `z`, setpoint `setpoint`, values `y` up to it): records
    /// the state, or, resuming past `join_after` at an instant the trace shares with the
    /// same state, appends the trace's remaining values and returns `true` (the run is done).
    pub(super) fn after(
        &mut self,
        grid: &[f64],
        i: usize,
        z: &[f64; N],
        setpoint: &Cmd<M>,
        y: &mut [Vec<f64>; N],
    ) -> bool {
        match self {
            Tape::Off => false,
            Tape::Record(states) => {
                states.push((*z, *setpoint));
                false
            }
            Tape::Resume {
                trace,
                join_after,
                at,
                joined,
                ..
            } => {
                let t = grid[i];
                if t <= *join_after {
                    return false;
                }
                while *at + 1 < trace.grid.len() && trace.grid[*at] < t {
                    *at += 1;
                }
                let j = *at;
                // The rest of both grids must be one list for the values to carry over.
                let joins = trace.grid[j].to_bits() == t.to_bits()
                    && same(&(*z, *setpoint), &trace.states[j])
                    && trace.grid[j + 1..] == grid[i + 1..];
                if joins {
                    for (yc, tc) in y.iter_mut().zip(&trace.values) {
                        yc.extend_from_slice(&tc[j + 1..]);
                    }
                    *joined = Some(i);
                }
                joins
            }
        }
    }
}

impl Extended {
    /// [`wheelid_core::DynamicModel::simulate`] with the run's [`Trace`], for
    /// [`Extended::resumed`]; `None` in place of the trace for a model with a traction stage
    /// (its state is not recorded).
    ///
    /// # Errors
    /// As `simulate`.
    pub fn traced(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
    ) -> Result<(Simulation, Option<Trace>)> {
        let (th0, ph, forces) = self.physics(theta)?;
        if ph.traction.is_some() {
            return Ok((
                wheelid_core::DynamicModel::simulate(self, theta, rec, initial)?,
                None,
            ));
        }
        let mut tape: Tape<'_, 2, 0> = Tape::Record(Vec::new());
        let (values, grid, index, avg) =
            self.integrate_taped::<2, 0>(&th0, &ph, &forces, rec, initial, &mut tape)?;
        let Tape::Record(states) = tape else {
            return Err(Error::InvalidSetting("no trace recorded".into()));
        };
        let y = to_samples(&values, &grid, &index, avg);
        Ok((
            y.to_vec(),
            Some(Trace(Taped {
                grid,
                values,
                states,
            })),
        ))
    }

    /// The simulation of θ on `rec` from `initial` — the same, to the bit, as
    /// [`wheelid_core::DynamicModel::simulate`] — given the [`Trace`] of a run whose
    /// parameters differ from θ at most in the payload change's time, both runs' changes
    /// inside `window` = (from, to) \[s\]: resumed from the trace's state at its last grid
    /// instant before `from`, and joined to it where their states meet after `to` (module
    /// docs). A run whose grid does not agree with the trace's up to `from` is simulated
    /// whole.
    ///
    /// # Errors
    /// As `simulate`.
    pub fn resumed(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
        trace: &Trace,
        window: (f64, f64),
    ) -> Result<Simulation> {
        self.resumed_span(theta, rec, initial, trace, window)
            .map(|(y, _)| y)
    }

    /// [`Self::resumed`] with the times \[s\] it integrated from and to (where it joined the
    /// trace, or the run's end); `None` where it simulated whole.
    fn resumed_span(
        &self,
        theta: &[f64],
        rec: &Recording,
        initial: &[f64],
        trace: &Trace,
        (from, to): (f64, f64),
    ) -> Result<(Simulation, Option<(f64, f64)>)> {
        let (th0, ph, forces) = self.physics(theta)?;
        let trace = &trace.0;
        let start = trace.grid.partition_point(|&t| t < from).saturating_sub(2);
        let plain =
            || wheelid_core::DynamicModel::simulate(self, theta, rec, initial).map(|y| (y, None));
        if ph.traction.is_some() {
            return plain();
        }
        let mut tape: Tape<'_, 2, 0> = Tape::Resume {
            trace,
            from: start,
            join_after: to + ph.output_delay.max(0.0),
            at: start,
            joined: None,
        };
        let (values, grid, index, avg) =
            self.integrate_taped::<2, 0>(&th0, &ph, &forces, rec, initial, &mut tape)?;
        // The grids must agree up to the resumption (nothing of θ's moved before it).
        if grid.len() <= start
            || grid[..=start] != trace.grid[..=start]
            || values[0].len() != grid.len()
        {
            return plain();
        }
        let Tape::Resume { joined, .. } = tape else {
            return plain();
        };
        let span = (grid[start], grid[joined.unwrap_or(grid.len() - 1)]);
        Ok((to_samples(&values, &grid, &index, avg).to_vec(), Some(span)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Candidate;
    use wheelid_core::DynamicModel;

    const THETA: [f64; 6] = [0.26, 0.25, -0.05, 0.9965, 0.08, 1.0768];

    /// 100 s at 50 Hz of a two-tone drive, commands held, instants or window averages.
    fn recording(avg: bool) -> Recording {
        super::super::tests::recording_at(avg, 5001, 0.02, |x| {
            (
                0.3 + 0.25 * (1.3 * x).sin(),
                0.8 * (0.7 * x).cos() - 0.3 * (2.3 * x).sin(),
            )
        })
    }

    /// A payload change's time scanned across (40, 55) s: every resumed run is the whole
    /// simulation to the bit — under a dead time, a rate limit, a drift, a measurement delay,
    /// instants and window averages — and integrates from before 40 s to within 10 s of 55 s
    /// (the state meets the traced run's there), not the 100 s drive.
    #[test]
    fn a_resumed_scan_is_the_whole_simulation_to_the_bit() {
        let payload = [47.3, 0.35, 0.3, -0.04, 0.1];
        use Candidate as C;
        let cases: Vec<(Vec<Candidate>, Vec<f64>)> = vec![
            (vec![C::PAYLOAD_CHANGE], vec![]),
            (vec![C::INPUT_DELAY, C::PAYLOAD_CHANGE], vec![0.13]),
            (
                vec![C::ACCELERATION_LIMIT, C::PAYLOAD_CHANGE],
                vec![0.8, 2.0],
            ),
            (vec![C::GAIN_DRIFT, C::PAYLOAD_CHANGE], vec![-0.001]),
            (vec![C::OUTPUT_DELAY, C::PAYLOAD_CHANGE], vec![0.07]),
        ];
        for avg in [false, true] {
            let rec = recording(avg);
            let x0 = [0.1, 0.05];
            for (cands, extra) in &cases {
                let e = Extended::new(cands, 0.34).expect("model");
                let mut th = THETA.to_vec();
                th.extend_from_slice(extra);
                th.extend_from_slice(&payload);
                let at = th.len() - payload.len();
                let (whole, trace) = e.traced(&th, &rec, &x0).expect("simulates");
                assert_eq!(whole, e.simulate(&th, &rec, &x0).expect("simulates"));
                let trace = trace.expect("a trace");
                for ts in [40.0, 41.37, 47.3, 50.0, 54.99] {
                    let mut moved = th.clone();
                    moved[at] = ts;
                    let want = e.simulate(&moved, &rec, &x0).expect("simulates");
                    let (got, span) = e
                        .resumed_span(&moved, &rec, &x0, &trace, (40.0, 55.0))
                        .expect("simulates");
                    let names: Vec<&str> = cands.iter().map(|c| c.name()).collect();
                    assert_eq!(got, want, "{names:?} avg {avg} at {ts}");
                    let (from, end) = span.expect("resumed");
                    assert!(from < 40.0 && from > 39.9, "{names:?} from {from}");
                    assert!(end < 70.0, "{names:?} avg {avg} at {ts}: joined at {end} s");
                }
            }
        }
    }
}
