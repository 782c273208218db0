//! The CPU sweep engine: monomial values generated on the fly, never materialised (except, by
//! choice, for tiny problems), rayon-parallel over sample blocks.
//!
//! # How a sweep runs
//! The candidates form a tree: every monomial of degree k >= 1 is its parent (degree k - 1) times
//! one variable, and the children of one parent are consecutive in the basis order (see
//! [`crate::basis`]). The engine walks the *internal* nodes (degree < d) depth first, one block of
//! `B` samples at a time. For every internal node p with values `x_p` it uses `v * z_k`
//! (formed once per block) so that the correlation of each child `c = p * z_k` is
//! `sum_i x_p,i (v z_k)_i`: one multiply-add per sample-candidate pair, computed for up to eight
//! children at a time with register accumulators (module `kernel`). At degree >= 3 the two bottom
//! levels, where most candidates are, go together: with `v z_a z_b` formed once per block, a
//! node of degree d-2 gives all its children and grandchildren as dot products, so nodes of
//! degree d-1 are never formed and one load of `x_p` feeds eight multiply-adds. Up to three
//! sibling nodes of degree d-2 go together: a sibling's vectors are a suffix of its elder's, so
//! over that suffix one load of a pair-table vector (from L2) feeds two or three multiply-adds
//! (25,000 x 12,376 on one thread: 15.0 -> 13.3 ms; 497,420: 0.674 -> 0.592 s). Only internal
//! nodes of degree < d-1 are ever written (one multiply per sample each). Partial sums over one
//! block are kept in the working precision and added to f64 totals, so the accumulation across
//! the whole sweep is f64.
//!
//! Where the CPU has AVX2 and FMA, f32 sweeps of degree >= 3 that are not materialised run
//! another kernel (module `tiles`) wherever one task's scratch stays within
//! `tiles::MAX_SCRATCH_BYTES` (the triples must fit L2: n_z up to 15): each candidate of degree
//! 3 or more as a node (degree <= d-3) times a triple `z_a z_b z_c`, the nodes of one last variable
//! four at a time against all the triples they meet in register tiles, 4 x 4 with AVX-512, two
//! of 2 x 4 with AVX2 (25,000 x 12,376 and 497,420 with AVX-512: about 2x faster than the
//! family walk, docs/method/regression.md). The family walk serves f64 sweeps, the column
//! statistics, larger n_z and CPUs without AVX2.
//!
//! B = 256 was measured best on this machine (2.2-2.8x the f32 multiply-add limit on 497,420
//! candidates, against 2.9x at 128 and 512 and 3.7x at 64): longer blocks amortise the
//! per-node reductions, and the pair table (91 vectors of B at n_z = 13) then lives in L2.
//!
//! # The f32 range
//! f32 products of up to d values fall below the normal range (2^-126) where a signal passes
//! close to zero, and x86 cores take a microcode assist on every subnormal operand or result:
//! on the noise-free MIMO plant at d = 6 (12,376 candidates) such blocks made a sweep 7x slower
//! than on random data. Flushing subnormals to zero would need the floating-point environment
//! changed, which Rust does not allow; instead each variable is scaled by a power of two so its
//! largest value is near `2^(96/d)` and each sweep's v so that its largest value is near
//! `2^(110 - d * floor(96/d))`: a product then stays normal down to relative sizes of 2^-230,
//! partial sums stay below 2^116, and the powers are divided out of the f64 totals. Powers of two
//! change no f32 rounding, so results are those of the unscaled sweep wherever it had no
//! subnormals.
//!
//! Memory: Z twice (f64 and f32 copies, O(n_s x n_z)), and per sweep task (eight per thread
//! where the tasks' workspaces stay within 16 MiB, else two) one f64 accumulator and a scratch,
//! kept from one sweep to the next (for f32 sweeps and for the f64 statistics separately). The
//! family walk's accumulator has one slot per candidate and about 100 KiB of scratch; the tile
//! kernel's has 16 slots per tile, some unused (1.13 slots per candidate at n_z = 11, d = 6,
//! 1.08 at n_z = 13, d = 9), and 411 KiB of scratch at n_z = 11, d = 6, 618 KiB at n_z = 13,
//! d = 9.
//!
//! # Materialised mode
//! When `n_samples x n_candidates x 8 bytes` is at most [`CpuOptions::materialize_limit_bytes`]
//! (default 8 MiB), the engine builds the f64 design once and sweeps it as a dense matrix
//! ([`DenseEngine`]); that avoids the tree walk overhead on tiny problems and is exact f64.
//!
//! Column statistics are always computed in f64, in one pass about a shift near each column's
//! mean (its weighted mean over 64 spread samples), with a second pass about the exact means for the
//! columns where that would lose more than six digits, so nearly constant monomials get an
//! accurate norm; `columns` evaluates exact f64 values.

