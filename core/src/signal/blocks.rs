//! Zero-phase filtering of long signals block by block, in memory that does not grow with them.
//!
//! [`super::sosfiltfilt`] holds the whole signal several times over (its odd extension, the
//! forward pass, the backward pass); for a 1e6-sample run that is tens of MB a signal.
//! [`sosfiltfilt_blocks`] gives the same values block by block, each block's samples with a
//! halo of neighbours (for a derivative stencil), so that a consumer (a regression, a sum)
//! never holds a whole filtered signal:
//!
//! * the **forward pass** is causal: it runs once from the start of the odd extension, its
//!   state carried from block to block (the same arithmetic, in the same order, as the whole
//!   signal's);
//! * the **backward pass** of a block [a, b) starts `lookahead` samples past its end, from the
//!   steady state of the forward output there (as `sosfilt_zi` starts scipy's), and runs down
//!   to a. A stable filter forgets its start: with the lookahead of
//!   [`crate::Conditioned::head_samples`] (80 periods of the cut-off; the slowest pole of an
//!   order-N Butterworth decays at ≥ 0.82 · 2π f_c per second for N ≤ 12) what is left of the
//!   start is below e⁻⁶⁵ of the signal, far under rounding. Where the lookahead reaches the
//!   end, the block runs to the end of the extension and starts exactly as the whole signal's
//!   backward pass does.
//!
//! A signal no longer than one block plus its lookahead is filtered in one block, which is the
//! whole-signal computation. The test holds blocked and whole results to 1e-13 of the signal's
//! scale for blocks far shorter than the default.

use std::ops::Range;

use sci_rs::signal::filter::design::Sos;
use sci_rs::signal::filter::sosfilt_zi_dyn;

use super::sos_padlen;
use crate::error::Error;

/// One input signal of [`sosfiltfilt_blocks`]: `fill(start, out)` writes samples
/// start … start + out.len() − 1 of the signal into `out` (one call a block, not one a sample).
pub type BlockInput<'a> = &'a (dyn Fn(usize, &mut [f64]) + Sync);

/// How [`sosfiltfilt_blocks`] cuts a signal.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockPlan {
    /// Samples a block answers for (≥ 1).
    pub block: usize,
    /// Samples past a block's end (halo included) where its backward pass starts.
    pub lookahead: usize,
    /// Neighbours delivered on each side of a block's samples (clipped at the signal's ends).
    pub halo: usize,
}

impl BlockPlan {
    /// Blocks of at least 2¹⁶ samples and four lookaheads (so the lookahead costs at most a
    /// quarter more forward filtering), for a filter that forgets its start over `lookahead`
    /// samples.
    pub fn for_lookahead(lookahead: usize, halo: usize) -> Self {
        Self {
            block: (1 << 16).max(4 * lookahead),
            lookahead,
            halo,
        }
    }
}

/// One block of [`sosfiltfilt_blocks`]' output.
#[derive(Debug, Clone)]
pub struct FilteredBlock<'a, const S: usize> {
    /// The samples this block answers for, [a, b).
    pub rows: Range<usize>,
    /// The index in the whole signal of each slice's first value: a − halo, clipped at 0.
    pub offset: usize,
    /// The S filtered signals on [offset, min(b + halo, n)).
    pub signals: [&'a [f64]; S],
}

/// One signal's filter state and buffers.
struct Lane {
    /// Forward-pass state at `cursor` (index in the extension, −padlen at the start).
    forward: Vec<Sos<f64>>,
    cursor: isize,
    /// The current block's input, then its forward, then its zero-phase outputs, in place.
    buf: Vec<f64>,
    /// Zero-phase outputs of the current block on [offset, hi).
    out: Vec<f64>,
}

/// Runs the cascade `sos` over `data` in place (forward, or from the last sample to the first
/// when `reverse`), its state carried in `sos`: scipy's `sosfilt` (transposed direct form II),
/// the same operations in the same order as `sci_rs`' `sosfilt_dyn`, with the sections' state
/// in registers for the usual orders.
fn cascade(sos: &mut [Sos<f64>], data: &mut [f64], reverse: bool) {
    cascade_lanes(&mut [sos], &mut [data], reverse);
}

/// Lanes a thread filters side by side ([`cascade_lanes`]).
const LANES: usize = 3;

