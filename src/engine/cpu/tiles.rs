//! The f32 sweep as small matrix products: nodes times triples, in register tiles (AVX-512 or
//! AVX2 + FMA).
//!
//! Every monomial of degree 3 or more is, in exactly one way, a *node* (its first variables in
//! sorted order, degree 0..=d-3) times a *triple* `z_a z_b z_c` (its last three, a <= b <= c)
//! with the node's last variable `f` at most `a`. With the triples ordered by `a`, the triples a
//! node meets are a *suffix* of that list, the same for every node of last variable `f`. So per
//! block of [`B`] samples the values `v z_a z_b z_c` of every triple are formed once, and the
//! nodes are walked depth first (as the family kernel walks them, one stack slot per level);
//! each node's values go into a buffer for its last variable, and when four nodes of last
//! variable `f` are waiting they meet the suffix of triples for `f` as one dense product in
//! register tiles of 4 nodes x 4 triples (8 vector loads per 16 multiply-adds, the nodes from
//! L1, the triples from L2; with AVX2's 16 registers, two tiles of 2 nodes x 4 triples),
//! whereas the family kernel (module `kernel`), where a node meets only its own children's
//! pairs, loads one vector per one to three multiply-adds. A tile's accumulators (16 or 8 lanes
//! each) are reduced together by one transposed tree into one vector of sums, added to
//! consecutive f64 slots. Candidates of degree 0, 1 and 2 are
//! plain sums of `v`, `v z_k` and `v z_a z_b`. The order of the nodes, the buffers' flushes and
//! so the slot of every candidate are fixed when the plan is built.
//!
//! Measured (25,000 x 12,376 and 25,000 x 497,420, this host's AVX-512): see
//! `docs/method/regression.md`, "Nodes times triples".
//!
//! Memory: one task's scratch holds `1 + n_z + pairs + triples + max(d - 3, 1) + 4 n_z`
//! vectors of [`B`] f32: 411 KiB at n_z = 11, d = 6, 618 KiB at n_z = 13, d = 9. The engine uses this kernel
//! where that is at most [`MAX_SCRATCH_BYTES`] (the triples must stay in one core's L2), else
//! the family kernel.

use crate::basis::{Basis, Code};

/// Samples per block (the engine's f32 block size).
pub const B: usize = super::kernel::SIMD_B;

/// The largest scratch (bytes per task) this kernel is chosen for.
pub const MAX_SCRATCH_BYTES: usize = 1_000_000;

/// One step of a block's walk.
#[derive(Debug, Clone, Copy)]
enum Op {
    /// `x = slot[parent] * z_var` (the constant: no `var`, x = slot 0, all ones) goes to
    /// position `pos` of buffer `buf`, and to stack slot `slot` when the node has children.
    Node {
        parent: u8,
        var: Option<u8>,
        slot: Option<u8>,
        buf: u8,
        pos: u8,
    },
    /// The `count` nodes in buffer `buf` meet every triple of first variable >= `buf`.
    Flush { buf: u8, count: u8 },
}

/// The instruction set a plan runs on; it decides where a tile puts each sum.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Isa {
    /// One 4 x 4 tile of 16-lane vectors: node r against triple t in slot `4 t + r`.
    Avx512,
    /// Two 2 x 4 tiles of 8-lane vectors: node r against triple t in slot `4 r + t`.
    Avx2,
}

impl Isa {
    /// The instruction set of this CPU for the kernel, as [`super::kernel::simd_level`] names
    /// it (so `CTSID_SIMD=avx2` chooses AVX2 here too); `None` without AVX2 and FMA.
    pub fn of_cpu() -> Option<Isa> {
        match super::kernel::simd_level() {
            "avx512" => Some(Isa::Avx512),
            "avx2" => Some(Isa::Avx2),
            _ => None,
        }
    }

    fn slot(self, r: usize, t: usize) -> usize {
        match self {
            Isa::Avx512 => 4 * t + r,
            Isa::Avx2 => 4 * r + t,
        }
    }
}