#![allow(clippy::needless_range_loop)]

mod dense;
mod kernel;
mod tiles;

pub use dense::DenseEngine;

use super::{ColumnStats, Features, Precision, SweepEngine};
use crate::basis::Basis;
use crate::error::{Error, Result};
pub use kernel::simd_level;
use kernel::{Elem, Plan};
use rayon::prelude::*;
use std::sync::Mutex;
use tiles::{TilePlan, TileScratch};

/// Settings of the CPU engine.
#[derive(Debug, Clone, Copy)]
pub struct CpuOptions {
    /// Arithmetic of the monomial products in sweeps (accumulation is f64 either way).
    pub precision: Precision,
    /// Materialise the design when it needs at most this many bytes (0 disables).
    pub materialize_limit_bytes: usize,
}

impl Default for CpuOptions {
    fn default() -> Self {
        CpuOptions {
            precision: Precision::F64,
            materialize_limit_bytes: 8 << 20,
        }
    }
}

/// Matrix-free engine over a monomial basis (see the module docs).
pub struct CpuEngine {
    basis: Basis,
    n_samples: usize,
    precision: Precision,
    plan: Plan,
    /// Z in f64, column-major (exact values for `columns` and the statistics).
    z64: Vec<f64>,
    z_blocks64: Vec<f64>,
    z_blocks32: Vec<f32>,
    /// Powers of two of the f32 sweeps (see "The f32 range" in the module docs).
    scale32: F32Scale,
    dense: Option<DenseEngine>,
    /// The f32 sweeps' matrix-product kernel (module `tiles`), where the CPU has AVX-512 or
    /// AVX2 + FMA and the basis suits it; the family kernel otherwise.
    tiles: Option<TilePlan>,
    /// Each sweep task's accumulator and scratch, kept from one sweep to the next.
    work32: Mutex<Vec<Work<kernel::Scratch<f32>>>>,
    work64: Mutex<Vec<Work<kernel::Scratch<f64>>>>,
    work_tiles: Mutex<Vec<Work<TileScratch>>>,
}

/// One sweep task's accumulator (plan order) and scratch. Kept by the engine: a LARS path asks
/// for hundreds of sweeps with other work between them, and fresh buffers each time (a few
/// hundred KiB per task at 12,376 candidates, 4 MB at 497,420) cost page faults on every sweep.
struct Work<S> {
    acc: Vec<f64>,
    scratch: S,
}

/// One pass over the blocks: Z laid out in blocks of `bsz` samples and the vector each block's
/// scratch loads (times `v_scale`).
struct Pass<'a, T> {
    blocks: &'a [T],
    bsz: usize,
    v: &'a [f64],
    v_scale: f64,
}

/// A kernel's scratch, which holds one block of the swept vector.
trait BlockScratch {
    /// Loads one block of v times `scale` (shorter than the block at the end: the rest zero).
    fn load_v(&mut self, v: &[f64], scale: f64);
}

impl<T: Elem> BlockScratch for kernel::Scratch<T> {
    fn load_v(&mut self, v: &[f64], scale: f64) {
        kernel::Scratch::load_v(self, v, scale)
    }
}

impl BlockScratch for TileScratch {
    fn load_v(&mut self, v: &[f64], scale: f64) {
        TileScratch::load_v(self, v, scale)
    }
}

/// Exponent of the largest f32 product a sweep forms (see the module docs).
const F32_TOP: i32 = 110;

/// The powers of two that keep f32 sweeps in the normal range (see the module docs).
#[derive(Debug, Clone, Default)]
struct F32Scale {
    /// Variable k is multiplied by `2^var_exp[k]` in the f32 blocks.
    var_exp: Vec<i32>,
    /// `2^-(sum of the exponents of its variables)` for each candidate (basis order).
    unscale: Vec<f64>,
    /// The exponent v's largest value is scaled to.
    v_top: i32,
}