/// [`cascade`] of up to [`LANES`] signals of one length at once, `sos[l]` over `data[l]`, in
/// lock step: each lane's recursion is a chain of dependent operations whose latency, not the
/// core's throughput, sets its speed, so lanes side by side cost about what one does. Each lane
/// gets the same operations in the same order as alone. More lanes, or lanes of other lengths,
/// are run in turn.
fn cascade_lanes(sos: &mut [&mut [Sos<f64>]], data: &mut [&mut [f64]], reverse: bool) {
    fn run<const N: usize, const L: usize>(
        sos: &mut [&mut [Sos<f64>]],
        data: &mut [&mut [f64]],
        reverse: bool,
    ) {
        let c: [[[f64; 5]; N]; L] = std::array::from_fn(|l| {
            std::array::from_fn(|i| {
                let s = &sos[l][i];
                [s.b[0], s.b[1], s.b[2], s.a[1], s.a[2]]
            })
        });
        let mut z: [[[f64; 2]; N]; L] =
            std::array::from_fn(|l| std::array::from_fn(|i| [sos[l][i].zi0, sos[l][i].zi1]));
        let len = data[0].len();
        let mut step = |k: usize| {
            for l in 0..L {
                let mut x = data[l][k];
                for i in 0..N {
                    let [b0, b1, b2, a1, a2] = c[l][i];
                    let y = b0 * x + z[l][i][0];
                    z[l][i][0] = b1 * x - a1 * y + z[l][i][1];
                    z[l][i][1] = b2 * x - a2 * y;
                    x = y;
                }
                data[l][k] = x;
            }
        };
        if reverse {
            (0..len).rev().for_each(&mut step);
        } else {
            (0..len).for_each(&mut step);
        }
        for (s, zl) in sos.iter_mut().zip(z) {
            for (s, [z0, z1]) in s.iter_mut().zip(zl) {
                (s.zi0, s.zi1) = (z0, z1);
            }
        }
    }
    fn sections<const L: usize>(
        sos: &mut [&mut [Sos<f64>]],
        data: &mut [&mut [f64]],
        reverse: bool,
    ) {
        match sos[0].len() {
            1 => run::<1, L>(sos, data, reverse),
            2 => run::<2, L>(sos, data, reverse),
            3 => run::<3, L>(sos, data, reverse),
            4 => run::<4, L>(sos, data, reverse),
            5 => run::<5, L>(sos, data, reverse),
            6 => run::<6, L>(sos, data, reverse),
            _ => {
                for (sos, data) in sos.iter_mut().zip(data.iter_mut()) {
                    let step = |v: &mut f64| *v = sci_rs::signal::filter::sosfilt_item(*v, sos);
                    if reverse {
                        data.iter_mut().rev().for_each(step);
                    } else {
                        data.iter_mut().for_each(step);
                    }
                }
            }
        }
    }
    let n = sos.len().min(data.len());
    let (sos, data) = (&mut sos[..n], &mut data[..n]);
    let alike = n <= LANES
        && data.iter().all(|d| d.len() == data[0].len())
        && sos.iter().all(|s| s.len() == sos[0].len());
    match n {
        0 => {}
        2 if alike => sections::<2>(sos, data, reverse),
        3 if alike => sections::<3>(sos, data, reverse),
        _ => {
            for l in 0..n {
                sections::<1>(&mut sos[l..=l], &mut data[l..=l], reverse);
            }
        }
    }
}

/// Sample k of the input.
fn sample(x: BlockInput<'_>, k: usize) -> f64 {
    let mut one = [0.0];
    x(k, &mut one);
    one[0]
}

/// Appends the input's odd extension (as scipy's `odd_ext`) on `range` (−padlen ≤ i <
/// n + padlen) to `out`: the samples inside [0, n) in one call of `x`, the padding sample by
/// sample (at most padlen of them).
fn extend_extended(x: BlockInput<'_>, n: usize, range: Range<isize>, out: &mut Vec<f64>) {
    let last = n as isize - 1;
    let ends = || (sample(x, 0), sample(x, last as usize));
    let (mut first, mut tail) = (None, None);
    for i in range.start..range.end.min(0) {
        let x0 = *first.get_or_insert_with(|| ends().0);
        out.push(2.0 * x0 - sample(x, (-i) as usize));
    }
    let (a, b) = (range.start.max(0), range.end.min(n as isize));
    if a < b {
        let at = out.len();
        out.resize(at + (b - a) as usize, 0.0);
        x(a as usize, &mut out[at..]);
    }
    for i in range.start.max(last + 1)..range.end {
        let xl = *tail.get_or_insert_with(|| ends().1);
        out.push(2.0 * xl - sample(x, (2 * last - i) as usize));
    }
}

/// The filter's steady state for a unit step (`sosfilt_zi`) scaled by `x0`.
fn steady(zi: &[Sos<f64>], x0: f64) -> Vec<Sos<f64>> {
    zi.iter()
        .map(|s| {
            let mut s = *s;
            s.zi0 *= x0;
            s.zi1 *= x0;
            s
        })
        .collect()
}

