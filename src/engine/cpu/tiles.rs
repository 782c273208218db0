//! The f32 sweep as small matrix products: nodes times triples, in register tiles (AVX-512).
//!
//! Every monomial of degree 3 or more is, in exactly one way, a *node* (its first variables in
//! sorted order, degree 0..=d-3) times a *triple* `z_a z_b z_c` (its last three, a <= b <= c)
//! with the node's last variable at most a. With the nodes ordered by their last variable (the
//! constant first), the nodes that a triple of first variable `a` meets are a *prefix* of that
//! list, `Q(a)` long. So per block of [`B`] samples, with the values of every node formed once,
//! the correlations of all candidates of degree >= 3 are, for each `a`, one dense product: the
//! first `Q(a)` node rows against the values `v z_a z_b z_c` of the triples of first variable
//! `a`. It runs in register tiles of 4 nodes x 4 triples (8 vector loads per 16 multiply-adds),
//! whereas the family kernel (module `kernel`), where a node meets only its own children's
//! pairs, loads one vector per one to three multiply-adds. Four triples at a time are formed
//! (from the pairs `v z_a z_b`) into a buffer that stays in L1 while every node meets them:
//! stored for the whole block they would be 286 more vectors written to L2 (one sweep 7 %
//! slower in a C model of the kernel). The 16 accumulators of a
//! tile (16 lanes each) are reduced together by one transposed tree into one vector of 16 sums,
//! added to 16 consecutive f64 slots. Candidates of degree 0, 1 and 2 are plain sums of `v`,
//! `v z_k` and `v z_a z_b`.
//!
//! Measured (25,000 x 12,376, n_z = 11, d = 6, this host's AVX-512, one thread): see
//! `docs/method/regression.md`, "Nodes times triples".
//!
//! Memory: one task's scratch holds (1 + n_z + pairs + 4 + nodes) vectors of [`B`] f32:
//! 456 KB at n_z = 11, d = 6. The engine uses this kernel where that is at most
//! [`MAX_SCRATCH_BYTES`] (it must stay in one core's L2), else the family kernel.

use crate::basis::{Basis, Code};

/// Samples per block (the engine's f32 block size).
pub const B: usize = super::kernel::SIMD_B;

/// The largest scratch (bytes per task) this kernel is chosen for.
pub const MAX_SCRATCH_BYTES: usize = 1_000_000;

/// One register tile: `mr` nodes from `node` against `nr` triples from `triple`.
#[derive(Debug, Clone, Copy)]
struct Tile {
    node: u32,
    triple: u32,
    mr: u8,
    nr: u8,
}

/// The nodes, triples and tiles of one basis, and which candidate each accumulator slot holds.
#[derive(Debug, Clone)]
pub struct TilePlan {
    n_vars: usize,
    /// `(a, b)` of each pair, a <= b, in the order `a` then `b`.
    pairs: Vec<(u8, u8)>,
    /// Each triple as (its pair `(a, b)`, c), in the order `a`, `b`, `c`.
    triples: Vec<(u32, u8)>,
    /// Each node after the constant as (parent node, variable); nodes by last variable.
    nodes: Vec<(u32, u8)>,
    tiles: Vec<Tile>,
    /// Basis index of every slot (`u32::MAX` for a tile's unused slots): 16 per tile, then the
    /// constant, the variables and the pairs.
    order: Vec<u32>,
}

/// Product of two monomial codes (the variables of `b` appended in order; both sorted, and
/// every variable of `b` at least the last of `a`).
fn product(a: Code, b: Code) -> Code {
    b.vars().fold(a, |c, v| c.times(v))
}