/// The smallest e with |x| < 2^e (0 for 0 and non-finite x).
fn exponent_above(x: f64) -> i32 {
    if x > 0.0 && x.is_finite() {
        x.log2().floor() as i32 + 1
    } else {
        0
    }
}

impl F32Scale {
    fn new(basis: &Basis, features: &Features) -> F32Scale {
        let d = basis.degree().max(1) as i32;
        let z_top = 96 / d;
        // Clamped so that the powers of a degree-d product stay well inside f64's range.
        let var_exp: Vec<i32> = (0..features.n_vars())
            .map(|k| {
                let m = features
                    .column(k)
                    .iter()
                    .fold(0.0f64, |m, x| m.max(x.abs()));
                (z_top - exponent_above(m)).clamp(-60, 60)
            })
            .collect();
        let unscale = basis
            .codes()
            .iter()
            .map(|c| 2f64.powi(-c.vars().map(|k| var_exp[k]).sum::<i32>()))
            .collect();
        F32Scale {
            var_exp,
            unscale,
            v_top: F32_TOP - d * z_top,
        }
    }

    /// Features with variable k times `2^var_exp[k]` (exact: powers of two).
    fn apply(&self, features: &Features) -> Features {
        let mut f = features.clone();
        let n = f.n_samples;
        for (k, e) in self.var_exp.iter().enumerate() {
            let s = 2f64.powi(*e);
            f.data[k * n..(k + 1) * n].iter_mut().for_each(|x| *x *= s);
        }
        f
    }

    /// The exponent v is scaled by in one sweep.
    fn v_exp(&self, v: &[f64]) -> i32 {
        let m = v.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        (self.v_top - exponent_above(m)).clamp(-1000, 1000)
    }
}

const B32: usize = kernel::SIMD_B;
const B64: usize = kernel::SIMD_B;

/// Column statistics sum the squares about a shift and subtract the shift's share; a column
/// whose sum of squares about the shift is more than this times its variance (six of f64's
/// sixteen digits lost) is summed again about its exact mean.
const CANCELLATION_LIMIT: f64 = 1e6;

/// Samples whose weighted mean is each column's shift in the column statistics.
const SHIFT_SAMPLES: usize = 64;

impl CpuEngine {
    /// Builds the engine for `basis` over the feature rows `features` (names must match). Refuses
    /// features that fail [`Features::check`], a number of variables other than the basis's, no
    /// samples and a feature value that is not finite.
    pub fn new(basis: &Basis, features: &Features, options: CpuOptions) -> Result<CpuEngine> {
        features.check()?;
        if features.n_vars() != basis.n_vars() {
            return Err(Error::param(
                "features",
                format!(
                    "the basis has {} variables but the data has {}",
                    basis.n_vars(),
                    features.n_vars()
                ),
            ));
        }
        if features.n_samples == 0 {
            return Err(Error::InvalidData("no samples to regress on".into()));
        }
        if let Some(k) = features.data.iter().position(|x| !x.is_finite()) {
            let (var, row) = (k / features.n_samples, k % features.n_samples);
            return Err(Error::InvalidData(format!(
                "feature '{}' is not finite at sample {row}",
                features.names.get(var).map(String::as_str).unwrap_or("?")
            )));
        }
        let n = features.n_samples;
        let nc = basis.len();
        let dense_bytes = (n as u128) * (nc as u128) * 8;
        let dense = if dense_bytes <= options.materialize_limit_bytes as u128 {
            let mut data = vec![0.0; n * nc];
            data.par_chunks_mut(n)
                .enumerate()
                .for_each(|(j, col)| eval_column(basis, features, j, col));
            Some(DenseEngine::from_column_major(n, nc, data)?)
        } else {
            None
        };
        let plan = Plan::new(basis);
        let z_blocks64 = kernel::block_layout::<f64>(features, B64);
        let (z_blocks32, scale32) = if options.precision == Precision::F32 && dense.is_none() {
            let scale = F32Scale::new(basis, features);
            (
                kernel::block_layout::<f32>(&scale.apply(features), B32),
                scale,
            )
        } else {
            (Vec::new(), F32Scale::default())
        };
        let tile_isa =
            tiles::Isa::of_cpu().filter(|_| options.precision == Precision::F32 && dense.is_none());
        Ok(CpuEngine {
            basis: basis.clone(),
            n_samples: n,
            precision: options.precision,
            plan,
            z64: features.data.clone(),
            z_blocks64,
            z_blocks32,
            scale32,
            dense,
            tiles: tile_isa.and_then(|isa| TilePlan::new(basis, isa)),
            work32: Mutex::new(Vec::new()),
            work64: Mutex::new(Vec::new()),
            work_tiles: Mutex::new(Vec::new()),
        })
    }