/// Zero-phase filtering (as [`super::sosfiltfilt`]) of the S signals `inputs` (sample k of
/// signal s is `inputs[s](k)`, k < n), handed to `consume` block by block in order (see the
/// module doc): memory O(S · (block + 2·halo + lookahead)) instead of O(S · n). The signals of a
/// block are filtered at once on the available cores when the block is long.
///
/// # Errors
/// [`Error::TooShort`] if n is not longer than the filter's padding, [`Error::InvalidSetting`]
/// for an empty block; otherwise the first error `consume` returns (which ends the run).
pub fn sosfiltfilt_blocks<const S: usize, E: From<Error>>(
    sos: &[Sos<f64>],
    n: usize,
    inputs: [BlockInput<'_>; S],
    plan: BlockPlan,
    mut consume: impl FnMut(FilteredBlock<'_, S>) -> std::result::Result<(), E>,
) -> std::result::Result<(), E> {
    let padlen = sos_padlen(sos);
    if n <= padlen {
        return Err(Error::TooShort {
            file: "<signal>".into(),
            samples: n,
            needed: padlen + 1,
            why: "zero-phase filtering pads each end by 3 × the filter length".into(),
        }
        .into());
    }
    if plan.block == 0 {
        return Err(
            Error::InvalidSetting("a filter block needs at least one sample".into()).into(),
        );
    }
    let mut zi = sos.to_vec();
    sosfilt_zi_dyn::<_, _, Sos<f64>>(zi.iter_mut());
    let mut lanes: Vec<Lane> = inputs
        .iter()
        .map(|x| Lane {
            forward: steady(&zi, 2.0 * sample(*x, 0) - sample(*x, padlen)),
            cursor: -(padlen as isize),
            buf: Vec::new(),
            out: Vec::new(),
        })
        .collect();
    let mut a = 0;
    while a < n {
        // One block covers the rest when the rest is within one lookahead of its end.
        let b = if a + plan.block + plan.lookahead >= n {
            n
        } else {
            a + plan.block
        };
        let lo = a.saturating_sub(plan.halo);
        let hi = (b + plan.halo).min(n);
        let next_lo = b.saturating_sub(plan.halo);
        let filter = |(lanes, xs): (&mut [Lane], &[BlockInput<'_>])| {
            filter_block(lanes, xs, n, padlen, &zi, (lo, hi, next_lo), plan.lookahead);
        };
        if (b - a) * S >= 1 << 16 {
            use rayon::prelude::*;
            // Groups of lanes, one a thread, each filtered side by side.
            let groups = S.div_ceil(LANES).max(rayon::current_num_threads().min(S));
            let size = S.div_ceil(groups);
            lanes
                .par_chunks_mut(size)
                .zip(inputs.par_chunks(size))
                .for_each(filter);
        } else {
            lanes
                .chunks_mut(LANES)
                .zip(inputs.chunks(LANES))
                .for_each(filter);
        }
        let signals: [&[f64]; S] = std::array::from_fn(|s| lanes[s].out.as_slice());
        consume(FilteredBlock {
            rows: a..b,
            offset: lo,
            signals,
        })?;
        a = b;
    }
    Ok(())
}

/// One group of lanes' block (up to [`LANES`], side by side): forward outputs from `lo` to the
/// backward start (the state saved at `next_lo` for the next block), then the backward pass
/// down to `lo`; each lane's zero-phase outputs on [lo, hi) land in its `out`.
fn filter_block(
    lanes: &mut [Lane],
    xs: &[BlockInput<'_>],
    n: usize,
    padlen: usize,
    zi: &[Sos<f64>],
    (lo, hi, next_lo): (usize, usize, usize),
    lookahead: usize,
) {
    let exact_end = hi + lookahead >= n;
    // The backward pass starts at `end` (exclusive), in extension indices.
    let end = if exact_end {
        (n + padlen) as isize
    } else {
        (hi + lookahead) as isize
    };
    let (lo_i, next_i) = (lo as isize, next_lo as isize);
    for (lane, &x) in lanes.iter_mut().zip(xs) {
        // Bring the forward state from the cursor to `lo` (the first block's padding).
        if lane.cursor < lo_i {
            let mut pad = Vec::new();
            extend_extended(x, n, lane.cursor..lo_i, &mut pad);
            cascade(&mut lane.forward, &mut pad, false);
        }
        lane.buf.clear();
        extend_extended(x, n, lo_i..end, &mut lane.buf);
        lane.cursor = next_i;
    }
    let split = (next_i - lo_i) as usize;
    {
        let (mut states, mut heads) = (Vec::new(), Vec::new());
        for lane in lanes.iter_mut() {
            states.push(lane.forward.as_mut_slice());
            heads.push(&mut lane.buf[..split]);
        }
        cascade_lanes(&mut states, &mut heads, false);
    }
    // The next block starts from the state at `next_lo`; the lookahead runs on a copy.
    let mut beyond: Vec<Vec<Sos<f64>>> = lanes.iter().map(|l| l.forward.clone()).collect();
    let mut states: Vec<&mut [Sos<f64>]> = beyond.iter_mut().map(Vec::as_mut_slice).collect();
    let mut aheads: Vec<&mut [f64]> = lanes.iter_mut().map(|l| &mut l.buf[split..]).collect();
    cascade_lanes(&mut states, &mut aheads, false);
    let mut backward: Vec<Vec<Sos<f64>>> = lanes
        .iter()
        .map(|l| steady(zi, l.buf.last().copied().unwrap_or(0.0)))
        .collect();
    let mut states: Vec<&mut [Sos<f64>]> = backward.iter_mut().map(Vec::as_mut_slice).collect();
    let mut bufs: Vec<&mut [f64]> = lanes.iter_mut().map(|l| l.buf.as_mut_slice()).collect();
    cascade_lanes(&mut states, &mut bufs, true);
    for lane in lanes.iter_mut() {
        lane.out.clear();
        lane.out.extend_from_slice(&lane.buf[..hi - lo]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signal::{Butterworth, sosfiltfilt};

    fn signal(n: usize) -> Vec<f64> {
        (0..n)
            .map(|k| {
                let t = k as f64 * 0.02;
                (0.7 * t).sin()
                    + 0.3 * (5.1 * t).cos()
                    + 0.05 * (((k * 7919) % 101) as f64 - 50.0) / 50.0
                    + 0.2
            })
            .collect()
    }

    /// Blocks far shorter than the default, halos of 0 and 3, a lookahead of 80 cut-off
    /// periods: every sample of every block equals the whole signal's `sosfiltfilt`.
    #[test]
    fn blocks_equal_the_whole_signal_filtered() {
        let fs = 50.0;
        let sos = Butterworth {
            order: 4,
            cutoff_hz: 2.0,
            fs_hz: fs,
        }
        .sos()
        .expect("valid filter");
        let lookahead = (80.0 * fs / 2.0) as usize;
        for n in [61, 2_500, 10_007] {
            let x = signal(n);
            let x2: Vec<f64> = x.iter().map(|v| -v * v).collect();
            let whole = [
                sosfiltfilt(&sos, &x).expect("long enough"),
                sosfiltfilt(&sos, &x2).expect("long enough"),
            ];
            for (block, halo) in [(1usize, 0usize), (97, 3), (1_000, 2), (1 << 16, 2)] {
                let plan = BlockPlan {
                    block,
                    lookahead,
                    halo,
                };
                let mut covered = 0;
                let fx = |k: usize, out: &mut [f64]| out.copy_from_slice(&x[k..k + out.len()]);
                let fx2 = |k: usize, out: &mut [f64]| out.copy_from_slice(&x2[k..k + out.len()]);
                // Six signals: filtered side by side in groups.
                sosfiltfilt_blocks::<6, Error>(
                    &sos,
                    n,
                    [&fx, &fx2, &fx, &fx2, &fx, &fx2],
                    plan,
                    |b| {
                        assert_eq!(b.rows.start, covered, "blocks in order, no gap");
                        assert_eq!(b.offset, b.rows.start.saturating_sub(halo));
                        let hi = (b.rows.end + halo).min(n);
                        for (s, w) in whole.iter().cycle().take(6).enumerate() {
                            assert_eq!(b.signals[s].len(), hi - b.offset);
                            for (j, v) in b.signals[s].iter().enumerate() {
                                let k = b.offset + j;
                                assert!(
                                    (v - w[k]).abs() < 1e-13,
                                    "n {n} block {block} signal {s} sample {k}: {v} vs {}",
                                    w[k]
                                );
                            }
                        }
                        covered = b.rows.end;
                        Ok(())
                    },
                )
                .expect("filters");
                assert_eq!(covered, n);
            }
        }
    }

    #[test]
    fn too_short_and_empty_blocks_are_errors() {
        let sos = Butterworth {
            order: 4,
            cutoff_hz: 2.0,
            fs_hz: 50.0,
        }
        .sos()
        .expect("valid filter");
        let x = |_: usize, out: &mut [f64]| out.fill(1.0);
        let plan = BlockPlan {
            block: 10,
            lookahead: 10,
            halo: 0,
        };
        let short = sosfiltfilt_blocks::<1, Error>(&sos, 10, [&x], plan, |_| Ok(()));
        assert!(matches!(short, Err(Error::TooShort { needed: 16, .. })));
        let empty = BlockPlan { block: 0, ..plan };
        let none = sosfiltfilt_blocks::<1, Error>(&sos, 100, [&x], empty, |_| Ok(()));
        assert!(matches!(none, Err(Error::InvalidSetting(_))));
    }
}