/// The walk of one block and which candidate each accumulator slot holds.
#[derive(Debug, Clone)]
pub struct TilePlan {
    isa: Isa,
    n_vars: usize,
    degree: usize,
    /// `(a, b)` of each pair, a <= b, in the order `a` then `b`.
    pairs: Vec<(u8, u8)>,
    /// Each triple as (its pair, c), in the order `a`, `b`, `c`.
    triples: Vec<(u32, u8)>,
    /// Index of the first triple of first variable `a` (and the count at `n_vars`).
    first_triple: Vec<u32>,
    ops: Vec<Op>,
    /// Basis index of every slot (`u32::MAX` for a tile's unused slots): 16 per tile in the
    /// order of the flushes, then the constant, the variables and the pairs.
    order: Vec<u32>,
}

/// Product of two monomial codes (the variables of `b` appended in order; both sorted, and
/// every variable of `b` at least the last of `a`).
fn product(a: Code, b: Code) -> Code {
    b.vars().fold(a, |c, v| c.times(v))
}

/// The plan under construction: the walk's ops, the buffers' waiting nodes and the slots.
struct Builder {
    isa: Isa,
    /// Basis index of every code (a map: `Basis::index_of` searches, once per slot).
    index: std::collections::HashMap<Code, u32>,
    degree: usize,
    n_vars: usize,
    triple_codes: Vec<Code>,
    first_triple: Vec<u32>,
    ops: Vec<Op>,
    waiting: Vec<Vec<Code>>,
    order: Vec<u32>,
}

impl Builder {
    /// Node `code` (degree k, values from stack slot `parent` times `var`) and its subtree.
    fn walk(&mut self, code: Code, parent: usize, var: Option<usize>) {
        let k = code.degree();
        let f = var.unwrap_or(0);
        let has_children = k + 3 < self.degree;
        let pos = self.waiting[f].len();
        self.ops.push(Op::Node {
            parent: parent as u8,
            var: var.map(|v| v as u8),
            slot: has_children.then_some(k as u8),
            buf: f as u8,
            pos: pos as u8,
        });
        self.waiting[f].push(code);
        if pos + 1 == 4 {
            self.flush(f);
        }
        if has_children {
            for g in f..self.n_vars {
                self.walk(code.times(g), k, Some(g));
            }
        }
    }

    fn flush(&mut self, f: usize) {
        let nodes = std::mem::take(&mut self.waiting[f]);
        if nodes.is_empty() {
            return;
        }
        self.ops.push(Op::Flush {
            buf: f as u8,
            count: nodes.len() as u8,
        });
        let end = *self.first_triple.last().expect("n_vars + 1 entries") as usize;
        for t0 in (self.first_triple[f] as usize..end).step_by(4) {
            let tile = self.order.len();
            self.order.extend([u32::MAX; 16]);
            for (r, node) in nodes.iter().enumerate() {
                for t in 0..(end - t0).min(4) {
                    let code = product(*node, self.triple_codes[t0 + t]);
                    self.order[tile + self.isa.slot(r, t)] = self.index[&code];
                }
            }
        }
    }
}

impl TilePlan {
    /// The plan of `basis` for `isa`, or `None` below degree 3 or where one task's scratch
    /// would exceed [`MAX_SCRATCH_BYTES`].
    pub fn new(basis: &Basis, isa: Isa) -> Option<TilePlan> {
        let (nv, d) = (basis.n_vars(), basis.degree());
        if d < 3 || nv == 0 || nv > u8::MAX as usize {
            return None;
        }
        let pairs: Vec<(u8, u8)> = (0..nv)
            .flat_map(|a| (a..nv).map(move |b| (a as u8, b as u8)))
            .collect();
        let pair_of = |a: usize, b: usize| super::kernel::pair_offset(a, nv) + b - a;
        let (mut triples, mut triple_codes, mut first_triple) = (vec![], vec![], vec![]);
        for a in 0..nv {
            first_triple.push(triples.len() as u32);
            for b in a..nv {
                for c in b..nv {
                    triples.push((pair_of(a, b) as u32, c as u8));
                    triple_codes.push(Code::ONE.times(a).times(b).times(c));
                }
            }
        }
        first_triple.push(triples.len() as u32);
        let vectors = Self::vectors_for(nv, d, pairs.len(), triples.len());
        if vectors * B * 4 > MAX_SCRATCH_BYTES {
            return None;
        }
        let index: std::collections::HashMap<Code, u32> = (basis.codes().iter())
            .enumerate()
            .map(|(j, c)| (*c, j as u32))
            .collect();
        let mut builder = Builder {
            isa,
            index,
            degree: d,
            n_vars: nv,
            triple_codes,
            first_triple,
            ops: Vec::new(),
            waiting: vec![Vec::new(); nv],
            order: Vec::new(),
        };
        builder.walk(Code::ONE, 0, None);
        for f in 0..nv {
            builder.flush(f);
        }
        let index = |c: Code| builder.index[&c];
        let mut order = std::mem::take(&mut builder.order);
        order.push(index(Code::ONE));
        order.extend((0..nv).map(|k| index(Code::ONE.times(k))));
        order.extend(
            pairs
                .iter()
                .map(|&(a, b)| index(Code::ONE.times(a as usize).times(b as usize))),
        );
        Some(TilePlan {
            isa,
            n_vars: nv,
            degree: d,
            pairs,
            triples,
            first_triple: builder.first_triple,
            ops: builder.ops,
            order,
        })
    }