    pub fn basis(&self) -> &Basis {
        &self.basis
    }

    /// Whether this engine materialised its design (tiny problems only).
    pub fn is_materialized(&self) -> bool {
        self.dense.is_some()
    }

    /// `out = X^T v` over `blocks` (Z laid out in blocks of `bsz`) with the family kernel; with
    /// `scale`, the blocks are the scaled f32 ones and v is scaled as they need (see "The f32
    /// range" in the module docs).
    fn raw_sweep<T: Elem>(
        &self,
        work: &Mutex<Vec<Work<kernel::Scratch<T>>>>,
        blocks: &[T],
        bsz: usize,
        v: &[f64],
        out: &mut [f64],
        scale: Option<&F32Scale>,
    ) {
        let v_exp = scale.map_or(0, |s| s.v_exp(v));
        let nz = self.basis.n_vars();
        let (degree, plan) = (self.plan.degree(), &self.plan);
        let scratch = kernel::Scratch::<T>::elements(degree, nz, bsz) * std::mem::size_of::<T>();
        let new = || kernel::Scratch::<T>::new(degree, nz, bsz);
        let pass = Pass {
            blocks,
            bsz,
            v,
            v_scale: 2f64.powi(v_exp),
        };
        let mut work = work.lock().unwrap_or_else(|e| e.into_inner());
        let total = self.on_blocks(
            &mut work,
            pass,
            plan.order().len(),
            scratch,
            new,
            |zb, s, acc| kernel::sweep_block(plan, zb, bsz, s, acc),
        );
        scatter(plan.order(), total, scale.map(|s| (s, v_exp)), out);
    }

    /// [`CpuEngine::raw_sweep`] of the scaled f32 blocks with the tile kernel.
    fn tile_sweep(&self, plan: &TilePlan, v: &[f64], out: &mut [f64]) {
        let v_exp = self.scale32.v_exp(v);
        let new = || TileScratch::new(plan);
        let pass = Pass {
            blocks: &self.z_blocks32,
            bsz: tiles::B,
            v,
            v_scale: 2f64.powi(v_exp),
        };
        let mut work = self.work_tiles.lock().unwrap_or_else(|e| e.into_inner());
        let (slots, bytes) = (plan.order().len(), plan.scratch_bytes());
        let total = self.on_blocks(&mut work, pass, slots, bytes, new, |zb, s, acc| {
            tiles::sweep_block(plan, zb, s, acc)
        });
        scatter(plan.order(), total, Some((&self.scale32, v_exp)), out);
    }