impl TilePlan {
    /// The plan of `basis`, or `None` below degree 3 or where one task's scratch would exceed
    /// [`MAX_SCRATCH_BYTES`].
    pub fn new(basis: &Basis) -> Option<TilePlan> {
        let (nv, d) = (basis.n_vars(), basis.degree());
        if d < 3 || nv == 0 {
            return None;
        }
        let pairs: Vec<(u8, u8)> = (0..nv)
            .flat_map(|a| (a..nv).map(move |b| (a as u8, b as u8)))
            .collect();
        let pair_of = |a: usize, b: usize| super::kernel::pair_offset(a, nv) + b - a;
        let mut triples = Vec::new();
        let mut first_triple = vec![0usize; nv + 1];
        for a in 0..nv {
            first_triple[a] = triples.len();
            for b in a..nv {
                for c in b..nv {
                    triples.push((pair_of(a, b) as u32, c as u8));
                }
            }
        }
        first_triple[nv] = triples.len();
        // Nodes of degree <= d-3 by last variable; within a group, parents before children.
        let mut codes = vec![Code::ONE];
        let mut nodes = Vec::new();
        let mut prefix = vec![0usize; nv];
        for f in 0..nv {
            let start = codes.len();
            let mut j = 0;
            while j < codes.len() {
                let c = codes[j];
                let last_ok = j >= start || c.degree() == 0 || c.var(c.degree() - 1) < f;
                if last_ok && c.degree() + 3 < d {
                    codes.push(c.times(f));
                    nodes.push((j as u32, f as u8));
                }
                j += 1;
            }
            prefix[f] = codes.len();
        }
        let scratch = (1 + nv + pairs.len() + 4 + codes.len()) * B * 4;
        if scratch > MAX_SCRATCH_BYTES {
            return None;
        }
        let triple_code = |t: usize| {
            let (p, c) = triples[t];
            let (a, b) = pairs[p as usize];
            Code::ONE
                .times(a as usize)
                .times(b as usize)
                .times(c as usize)
        };
        let mut tiles = Vec::new();
        let mut order = Vec::new();
        for a in 0..nv {
            for t0 in (first_triple[a]..first_triple[a + 1]).step_by(4) {
                let nr = (first_triple[a + 1] - t0).min(4);
                for r0 in (0..prefix[a]).step_by(4) {
                    let mr = (prefix[a] - r0).min(4);
                    tiles.push(Tile {
                        node: r0 as u32,
                        triple: t0 as u32,
                        mr: mr as u8,
                        nr: nr as u8,
                    });
                    // Slot 4 t + r of a tile holds node r against triple t (see `reduce16`).
                    for lane in 0..16 {
                        let (r, t) = (lane % 4, lane / 4);
                        let j = (r < mr && t < nr).then(|| {
                            let code = product(codes[r0 + r], triple_code(t0 + t));
                            basis.index_of(code).expect("every product is a candidate") as u32
                        });
                        order.push(j.unwrap_or(u32::MAX));
                    }
                }
            }
        }
        let index = |c: Code| basis.index_of(c).expect("low degrees are candidates") as u32;
        order.push(index(Code::ONE));
        order.extend((0..nv).map(|k| index(Code::ONE.times(k))));
        order.extend(
            pairs
                .iter()
                .map(|&(a, b)| index(Code::ONE.times(a as usize).times(b as usize))),
        );
        Some(TilePlan {
            n_vars: nv,
            pairs,
            triples,
            nodes,
            tiles,
            order,
        })
    }

    /// Basis index of every accumulator slot (`u32::MAX`: unused).
    pub fn order(&self) -> &[u32] {
        &self.order
    }