    /// Basis index of every accumulator slot (`u32::MAX`: unused).
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// Vectors of [`B`] f32 in one task's scratch: v, `v z_k`, the pairs, the triples, the
    /// stack slots (levels 0..=d-4 have children; slot 0, the constant's ones, exists at d = 3
    /// too) and four per buffer.
    fn vectors_for(nv: usize, d: usize, pairs: usize, triples: usize) -> usize {
        1 + nv + pairs + triples + Self::slots(d) + 4 * nv
    }

    /// The scratch's first stack slot, in vectors (after v, `v z_k`, the pairs, the triples).
    fn first_slot(&self) -> usize {
        1 + self.n_vars + self.pairs.len() + self.triples.len()
    }

    fn slots(d: usize) -> usize {
        (d - 3).max(1)
    }

    fn vectors(&self) -> usize {
        Self::vectors_for(
            self.n_vars,
            self.degree,
            self.pairs.len(),
            self.triples.len(),
        )
    }

    /// Bytes of one task's scratch.
    pub fn scratch_bytes(&self) -> usize {
        self.vectors() * B * 4
    }
}

/// 16 f32 on one 64-byte line, so that every vector of the scratch is aligned.
#[derive(Debug, Clone, Copy, Default)]
#[repr(C, align(64))]
struct Line([f32; 16]);

/// One task's vectors (see [`TilePlan::vectors_for`]); stack slot 0 holds ones.
pub struct TileScratch {
    lines: Vec<Line>,
}

impl TileScratch {
    pub fn new(plan: &TilePlan) -> TileScratch {
        let mut s = TileScratch {
            lines: vec![Line::default(); plan.vectors() * B / 16],
        };
        let slots = plan.first_slot() * B;
        s.floats()[slots..slots + B].fill(1.0);
        s
    }

    fn floats(&mut self) -> &mut [f32] {
        // SAFETY: `Line` is 16 f32 with no padding (repr C, 64 bytes).
        unsafe {
            std::slice::from_raw_parts_mut(
                self.lines.as_mut_ptr() as *mut f32,
                self.lines.len() * 16,
            )
        }
    }

    /// Loads one block of v times `scale` (shorter at the end: the rest is zero).
    pub fn load_v(&mut self, v: &[f64], scale: f64) {
        let f = self.floats();
        for (d, s) in f[..B].iter_mut().zip(v) {
            *d = (*s * scale) as f32;
        }
        f[v.len()..B].fill(0.0);
    }
}

/// Whether this CPU has the instruction set `isa`.
pub fn available(isa: Isa) -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        match isa {
            Isa::Avx512 => std::arch::is_x86_feature_detected!("avx512f"),
            Isa::Avx2 => {
                std::arch::is_x86_feature_detected!("avx2")
                    && std::arch::is_x86_feature_detected!("fma")
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let _ = isa;
        false
    }
}