    /// Runs `kernel(zb, scratch, acc)` for every block of `pass` (its Z and, loaded into the
    /// scratch, its part of v) in a few tasks per thread (enough for load balance, few enough
    /// that their accumulators stay cheap), each on one kept [`Work`] of `slots` accumulators
    /// (zeroed first; a fresh one from `new_scratch`, of `scratch_bytes`, where the task count
    /// changed); the tasks' accumulators summed.
    fn on_blocks<'w, T: Sync, S: BlockScratch + Send>(
        &self,
        work: &'w mut Vec<Work<S>>,
        pass: Pass<'_, T>,
        slots: usize,
        scratch_bytes: usize,
        new_scratch: impl Fn() -> S,
        kernel: impl Fn(&[T], &mut S, &mut [f64]) + Sync,
    ) -> &'w [f64] {
        let (n, bsz, nz) = (self.n_samples, pass.bsz, self.basis.n_vars());
        let n_blocks = n.div_ceil(bsz);
        let threads = rayon::current_num_threads().max(1);
        // Eight tasks per thread where their workspaces stay small (16 MiB per pool): on a
        // shared host a core slowed for a moment holds up the sweep's end, and finer tasks let
        // the other core take its share (25,000 x 12,376 on 2 cores: 5-6 % faster sweeps in
        // LARS paths, docs/method/regression.md); two per thread at 497,420 candidates, where
        // sixteen accumulators would be 64 MiB to zero and sum.
        let task_bytes = 8 * slots + scratch_bytes;
        let by_memory = (16 << 20) / task_bytes.max(1);
        let tasks = (threads * 8).min(by_memory).max(threads * 2);
        let per_task = n_blocks.div_ceil(tasks).max(1);
        let n_tasks = n_blocks.div_ceil(per_task);
        // The f64 sweeps and the column statistics share one pool with different slot counts.
        if work.len() != n_tasks || work.iter().any(|w| w.acc.len() != slots) {
            *work = (0..n_tasks)
                .map(|_| Work {
                    acc: vec![0.0; slots],
                    scratch: new_scratch(),
                })
                .collect();
        }
        work.par_iter_mut().enumerate().for_each(|(t, wk)| {
            wk.acc.fill(0.0);
            for b in t * per_task..((t + 1) * per_task).min(n_blocks) {
                let s0 = b * bsz;
                let len = bsz.min(n - s0);
                wk.scratch.load_v(&pass.v[s0..s0 + len], pass.v_scale);
                kernel(
                    &pass.blocks[b * nz * bsz..(b + 1) * nz * bsz],
                    &mut wk.scratch,
                    &mut wk.acc,
                );
            }
        });
        let (first, rest) = work.split_first_mut().expect("at least one task");
        for wk in rest.iter() {
            first.acc.iter_mut().zip(&wk.acc).for_each(|(x, y)| *x += y);
        }
        &first.acc
    }

    /// Each candidate's weighted mean over `SHIFT_SAMPLES` samples spread over the record: a
    /// shift near its weighted mean for [`CpuEngine::shifted_sums`] (the plain mean where those
    /// samples have no weight).
    fn shifts(&self, w: &[f64]) -> Vec<f64> {
        let n = self.n_samples;
        let at: Vec<usize> = (0..SHIFT_SAMPLES).map(|k| k * n / SHIFT_SAMPLES).collect();
        let sw: f64 = at.iter().map(|&i| w[i]).sum();
        let weight = |i: usize| {
            if sw > 0.0 {
                w[i] / sw
            } else {
                1.0 / at.len() as f64
            }
        };
        (0..self.basis.len())
            .into_par_iter()
            .map(|j| {
                let code = self.basis.code(j);
                let x: [f64; SHIFT_SAMPLES] = std::array::from_fn(|k| {
                    code.vars().fold(1.0, |p, v| p * self.z64[v * n + at[k]])
                });
                // A column constant on these samples (the constant monomial) gets its value
                // itself: a mean rounded off it would make its zero variance a cancellation.
                if x.iter().all(|&v| v == x[0]) {
                    x[0]
                } else {
                    at.iter().zip(&x).map(|(&i, v)| weight(i) * v).sum()
                }
            })
            .collect()
    }

    /// Per candidate j, `sum_i v_i (x_ij - k_j)` (slot j) and `sum_i v_i (x_ij - k_j)^2` (slot
    /// len + j) about the shifts `k`, in one f64 pass.
    fn shifted_sums(&self, v: &[f64], shift: &[f64]) -> Vec<f64> {
        let nz = self.basis.n_vars();
        let bsz = B64;
        let scratch = kernel::Scratch::<f64>::elements(self.plan.degree(), nz, bsz) * 8;
        let new = || kernel::Scratch::<f64>::new(self.plan.degree(), nz, bsz);
        let pass = Pass {
            blocks: &self.z_blocks64,
            bsz,
            v,
            v_scale: 1.0,
        };
        let mut work = self.work64.lock().unwrap_or_else(|e| e.into_inner());
        let slots = 2 * self.basis.len();
        self.on_blocks(&mut work, pass, slots, scratch, new, |zb, s, acc| {
            kernel::shifted_block(&self.plan, zb, bsz, s, shift, acc)
        })
        .to_vec()
    }

    /// Per candidate, `sum_i v_i (x_ij - m_j)^2` about the exact means `m` (a second pass, for
    /// the columns where the shifted sums cancel).
    fn centred_squares(&self, v: &[f64], mean: &[f64]) -> Vec<f64> {
        let sums = self.shifted_sums(v, mean);
        sums[mean.len()..].to_vec()
    }
}