    /// Vectors of [`B`] f32 in one task's scratch.
    fn vectors(&self) -> usize {
        1 + self.n_vars + self.pairs.len() + 4 + 1 + self.nodes.len()
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

/// One task's vectors: v, `v z_k`, `v z_a z_b`, four triples `v z_a z_b z_c`, the nodes.
pub struct TileScratch {
    lines: Vec<Line>,
}

impl TileScratch {
    pub fn new(plan: &TilePlan) -> TileScratch {
        TileScratch {
            lines: vec![Line::default(); plan.vectors() * B / 16],
        }
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

/// Whether this CPU runs the kernel (AVX-512F).
pub fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Adds one block's `sum_i x_ij v_i` to `acc` in slot order ([`TilePlan::order`]). `zb` holds
/// the block's `n_vars` vectors of [`B`] samples (zero past the data), `s` the block's v
/// ([`TileScratch::load_v`]). Panics where the CPU lacks AVX-512F (see [`available`]) or the
/// slices are shorter than the plan needs.
pub fn sweep_block(plan: &TilePlan, zb: &[f32], s: &mut TileScratch, acc: &mut [f64]) {
    assert!(available(), "the tile kernel needs AVX-512F");
    assert!(zb.len() >= plan.n_vars * B && acc.len() >= plan.order.len());
    assert_eq!(s.lines.len(), plan.vectors() * B / 16);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: the CPU has AVX-512F (asserted), and every pointer the kernel forms stays inside
    // `zb`, the scratch and `acc`, whose lengths are asserted above.
    unsafe {
        avx512::block(plan, zb, s.floats(), acc)
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{TilePlan, B};
    use std::arch::x86_64::*;

    #[target_feature(enable = "avx512f")]
    pub unsafe fn block(plan: &TilePlan, zb: &[f32], f: &mut [f32], acc: &mut [f64]) {
        let nv = plan.n_vars;
        let base = f.as_mut_ptr();
        let v = base;
        let vz = base.add(B);
        let pw = vz.add(nv * B);
        let tw = pw.add(plan.pairs.len() * B);
        let nodes = tw.add(4 * B);
        let z = zb.as_ptr();
        let low = plan.tiles.len() * 16;
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
        let ones = _mm512_set1_ps(1.0);
        let mut i = 0;
        while i < B {
            _mm512_storeu_ps(nodes.add(i), ones);
            i += 16;
        }
        for (j, &(parent, var)) in plan.nodes.iter().enumerate() {
            let x = nodes.add(parent as usize * B);
            mul(x, z.add(var as usize * B), nodes.add((j + 1) * B));
        }
        let out = acc.as_mut_ptr();
        let mut formed = u32::MAX;
        for (k, t) in plan.tiles.iter().enumerate() {
            if t.triple != formed {
                formed = t.triple;
                for r in 0..t.nr as usize {
                    let (p, c) = plan.triples[t.triple as usize + r];
                    mul(pw.add(p as usize * B), z.add(c as usize * B), tw.add(r * B));
                }
            }
            let x = nodes.add(t.node as usize * B) as *const f32;
            let w = tw as *const f32;
            let o = out.add(16 * k);
            match (t.mr, t.nr) {
                (4, 4) => tile::<4, 4>(x, w, o),
                (4, 3) => tile::<4, 3>(x, w, o),
                (4, 2) => tile::<4, 2>(x, w, o),
                (4, 1) => tile::<4, 1>(x, w, o),
                (3, 4) => tile::<3, 4>(x, w, o),
                (3, 3) => tile::<3, 3>(x, w, o),
                (3, 2) => tile::<3, 2>(x, w, o),
                (3, 1) => tile::<3, 1>(x, w, o),
                (2, 4) => tile::<2, 4>(x, w, o),
                (2, 3) => tile::<2, 3>(x, w, o),
                (2, 2) => tile::<2, 2>(x, w, o),
                (2, 1) => tile::<2, 1>(x, w, o),
                (1, 4) => tile::<1, 4>(x, w, o),
                (1, 3) => tile::<1, 3>(x, w, o),
                (1, 2) => tile::<1, 2>(x, w, o),
                _ => tile::<1, 1>(x, w, o),
            }
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

    /// `out = x * y` over one block; returns the lane sums of `out`.
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn mul(x: *const f32, y: *const f32, out: *mut f32) -> __m512 {
        let mut sum = _mm512_setzero_ps();
        let mut i = 0;
        while i < B {
            let p = _mm512_mul_ps(_mm512_loadu_ps(x.add(i)), _mm512_loadu_ps(y.add(i)));
            _mm512_storeu_ps(out.add(i), p);
            sum = _mm512_add_ps(sum, p);
            i += 16;
        }
        sum
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn hsum(x: __m512) -> f64 {
        let mut l = [0f32; 16];
        _mm512_storeu_ps(l.as_mut_ptr(), x);
        l.iter().map(|x| *x as f64).sum()
    }

    /// Node rows `x + r B` (r < MR) against triple rows `w + t B` (t < NR) over one block; the
    /// sums added to `out[4 t + r]` in f64.
    #[inline]
    #[target_feature(enable = "avx512f")]
    unsafe fn tile<const MR: usize, const NR: usize>(x: *const f32, w: *const f32, out: *mut f64) {
        let mut a = [_mm512_setzero_ps(); 16];
        let mut i = 0;
        while i < B {
            let xs: [__m512; MR] = std::array::from_fn(|r| _mm512_loadu_ps(x.add(r * B + i)));
            for t in 0..NR {
                let wt = _mm512_loadu_ps(w.add(t * B + i));
                for r in 0..MR {
                    a[4 * r + t] = _mm512_fmadd_ps(xs[r], wt, a[4 * r + t]);
                }
            }
            i += 16;
        }
        let s = reduce16(&a);
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
        for (nv, d) in [(1, 3), (2, 3), (3, 5), (5, 4), (4, 7), (11, 6)] {
            let b = basis(nv, d);
            let plan = TilePlan::new(&b).expect("small enough");
            let mut seen = vec![0; b.len()];
            for &j in plan.order() {
                if j != u32::MAX {
                    seen[j as usize] += 1;
                }
            }
            assert!(seen.iter().all(|&c| c == 1), "n {nv} d {d}");
        }
        assert!(TilePlan::new(&basis(4, 2)).is_none());
        assert!(
            TilePlan::new(&basis(13, 9)).is_none(),
            "497,420 candidates need the family kernel"
        );
    }

    #[test]
    fn the_reduction_puts_sum_4e_plus_j_in_lane_4j_plus_e() {
        if !available() {
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