/// Adds one block's `sum_i x_ij v_i` to `acc` in slot order ([`TilePlan::order`]). `zb` holds
/// the block's `n_vars` vectors of [`B`] samples (zero past the data), `s` the block's v
/// ([`TileScratch::load_v`]). Panics where the CPU lacks the plan's instruction set (see
/// [`available`]) or the slices are shorter than the plan needs.
pub fn sweep_block(plan: &TilePlan, zb: &[f32], s: &mut TileScratch, acc: &mut [f64]) {
    assert!(available(plan.isa), "the CPU lacks {:?}", plan.isa);
    assert!(zb.len() >= plan.n_vars * B && acc.len() >= plan.order.len());
    assert_eq!(s.lines.len(), plan.vectors() * B / 16);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has the instruction set (asserted), and every pointer the kernel forms
    // stays inside `zb`, the scratch and `acc`, whose lengths are asserted above.
    unsafe {
        match plan.isa {
            Isa::Avx512 => avx512::block(plan, zb, s.floats(), acc),
            Isa::Avx2 => avx2::block(plan, zb, s.floats(), acc),
        }
    }
}

/// The walk of one block (the same for every instruction set; see the module docs) and its
/// element-wise helpers, for one vector type; the module that invokes it gives `sum64`, `hsum`
/// (a vector's lanes to f64) and `chunk` (the tiles of one buffer against four triples).
#[cfg(target_arch = "x86_64")]
macro_rules! walk {
    ($feat:literal, $v:ty, $lanes:literal, $acc:literal, $load:ident, $store:ident, $mul:ident, $add:ident, $fma:ident, $zero:ident) => {
        #[target_feature(enable = $feat)]
        pub unsafe fn block(plan: &TilePlan, zb: &[f32], f: &mut [f32], acc: &mut [f64]) {
            let nv = plan.n_vars;
            let base = f.as_mut_ptr();
            let v = base;
            let vz = base.add(B);
            let pw = vz.add(nv * B);
            let tw = pw.add(plan.pairs.len() * B);
            let slots = base.add(plan.first_slot() * B);
            let bufs = slots.add(TilePlan::slots(plan.degree) * B);
            let z = zb.as_ptr();
            let low = plan.order.len() - 1 - nv - plan.pairs.len();
            // Degrees 0 and 1 summed in f64 (as the family kernel does), degree 2 by lanes.
            acc[low] += sum64(v);
            for k in 0..nv {
                mul(v, z.add(k * B), vz.add(k * B));
                acc[low + 1 + k] += sum64(vz.add(k * B));
            }
            for (p, &(a, b)) in plan.pairs.iter().enumerate() {
                let sum = mul(vz.add(a as usize * B), z.add(b as usize * B), pw.add(p * B));
                acc[low + 1 + nv + p] += hsum(sum);
            }
            for (t, &(p, c)) in plan.triples.iter().enumerate() {
                mul(pw.add(p as usize * B), z.add(c as usize * B), tw.add(t * B));
            }
            let n_triples = plan.triples.len();
            let mut out = acc.as_mut_ptr();
            for op in &plan.ops {
                match *op {
                    Op::Node {
                        parent,
                        var,
                        slot,
                        buf,
                        pos,
                    } => {
                        let x = slots.add(parent as usize * B) as *const f32;
                        let to = bufs.add((4 * buf as usize + pos as usize) * B);
                        let keep = slot.map(|k| slots.add(k as usize * B));
                        let zv = var.map(|v| z.add(v as usize * B));
                        node(x, zv, to, keep);
                    }
                    Op::Flush { buf, count } => {
                        let x = bufs.add(4 * buf as usize * B) as *const f32;
                        let mut t0 = plan.first_triple[buf as usize] as usize;
                        while t0 < n_triples {
                            let w = tw.add(t0 * B) as *const f32;
                            chunk(x, w, count as usize, (n_triples - t0).min(4), out);
                            out = out.add(16);
                            t0 += 4;
                        }
                    }
                }
            }
        }

        /// `to = x * z` (or `x` without z) over one block, and into `keep` as well where given.
        #[inline]
        #[target_feature(enable = $feat)]
        unsafe fn node(x: *const f32, z: Option<*const f32>, to: *mut f32, keep: Option<*mut f32>) {
            let mut i = 0;
            while i < B {
                let mut p = $load(x.add(i));
                if let Some(z) = z {
                    p = $mul(p, $load(z.add(i)));
                }
                $store(to.add(i), p);
                if let Some(k) = keep {
                    $store(k.add(i), p);
                }
                i += $lanes;
            }
        }

        /// `out = x * y` over one block; returns the lane sums of `out`.
        #[inline]
        #[target_feature(enable = $feat)]
        unsafe fn mul(x: *const f32, y: *const f32, out: *mut f32) -> $v {
            let mut sum = $zero();
            let mut i = 0;
            while i < B {
                let p = $mul($load(x.add(i)), $load(y.add(i)));
                $store(out.add(i), p);
                sum = $add(sum, p);
                i += $lanes;
            }
            sum
        }

        /// A vector's lanes summed in f64.
        #[inline]
        #[target_feature(enable = $feat)]
        unsafe fn hsum(x: $v) -> f64 {
            let mut l = [0f32; $lanes];
            $store(l.as_mut_ptr(), x);
            l.iter().map(|x| *x as f64).sum()
        }

        /// Node rows `x + r B` (r < MR) against triple rows `w + t B` (t < NR) over one block,
        /// in accumulator `4 r + t`; `finish` adds their sums to `out`.
        #[inline]
        #[target_feature(enable = $feat)]
        unsafe fn tile<const MR: usize, const NR: usize>(x: *const f32, w: *const f32, out: *mut f64) {
            let mut a = [$zero(); $acc];
            let mut i = 0;
            while i < B {
                let xs: [$v; MR] = std::array::from_fn(|r| $load(x.add(r * B + i)));
                for t in 0..NR {
                    let wt = $load(w.add(t * B + i));
                    for r in 0..MR {
                        a[4 * r + t] = $fma(xs[r], wt, a[4 * r + t]);
                    }
                }
                i += $lanes;
            }
            finish(&a, out);
        }

        /// [`tile`] of MR nodes against `nr` (1 to 4) triples.
        #[inline]
        #[target_feature(enable = $feat)]
        unsafe fn tile_nr<const MR: usize>(x: *const f32, w: *const f32, nr: usize, out: *mut f64) {
            match nr {
                4 => tile::<MR, 4>(x, w, out),
                3 => tile::<MR, 3>(x, w, out),
                2 => tile::<MR, 2>(x, w, out),
                _ => tile::<MR, 1>(x, w, out),
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{Op, TilePlan, B};
    use std::arch::x86_64::*;

    walk!(
        "avx512f",
        __m512,
        16,
        16,
        _mm512_loadu_ps,
        _mm512_storeu_ps,
        _mm512_mul_ps,
        _mm512_add_ps,
        _mm512_fmadd_ps,
        _mm512_setzero_ps
    );

    /// The `count` nodes at `x` against the `nr` triples at `w`: one 4 x 4 tile.
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn chunk(x: *const f32, w: *const f32, count: usize, nr: usize, out: *mut f64) {
        match count {
            4 => tile_nr::<4>(x, w, nr, out),
            3 => tile_nr::<3>(x, w, nr, out),
            2 => tile_nr::<2>(x, w, nr, out),
            _ => tile_nr::<1>(x, w, nr, out),
        }
    }

    /// The sum of one block in f64 (each value converted, eight partial sums).
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn sum64(x: *const f32) -> f64 {
        let mut s = _mm512_setzero_pd();
        let mut i = 0;
        while i < B {
            s = _mm512_add_pd(s, _mm512_cvtps_pd(_mm256_loadu_ps(x.add(i))));
            i += 8;
        }
        let mut l = [0f64; 8];
        _mm512_storeu_pd(l.as_mut_ptr(), s);
        l.iter().sum()
    }

    /// A tile's 16 sums added to `out` in f64: accumulator `4 r + t` to slot `4 t + r`.
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn finish(a: &[__m512; 16], out: *mut f64) {
        let s = reduce16(a);
        let lo = _mm512_cvtps_pd(_mm512_castps512_ps256(s));
        let hi = _mm512_cvtps_pd(_mm256_castpd_ps(_mm512_extractf64x4_pd::<1>(
            _mm512_castps_pd(s),
        )));
        _mm512_storeu_pd(out, _mm512_add_pd(_mm512_loadu_pd(out), lo));
        _mm512_storeu_pd(out.add(8), _mm512_add_pd(_mm512_loadu_pd(out.add(8)), hi));
    }

    /// The 16 lane sums of 16 vectors in one vector: lane `4 j + e` holds the sum of `a[4 e + j]`
    /// (four rounds, each halving the vectors: quarters of two vectors, then halves within
    /// 128-bit lanes).
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub(super) unsafe fn reduce16(a: &[__m512; 16]) -> __m512 {
        let b: [__m512; 8] = std::array::from_fn(|i| {
            let (x, y) = (a[2 * i], a[2 * i + 1]);
            _mm512_add_ps(
                _mm512_shuffle_f32x4::<0x44>(x, y),
                _mm512_shuffle_f32x4::<0xEE>(x, y),
            )
        });
        let c: [__m512; 4] = std::array::from_fn(|i| {
            let (x, y) = (b[2 * i], b[2 * i + 1]);
            _mm512_add_ps(
                _mm512_shuffle_f32x4::<0x88>(x, y),
                _mm512_shuffle_f32x4::<0xDD>(x, y),
            )
        });
        let d: [__m512; 2] = std::array::from_fn(|i| {
            let (x, y) = (c[2 * i], c[2 * i + 1]);
            _mm512_add_ps(
                _mm512_shuffle_ps::<0x44>(x, y),
                _mm512_shuffle_ps::<0xEE>(x, y),
            )
        });
        _mm512_add_ps(
            _mm512_shuffle_ps::<0x88>(d[0], d[1]),
            _mm512_shuffle_ps::<0xDD>(d[0], d[1]),
        )
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{Op, TilePlan, B};
    use std::arch::x86_64::*;

    walk!(
        "avx2,fma",
        __m256,
        8,
        8,
        _mm256_loadu_ps,
        _mm256_storeu_ps,
        _mm256_mul_ps,
        _mm256_add_ps,
        _mm256_fmadd_ps,
        _mm256_setzero_ps
    );

    /// The `count` nodes at `x` against the `nr` triples at `w`: nodes 0, 1 in slots 0..8, nodes
    /// 2, 3 in slots 8..16 (16 registers hold one 2 x 4 tile's accumulators and operands).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn chunk(x: *const f32, w: *const f32, count: usize, nr: usize, out: *mut f64) {
        for (half, rows) in [(0, count.min(2)), (1, count.saturating_sub(2))] {
            let (x, out) = (x.add(2 * half * B), out.add(8 * half));
            match rows {
                0 => {}
                2 => tile_nr::<2>(x, w, nr, out),
                _ => tile_nr::<1>(x, w, nr, out),
            }
        }
    }

    /// The sum of one block in f64 (each value converted, four partial sums).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn sum64(x: *const f32) -> f64 {
        let mut s = _mm256_setzero_pd();
        let mut i = 0;
        while i < B {
            s = _mm256_add_pd(s, _mm256_cvtps_pd(_mm_loadu_ps(x.add(i))));
            i += 4;
        }
        let mut l = [0f64; 4];
        _mm256_storeu_pd(l.as_mut_ptr(), s);
        l.iter().sum()
    }

    /// A tile's 8 sums added to `out` in f64, accumulator i to slot i.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn finish(a: &[__m256; 8], out: *mut f64) {
        let s = reduce8(a);
        let lo = _mm256_cvtps_pd(_mm256_castps256_ps128(s));
        let hi = _mm256_cvtps_pd(_mm256_extractf128_ps::<1>(s));
        _mm256_storeu_pd(out, _mm256_add_pd(_mm256_loadu_pd(out), lo));
        _mm256_storeu_pd(out.add(4), _mm256_add_pd(_mm256_loadu_pd(out.add(4)), hi));
    }

    /// The 8 lane sums of 8 vectors in one vector, lane i holding `a[i]`'s (horizontal adds of
    /// pairs, twice, then the two 128-bit halves).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub(super) unsafe fn reduce8(a: &[__m256; 8]) -> __m256 {
        let t: [__m256; 4] = std::array::from_fn(|i| _mm256_hadd_ps(a[2 * i], a[2 * i + 1]));
        let u0 = _mm256_hadd_ps(t[0], t[1]);
        let u1 = _mm256_hadd_ps(t[2], t[3]);
        _mm256_add_ps(
            _mm256_permute2f128_ps::<0x20>(u0, u1),
            _mm256_permute2f128_ps::<0x31>(u0, u1),
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::BasisLimits;

    fn basis(nv: usize, d: usize) -> Basis {
        let names: Vec<String> = (0..nv).map(|k| format!("z{k}")).collect();
        Basis::new(&names, d, BasisLimits::default()).unwrap()
    }

    #[test]
    fn every_candidate_has_exactly_one_slot() {
        for (nv, d) in [(1, 3), (2, 3), (3, 5), (5, 4), (4, 7), (11, 6), (13, 9)] {
            let b = basis(nv, d);
            let plan = TilePlan::new(&b, Isa::Avx512).expect("small enough");
            let plan2 = TilePlan::new(&b, Isa::Avx2).expect("small enough");
            let mut seen = vec![0; b.len()];
            for &j in plan.order().iter().chain(plan2.order()) {
                if j != u32::MAX {
                    seen[j as usize] += 1;
                }
            }
            assert!(seen.iter().all(|&c| c == 2), "n {nv} d {d}");
        }
        assert!(TilePlan::new(&basis(4, 2), Isa::Avx2).is_none());
        let big = TilePlan::new(&basis(13, 9), Isa::Avx512).expect("497,420 candidates");
        assert!(big.scratch_bytes() < 700_000);
        assert!(
            TilePlan::new(&basis(24, 3), Isa::Avx512).is_none(),
            "2,600 triples do not fit"
        );
    }

    #[test]
    fn every_instruction_set_gives_the_exact_sums() {
        let mut seed = 11u64;
        let mut u = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for (nv, d, n) in [(5, 5, 300), (3, 3, 256), (2, 6, 40)] {
            let b = basis(nv, d);
            let z: Vec<Vec<f64>> = (0..nv).map(|_| (0..n).map(|_| u()).collect()).collect();
            let v: Vec<f64> = (0..n).map(|_| u()).collect();
            for isa in [Isa::Avx512, Isa::Avx2] {
                if !available(isa) {
                    eprintln!("skipped {isa:?}: not on this CPU");
                    continue;
                }
                let plan = TilePlan::new(&b, isa).expect("small");
                let mut scratch = TileScratch::new(&plan);
                let mut acc = vec![0.0; plan.order().len()];
                for s0 in (0..n).step_by(B) {
                    let len = B.min(n - s0);
                    let mut zb = vec![0f32; nv * B];
                    for k in 0..nv {
                        for i in 0..len {
                            zb[k * B + i] = z[k][s0 + i] as f32;
                        }
                    }
                    scratch.load_v(&v[s0..s0 + len], 1.0);
                    sweep_block(&plan, &zb, &mut scratch, &mut acc);
                }
                let mut got = vec![f64::NAN; b.len()];
                for (slot, &j) in plan.order().iter().enumerate() {
                    if j != u32::MAX {
                        got[j as usize] = acc[slot];
                    }
                }
                for (j, g) in got.iter().enumerate() {
                    let terms = (0..n).map(|i| {
                        let zi: Vec<f64> = (0..nv).map(|k| z[k][i]).collect();
                        v[i] * b.code(j).eval(&zi)
                    });
                    let (exact, scale) = terms.fold((0.0, 0.0), |(s, a), t| (s + t, a + t.abs()));
                    assert!(
                        (g - exact).abs() <= 1e-5 * scale,
                        "{isa:?} n {nv} d {d}: {} {g} against {exact}",
                        b.name(j)
                    );
                }
            }
        }
    }

    #[test]
    fn the_reduction_puts_sum_4e_plus_j_in_lane_4j_plus_e() {
        if !available(Isa::Avx512) {
            eprintln!("skipped: no AVX-512F");
            return;
        }
        #[cfg(target_arch = "x86_64")]
        // SAFETY: AVX-512F checked above.
        unsafe {
            use std::arch::x86_64::*;
            let a: [__m512; 16] = std::array::from_fn(|i| {
                let l: [f32; 16] = std::array::from_fn(|k| (i * 100 + k) as f32);
                _mm512_loadu_ps(l.as_ptr())
            });
            let mut out = [0f32; 16];
            _mm512_storeu_ps(out.as_mut_ptr(), avx512::reduce16(&a));
            for lane in 0..16 {
                let i = 4 * (lane % 4) + lane / 4;
                assert_eq!(
                    out[lane],
                    (0..16).map(|k| (i * 100 + k) as f32).sum::<f32>()
                );
            }
        }
    }
}