/// `out[order[p]] = total[p]` for every used slot p, with the f32 sweeps' powers of two divided
/// out where `scale` gives them (with the exponent v was scaled by).
fn scatter(order: &[u32], total: &[f64], scale: Option<(&F32Scale, i32)>, out: &mut [f64]) {
    let used = order.iter().zip(total).filter(|(o, _)| **o != u32::MAX);
    match scale {
        Some((s, v_exp)) => {
            let v_unscale = 2f64.powi(-v_exp);
            for (&o, t) in used {
                out[o as usize] = t * s.unscale[o as usize] * v_unscale;
            }
        }
        None => used.for_each(|(&o, t)| out[o as usize] = *t),
    }
}

/// Exact f64 values of monomial j on every sample.
fn eval_column(basis: &Basis, features: &Features, j: usize, out: &mut [f64]) {
    out.fill(1.0);
    for v in basis.code(j).vars() {
        let z = features.column(v);
        out.iter_mut().zip(z).for_each(|(o, zi)| *o *= zi);
    }
}

pub(crate) fn check_weights(weights: Option<&[f64]>, n: usize) -> Result<()> {
    if let Some(w) = weights {
        if w.len() != n {
            return Err(Error::param(
                "weights",
                format!("{} weights for {n} samples", w.len()),
            ));
        }
        if let Some(i) = w.iter().position(|x| !x.is_finite() || *x < 0.0) {
            return Err(Error::param(
                "weights",
                format!("weight {} at sample {i} is negative or not finite", w[i]),
            ));
        }
        if !w.iter().any(|x| *x > 0.0) {
            return Err(Error::param("weights", "all weights are zero"));
        }
    }
    Ok(())
}

impl SweepEngine for CpuEngine {
    fn describe(&self) -> String {
        let mode = if self.dense.is_some() {
            "materialised f64".to_string()
        } else {
            // f64 sweeps have no AVX-512 instance: they run AVX2 there.
            let simd = match (self.precision, kernel::simd_level()) {
                (Precision::F64, "avx512") => "avx2",
                (Precision::F32, "avx512") if self.tiles.is_some() => "avx512 tiles",
                (Precision::F32, "avx2") if self.tiles.is_some() => "avx2 tiles",
                (_, level) => level,
            };
            format!("on-the-fly {:?}, {simd}", self.precision).to_lowercase()
        };
        format!(
            "cpu ({mode}, {} threads, {} x {})",
            rayon::current_num_threads(),
            self.n_samples,
            self.basis.len()
        )
    }

    fn n_samples(&self) -> usize {
        self.n_samples
    }

    fn n_candidates(&self) -> usize {
        self.basis.len()
    }

    fn column_stats(&mut self, weights: Option<&[f64]>) -> Result<ColumnStats> {
        check_weights(weights, self.n_samples)?;
        if let Some(d) = self.dense.as_mut() {
            return d.column_stats(weights);
        }
        let n = self.n_samples;
        let w: Vec<f64> = weights.map(<[f64]>::to_vec).unwrap_or_else(|| vec![1.0; n]);
        let sw: f64 = w.iter().sum();
        let len = self.basis.len();
        // One pass about shifts near each mean: `S2 - S1^2 / sw` cancels by a factor of
        // `S2 / var`, about 1 + ((m - k) / sd)^2, so it keeps nearly all of f64's digits; where
        // it would lose more than six (weights that put the mean far from the shift), the
        // columns' squares are summed again about their exact means.
        let shift = self.shifts(&w);
        let sums = self.shifted_sums(&w, &shift);
        let (s1, s2) = sums.split_at(len);
        let mean: Vec<f64> = (0..len).map(|j| shift[j] + s1[j] / sw).collect();
        let mut sq: Vec<f64> = (0..len).map(|j| s2[j] - s1[j] * s1[j] / sw).collect();
        // (Not `sq * limit < s2`: a NaN would pass that.)
        let kept = |sq: f64, s2: f64| sq * CANCELLATION_LIMIT >= s2;
        if (0..len).any(|j| !kept(sq[j], s2[j])) {
            let exact = self.centred_squares(&w, &mean);
            for j in 0..len {
                if !kept(sq[j], s2[j]) {
                    sq[j] = exact[j];
                }
            }
        }
        let norm = sq.iter().map(|s| s.max(0.0).sqrt()).collect();
        Ok(ColumnStats { mean, norm })
    }

    fn sweep(&mut self, v: &[f64], out: &mut [f64]) -> Result<()> {
        if v.len() != self.n_samples || out.len() != self.basis.len() {
            return Err(Error::param(
                "sweep",
                format!(
                    "vector lengths {} / {} do not match {} samples / {} candidates",
                    v.len(),
                    out.len(),
                    self.n_samples,
                    self.basis.len()
                ),
            ));
        }
        if let Some(d) = self.dense.as_mut() {
            return d.sweep(v, out);
        }
        match (self.precision, &self.tiles) {
            (Precision::F32, Some(plan)) => self.tile_sweep(plan, v, out),
            (Precision::F32, None) => self.raw_sweep::<f32>(
                &self.work32,
                &self.z_blocks32,
                B32,
                v,
                out,
                Some(&self.scale32),
            ),
            (Precision::F64, _) => {
                self.raw_sweep::<f64>(&self.work64, &self.z_blocks64, B64, v, out, None)
            }
        }
        Ok(())
    }

    fn columns(&mut self, idx: &[usize]) -> Result<Vec<Vec<f64>>> {
        let n = self.n_samples;
        let feats = Features {
            n_samples: n,
            names: self.basis.names().to_vec(),
            data: std::mem::take(&mut self.z64),
        };
        let mut res = Vec::with_capacity(idx.len());
        for &j in idx {
            if j >= self.basis.len() {
                self.z64 = feats.data;
                return Err(Error::param(
                    "columns",
                    format!(
                        "candidate {j} is out of range ({} candidates)",
                        self.basis.len()
                    ),
                ));
            }
            let mut col = vec![0.0; n];
            eval_column(&self.basis, &feats, j, &mut col);
            res.push(col);
        }
        self.z64 = feats.data;
        Ok(res)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::BasisLimits;

    fn lcg(seed: &mut u64) -> f64 {
        *seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((*seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }

    fn problem(nz: usize, d: usize, n: usize) -> (Basis, Features) {
        let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
        let mut s = 7u64;
        let cols = (0..nz)
            .map(|_| (0..n).map(|_| lcg(&mut s)).collect())
            .collect();
        (
            Basis::new(&names, d, BasisLimits::default()).unwrap(),
            Features::new(names, cols).unwrap(),
        )
    }

    #[test]
    fn on_the_fly_sweeps_and_stats_match_materialised() {
        for (nz, d, n) in [
            (3, 4, 300),
            (5, 3, 1000),
            (2, 0, 50),
            (4, 1, 129),
            (13, 4, 260),
            (7, 6, 131),
            (4, 2, 140),
            (1, 5, 300),
            (2, 3, 257),
            // Too many triples for the tile kernel: f32 sweeps of degree 3 in the family walk,
            // whose plan order differs from the basis order.
            (16, 3, 300),
        ] {
            let (b, f) = problem(nz, d, n);
            let mut dense = CpuEngine::new(
                &b,
                &f,
                CpuOptions {
                    materialize_limit_bytes: usize::MAX,
                    ..Default::default()
                },
            )
            .unwrap();
            assert!(dense.is_materialized());
            let mut s = 3u64;
            let v: Vec<f64> = (0..n).map(|_| lcg(&mut s)).collect();
            let w: Vec<f64> = (0..n).map(|_| lcg(&mut s).abs()).collect();
            let mut reference = vec![0.0; b.len()];
            dense.sweep(&v, &mut reference).unwrap();
            let rs = dense.column_stats(Some(&w)).unwrap();
            for precision in [Precision::F64, Precision::F32] {
                let mut e = CpuEngine::new(
                    &b,
                    &f,
                    CpuOptions {
                        precision,
                        materialize_limit_bytes: 0,
                    },
                )
                .unwrap();
                assert!(!e.is_materialized());
                let mut out = vec![f64::NAN; b.len()];
                e.sweep(&v, &mut out).unwrap();
                let cols = e.columns(&(0..b.len()).collect::<Vec<_>>()).unwrap();
                let tol = if precision == Precision::F64 {
                    1e-13
                } else {
                    1e-5
                };
                for j in 0..b.len() {
                    let scale: f64 = cols[j].iter().zip(&v).map(|(x, y)| (x * y).abs()).sum();
                    assert!(
                        (out[j] - reference[j]).abs() <= tol * scale,
                        "{precision:?} candidate {j}: {} vs {}",
                        out[j],
                        reference[j]
                    );
                }
                let st = e.column_stats(Some(&w)).unwrap();
                for j in 0..b.len() {
                    assert!((st.mean[j] - rs.mean[j]).abs() <= 1e-12 * (1.0 + rs.mean[j].abs()));
                    assert!(
                        (st.norm[j] - rs.norm[j]).abs() <= 1e-10 * (1.0 + rs.norm[j]),
                        "norm {j}"
                    );
                }
            }
        }
    }

    /// Column statistics sum about a shift near each column's weighted mean on 64 spread
    /// samples; a weight that puts nearly all the mass on a sample outside them (17 of 300)
    /// moves the mean far from it, and those columns are summed again about their exact means:
    /// the dense engine's exact two-pass statistics.
    #[test]
    fn column_statistics_hold_where_the_weights_move_the_mean_off_the_shift() {
        let n = 300;
        let (b, mut f) = problem(3, 3, n);
        f.data[..n].iter_mut().for_each(|x| *x += 1e3);
        let mut s = 9u64;
        let mut w: Vec<f64> = (0..n).map(|_| lcg(&mut s).abs()).collect();
        w[17] = 1e12;
        let options = |limit| CpuOptions {
            precision: Precision::F64,
            materialize_limit_bytes: limit,
        };
        let rs = CpuEngine::new(&b, &f, options(usize::MAX))
            .unwrap()
            .column_stats(Some(&w))
            .unwrap();
        let st = CpuEngine::new(&b, &f, options(0))
            .unwrap()
            .column_stats(Some(&w))
            .unwrap();
        for j in 0..b.len() {
            assert!((st.mean[j] - rs.mean[j]).abs() <= 1e-12 * (1.0 + rs.mean[j].abs()));
            assert!(
                (st.norm[j] - rs.norm[j]).abs() <= 1e-7 * rs.norm[j],
                "{} norm {} vs {}",
                b.name(j),
                st.norm[j],
                rs.norm[j]
            );
        }
    }

    /// Values far from 1 (tiny, huge, a tiny v) would put f32 products of degree 6 below the
    /// normal range or above f32's largest value; the powers of two keep the sweep at f32
    /// accuracy against the exact f64 sweep.
    #[test]
    fn f32_sweeps_hold_their_accuracy_far_from_unit_magnitude() {
        let n = 600;
        let (b, mut f) = problem(4, 6, n);
        for (k, s) in [1e-9, 1e-3, 1e12, 1.0].iter().enumerate() {
            f.data[k * n..(k + 1) * n].iter_mut().for_each(|x| *x *= s);
        }
        let mut s = 5u64;
        let v: Vec<f64> = (0..n).map(|_| 1e-25 * lcg(&mut s)).collect();
        let engine = |precision| {
            let options = CpuOptions {
                precision,
                materialize_limit_bytes: 0,
            };
            CpuEngine::new(&b, &f, options).unwrap()
        };
        let (mut e32, mut e64) = (engine(Precision::F32), engine(Precision::F64));
        let (mut out, mut reference) = (vec![0.0; b.len()], vec![0.0; b.len()]);
        e32.sweep(&v, &mut out).unwrap();
        e64.sweep(&v, &mut reference).unwrap();
        let cols = e64.columns(&(0..b.len()).collect::<Vec<_>>()).unwrap();
        for j in 0..b.len() {
            let scale: f64 = cols[j].iter().zip(&v).map(|(x, y)| (x * y).abs()).sum();
            assert!(
                (out[j] - reference[j]).abs() <= 1e-5 * scale,
                "candidate {} ({j}): {} vs {}",
                b.name(j),
                out[j],
                reference[j]
            );
        }
    }

    #[test]
    fn columns_are_exact_monomials() {
        let (b, f) = problem(3, 3, 20);
        let mut e = CpuEngine::new(
            &b,
            &f,
            CpuOptions {
                materialize_limit_bytes: 0,
                ..Default::default()
            },
        )
        .unwrap();
        let cols = e.columns(&[0, 5, b.len() - 1]).unwrap();
        for (c, j) in cols.iter().zip([0, 5, b.len() - 1]) {
            for i in 0..20 {
                let z: Vec<f64> = (0..3).map(|k| f.column(k)[i]).collect();
                assert_eq!(c[i], b.code(j).eval(&z));
            }
        }
        assert!(e.columns(&[b.len()]).is_err());
        assert!(e.column_stats(Some(&[1.0; 3])).is_err());
    }
}
