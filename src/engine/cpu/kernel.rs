//! The inner loops of the CPU engine: one block of samples against every candidate.
//!
//! The family loop has explicit SIMD versions (AVX2 + FMA, f32 and f64, and AVX-512 for f32,
//! chosen at run time from the CPU's features, see [`simd_level`]); other CPUs use the portable
//! loops.

use crate::basis::Basis;
use crate::engine::Features;
use std::ops::{Add, Mul, Sub};

/// The working precision of monomial products (f32 or f64).
pub trait Elem:
    Copy
    + Send
    + Sync
    + Default
    + Add<Output = Self>
    + Mul<Output = Self>
    + Sub<Output = Self>
    + 'static
{
    const ZERO: Self;
    const ONE: Self;
    fn from_f64(x: f64) -> Self;
    fn to_f64(self) -> f64;
}

impl Elem for f32 {
    const ZERO: f32 = 0.0;
    const ONE: f32 = 1.0;
    fn from_f64(x: f64) -> f32 {
        x as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl Elem for f64 {
    const ZERO: f64 = 0.0;
    const ONE: f64 = 1.0;
    fn from_f64(x: f64) -> f64 {
        x
    }
    fn to_f64(self) -> f64 {
        self
    }
}

/// One internal node of the monomial tree (degree < d) and its children.
#[derive(Debug, Clone, Copy)]
struct Family {
    /// Degree of the node: its values live in stack slot `level`.
    level: u8,
    /// Variable that multiplies the parent (slot level-1) to give this node (unused at level 0).
    var: u8,
    /// Children are `node * z_k` for k in `first_var..n_vars`, basis indices from `child_start`.
    first_var: u8,
    child_start: u32,
    /// Where the children's sums go in the sweep accumulator, which is in *plan order*: the
    /// children of each family are contiguous and families follow the depth-first walk, so a
    /// sweep writes its accumulator sequentially (basis order would scatter the writes over the
    /// whole array, one cache miss per family and block).
    out_start: u32,
}

/// Depth-first list of the internal nodes of a basis (see the module docs of `cpu`).
#[derive(Debug, Clone)]
pub struct Plan {
    families: Vec<Family>,
    /// Basis index of each accumulator position.
    order: Vec<u32>,
    degree: usize,
    n_vars: usize,
    /// Whether the SIMD loops may treat the two bottom levels together (see [`sweep_block`]):
    /// degree >= 3, and every level d-2 family is followed by its level d-1 child families,
    /// whose accumulator ranges continue its own.
    two_level: bool,
}

/// Start, in vectors of one block, of `w_a = z_a * vz_b` for b >= a in the pair table.
pub(super) fn pair_offset(a: usize, n: usize) -> usize {
    a * n - a * a.saturating_sub(1) / 2
}

impl Plan {
    pub fn new(basis: &Basis) -> Plan {
        let nc = basis.len();
        let mut first_child = vec![u32::MAX; nc];
        for j in 1..nc {
            let p = basis
                .parent(j)
                .expect("non-constant monomials have parents");
            if first_child[p] == u32::MAX {
                first_child[p] = j as u32;
            }
        }
        let degree = basis.degree();
        let n_vars = basis.n_vars();
        let mut families = Vec::new();
        let mut order = vec![0u32];
        if degree > 0 {
            // Explicit stack: (node index); children pushed in reverse to visit in basis order.
            let mut stack = vec![0usize];
            while let Some(j) = stack.pop() {
                let code = basis.code(j);
                let first_var = basis.last_var(j).unwrap_or(0);
                families.push(Family {
                    level: code.degree() as u8,
                    var: first_var as u8,
                    first_var: first_var as u8,
                    child_start: first_child[j],
                    out_start: order.len() as u32,
                });
                order.extend(first_child[j]..first_child[j] + (n_vars - first_var) as u32);
                if code.degree() + 1 < degree {
                    let start = first_child[j] as usize;
                    for c in (start..start + (n_vars - first_var)).rev() {
                        stack.push(c);
                    }
                }
            }
        }
        debug_assert_eq!(order.len(), nc);
        let two_level = degree >= 3 && {
            let mut ok = true;
            let mut i = 1;
            while ok && i < families.len() {
                let f = families[i];
                if f.level as usize + 2 == degree {
                    let m = n_vars - f.first_var as usize;
                    let mut out = f.out_start as usize + m;
                    for (t, c) in families[i + 1..].iter().take(m).enumerate() {
                        ok &= c.level as usize + 1 == degree
                            && c.first_var as usize == f.first_var as usize + t
                            && c.out_start as usize == out;
                        out += n_vars - c.first_var as usize;
                    }
                    ok &= i + m < families.len();
                    i += 1 + m;
                } else {
                    ok &= f.level as usize + 2 < degree;
                    i += 1;
                }
            }
            ok
        };
        Plan {
            families,
            order,
            degree,
            n_vars,
            two_level,
        }
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    /// Basis index of every accumulator position of [`sweep_block`].
    pub fn order(&self) -> &[u32] {
        &self.order
    }
}

/// Z rearranged block by block: block b, variable k, sample i at `(b * n_vars + k) * bsz + i`,
/// zero-padded past the last sample.
pub fn block_layout<T: Elem>(features: &Features, bsz: usize) -> Vec<T> {
    let n = features.n_samples;
    let nz = features.n_vars();
    let nb = n.div_ceil(bsz);
    let mut out = vec![T::ZERO; nb * nz * bsz];
    for b in 0..nb {
        for k in 0..nz {
            let col = features.column(k);
            let dst = &mut out[(b * nz + k) * bsz..(b * nz + k + 1) * bsz];
            for (i, d) in dst.iter_mut().enumerate() {
                let s = b * bsz + i;
                if s < n {
                    *d = T::from_f64(col[s]);
                }
            }
        }
    }
    out
}

/// Per-task scratch: the stack of node values (one slot per level), the block of v, and x_p * v.
pub struct Scratch<T> {
    vals: Vec<T>,
    vb: Vec<T>,
    /// v times each variable, for the current block.
    vz: Vec<T>,
    /// v times each pair of variables `z_a z_b` (a <= b, see [`pair_offset`]), for degree >= 3.
    w: Vec<T>,
}

impl<T: Elem> Scratch<T> {
    pub fn new(degree: usize, n_vars: usize, bsz: usize) -> Self {
        // Two slots more than the levels: the SIMD loops' sibling groups (three nodes of
        // degree d-2, in slots d-2, d-1 and d).
        let mut vals = vec![T::ZERO; (degree.max(1) + 2) * bsz];
        vals[..bsz].fill(T::ONE);
        let pairs = Self::pairs(degree, n_vars);
        Scratch {
            vals,
            vb: vec![T::ZERO; bsz],
            vz: vec![T::ZERO; n_vars * bsz],
            w: vec![T::ZERO; pairs * bsz],
        }
    }

    /// Elements [`Scratch::new`] allocates: the levels' slots, v, v z_k and the pair table.
    pub fn elements(degree: usize, n_vars: usize, bsz: usize) -> usize {
        (degree.max(1) + 2 + 1 + n_vars + Self::pairs(degree, n_vars)) * bsz
    }

    /// Vectors of the pair table `v z_a z_b` (only the two-level loop of degree 3 and up has one).
    fn pairs(degree: usize, n_vars: usize) -> usize {
        if degree >= 3 {
            n_vars * (n_vars + 1) / 2
        } else {
            0
        }
    }

    /// Loads one block of v times `scale` (shorter than the block at the end: the rest is zero).
    pub fn load_v(&mut self, v: &[f64], scale: f64) {
        for (d, s) in self.vb.iter_mut().zip(v) {
            *d = T::from_f64(*s * scale);
        }
        self.vb[v.len()..].fill(T::ZERO);
    }
}

/// Adds one block's contribution `sum_i x_ij v_i` to the accumulator of every candidate, in
/// plan order (`acc[p]` belongs to basis index `plan.order()[p]`).
///
/// Per block, `vz_k = v * z_k` is formed once for every variable; the correlation of child
/// `p * z_k` is then `sum_i x_p,i vz_k,i`, one multiply-add per pair, with the parent values
/// `x_p` (themselves `x_parent(p) * z_var`) computed in the same pass.
///
/// The SIMD loops go one step further at the bottom of the tree, where most candidates are
/// (59 % of 497,420 are leaves of degree 9, another 25 % have degree 8): with the pair table
/// `w_ab = v z_a z_b` formed once per block, a node q of degree d-2 yields the correlations of all
/// its children and grandchildren as plain dot products of x_q with vz and w, eight at a time.
/// The families of degree d-1 are never formed, and each load of x_q feeds eight multiply-adds,
/// which is what lifts the loop from per-family overhead towards the multiply-add limit.
pub fn sweep_block<T: Elem>(
    plan: &Plan,
    zb: &[T],
    bsz: usize,
    s: &mut Scratch<T>,
    acc: &mut [f64],
) {
    sweep_block_at(simd_level(), plan, zb, bsz, s, acc)
}

/// [`sweep_block`] with the instruction set named (as [`simd_level`] names them); a level the
/// CPU lacks must not be asked for (the tests ask only for what the CPU has).
fn sweep_block_at<T: Elem>(
    level: &str,
    plan: &Plan,
    zb: &[T],
    bsz: usize,
    s: &mut Scratch<T>,
    acc: &mut [f64],
) {
    let nv = plan.n_vars;
    // vz_k and the constant / degree-1 candidates.
    acc[0] += s.vb.iter().map(|x| x.to_f64()).sum::<f64>();
    for k in 0..nv {
        let zk = &zb[k * bsz..(k + 1) * bsz];
        let dst = &mut s.vz[k * bsz..(k + 1) * bsz];
        let mut sum = 0.0f64;
        for i in 0..bsz {
            dst[i] = s.vb[i] * zk[i];
            sum += dst[i].to_f64();
        }
        if plan.degree >= 1 {
            acc[1 + k] += sum;
        }
    }
    #[cfg(target_arch = "x86_64")]
    {
        use std::any::TypeId;
        if bsz == SIMD_B && level != "none" {
            if plan.two_level {
                for a in 0..nv {
                    let za = &zb[a * bsz..(a + 1) * bsz];
                    for b in a..nv {
                        let o = (pair_offset(a, nv) + b - a) * bsz;
                        let vzb = &s.vz[b * bsz..(b + 1) * bsz];
                        for ((d, x), y) in s.w[o..o + bsz].iter_mut().zip(za).zip(vzb) {
                            *d = *x * *y;
                        }
                    }
                }
            }
            // SAFETY: the slices are reinterpreted only as their own element type (checked by
            // TypeId), and each path runs only when the CPU has its instruction set.
            unsafe {
                macro_rules! run {
                    ($e:ty, $m:ident) => {{
                        let zb = std::slice::from_raw_parts(zb.as_ptr() as *const $e, zb.len());
                        let vz = std::slice::from_raw_parts(s.vz.as_ptr() as *const $e, s.vz.len());
                        let w = std::slice::from_raw_parts(s.w.as_ptr() as *const $e, s.w.len());
                        let vals = std::slice::from_raw_parts_mut(
                            s.vals.as_mut_ptr() as *mut $e,
                            s.vals.len(),
                        );
                        simd::$m::families(plan, zb, vz, w, vals, acc);
                        return;
                    }};
                }
                let is32 = TypeId::of::<T>() == TypeId::of::<f32>();
                let is64 = TypeId::of::<T>() == TypeId::of::<f64>();
                match (level, is32, is64) {
                    ("avx512", true, _) => run!(f32, avx512_f32),
                    ("avx2", true, _) => run!(f32, avx2_f32),
                    ("avx2" | "avx512", _, true) => run!(f64, avx2_f64),
                    _ => {}
                }
            }
        }
    }
    families_generic(plan, zb, bsz, s, acc);
}

fn families_generic<T: Elem>(
    plan: &Plan,
    zb: &[T],
    bsz: usize,
    s: &mut Scratch<T>,
    acc: &mut [f64],
) {
    let nv = plan.n_vars;
    for f in plan.families.iter().skip(1) {
        let lvl = f.level as usize;
        let (lo, hi) = s.vals.split_at_mut(lvl * bsz);
        let parent = &lo[(lvl - 1) * bsz..];
        let me = &mut hi[..bsz];
        let zk = &zb[f.var as usize * bsz..(f.var as usize + 1) * bsz];
        for i in 0..bsz {
            me[i] = parent[i] * zk[i];
        }
        for (t, k) in (f.first_var as usize..nv).enumerate() {
            let vz = &s.vz[k * bsz..(k + 1) * bsz];
            let mut part = [T::ZERO; 8];
            for c in (0..bsz).step_by(8) {
                for l in 0..8 {
                    part[l] = me[c + l] * vz[c + l] + part[l];
                }
            }
            acc[f.out_start as usize + t] += part.iter().map(|x| x.to_f64()).sum::<f64>();
        }
    }
}

/// Block size of the SIMD paths (f32 or f64 elements).
pub const SIMD_B: usize = 256;

/// Generates one SIMD implementation of the family loop (see [`sweep_block`]) for an element
/// type and an instruction set; `$hsum` reduces one accumulator vector to f64.
#[cfg(target_arch = "x86_64")]
macro_rules! simd_families {
    ($name:ident, $feat:literal, $t:ty, $v:ty, $lanes:literal, $load:ident, $store:ident, $mul:ident, $add:ident, $fma:ident, $zero:ident, $reduce:item) => {
        pub mod $name {
            use super::super::Plan;
            use std::arch::x86_64::*;

            const B: usize = super::super::SIMD_B;
            const L: usize = $lanes;

            $reduce

            /// All families but the constant one (handled by the caller).
            #[target_feature(enable = $feat)]
            pub unsafe fn families(plan: &Plan, zb: &[$t], vz: &[$t], w: &[$t], vals: &mut [$t], acc: &mut [f64]) {
                let nv = plan.n_vars;
                let deg = plan.degree;
                assert!(zb.len() >= nv * B && vz.len() >= nv * B && vals.len() >= (deg + 2) * B);
                let two = plan.two_level;
                assert!(!two || w.len() >= nv * (nv + 1) / 2 * B);
                let zp = zb.as_ptr();
                let vzp = vz.as_ptr();
                let wp = w.as_ptr();
                let vp = vals.as_mut_ptr();
                let fams = &plan.families;
                let mut i = 1;
                while i < fams.len() {
                    let f = fams[i];
                    let lvl = f.level as usize;
                    let parent = vp.add((lvl - 1) * B) as *const $t;
                    let me = vp.add(lvl * B);
                    let zvar = zp.add(f.var as usize * B);
                    let fv = f.first_var as usize;
                    let out = f.out_start as usize;
                    if two && lvl + 2 == deg {
                        let m = nv - fv;
                        // A family of this level right after a node's subtree is its next
                        // sibling (depth first): up to three go together.
                        let sib = |j: usize| j < fams.len() && fams[j].level as usize == lvl;
                        let (j1, j2) = (i + 1 + m, i + 1 + m + m);
                        let slot = |r: usize| vp.add((lvl + r) * B);
                        let zv = |j: usize| zp.add(fams[j].var as usize * B) as *const $t;
                        let os = |j: usize| fams[j].out_start as usize;
                        if sib(j1) && m >= 2 && sib(j2) {
                            group::<3>(fv, parent, [zvar, zv(j1), zv(j2)], [slot(0), slot(1), slot(2)], vzp, wp, nv, acc, [out, os(j1), os(j2)]);
                            i = j2 + 1 + (m - 2);
                            continue;
                        }
                        if sib(j1) {
                            group::<2>(fv, parent, [zvar, zv(j1)], [slot(0), slot(1)], vzp, wp, nv, acc, [out, os(j1)]);
                            i = j1 + 1 + (m - 1);
                            continue;
                        }
                        // Children against vz, grandchildren against the pair table; the
                        // child families that follow in the plan are covered here (Plan::new
                        // checked that their accumulators continue this one's).
                        let nw = nv * (nv + 1) / 2 - super::super::pair_offset(fv, nv);
                        run(parent, zvar, me, vzp.add(fv * B), m, &mut acc[out..out + m], true);
                        let wv = wp.add(super::super::pair_offset(fv, nv) * B);
                        run_n::<1>([me as *const $t], wv, nw, [acc[out + m..out + m + nw].as_mut_ptr()]);
                        i += 1 + m;
                        continue;
                    }
                    // Leaves' parents (level d-1) never need their values again.
                    let store = lvl + 1 < deg;
                    run(parent, zvar, me, vzp.add(fv * B), nv - fv, &mut acc[out..out + nv - fv], store);
                    i += 1;
                }
            }

            /// `G` consecutive sibling nodes of degree d-2, `x_r = parent * z_(fv+r)` (accumulators
            /// from `outs[r]`). Node r's vectors (vz from fv+r, the pairs from
            /// `pair_offset(fv+r)`) are a suffix of node r-1's, so region r (vz_(fv+r) and the
            /// pairs (fv+r, b); for the last node all that is left) is shared by nodes 0..=r, and
            /// one load of each of its vectors feeds them all: the pair table's traffic from L2
            /// per multiply-add falls to 1/G over the shared suffix.
            #[inline]
            #[allow(clippy::too_many_arguments)]
            #[target_feature(enable = $feat)]
            unsafe fn group<const G: usize>(fv: usize, parent: *const $t, zs: [*const $t; G], mes: [*mut $t; G], vzp: *const $t, wp: *const $t, nv: usize, acc: &mut [f64], outs: [usize; G]) {
                let mut c = 0;
                while c < B {
                    let p = $load(parent.add(c));
                    for r in 0..G {
                        $store(mes[r].add(c), $mul(p, $load(zs[r].add(c))));
                    }
                    c += L;
                }
                let po = |a: usize| super::super::pair_offset(a, nv);
                let npairs = nv * (nv + 1) / 2;
                // Node r's accumulators: m_r children, then its grandchildren.
                let m = |r: usize| nv - fv - r;
                for r in 0..G {
                    let end = outs[r] + m(r) + npairs - po(fv + r);
                    assert!(end <= acc.len() && (r + 1 == G || end <= outs[r + 1]));
                }
                let ap = acc.as_mut_ptr();
                let xs: [*const $t; G] = std::array::from_fn(|r| mes[r] as *const $t);
                for r in 0..G {
                    let last = r + 1 == G;
                    let nvz = if last { m(r) } else { 1 };
                    let npr = if last { npairs - po(fv + r) } else { po(fv + r + 1) - po(fv + r) };
                    let child = |s: usize| ap.add(outs[s] + (r - s));
                    let grand = |s: usize| ap.add(outs[s] + m(s) + po(fv + r) - po(fv + s));
                    let (vz, w) = (vzp.add((fv + r) * B), wp.add(po(fv + r) * B));
                    match r {
                        0 => {
                            run_n::<1>([xs[0]], vz, nvz, [child(0)]);
                            run_n::<1>([xs[0]], w, npr, [grand(0)]);
                        }
                        1 => {
                            run_n::<2>([xs[0], xs[1]], vz, nvz, [child(0), child(1)]);
                            run_n::<2>([xs[0], xs[1]], w, npr, [grand(0), grand(1)]);
                        }
                        _ => {
                            run_n::<3>([xs[0], xs[1], xs[2]], vz, nvz, [child(0), child(1), child(2)]);
                            run_n::<3>([xs[0], xs[1], xs[2]], w, npr, [grand(0), grand(1), grand(2)]);
                        }
                    }
                }
            }

            /// `outs[r][t] += sum_i xs[r]_i vecs_{t,i}` for `count` vectors and R nodes, in
            /// tiles of up to 8 / 6 / 4 vectors (R = 1 / 2 / 3: at most 12 accumulators, and K
            /// of them per pair where a tile is narrow, to break the multiply-add latency chain).
            #[inline]
            #[target_feature(enable = $feat)]
            unsafe fn run_n<const R: usize>(xs: [*const $t; R], vecs: *const $t, count: usize, outs: [*mut f64; R]) {
                let cap = [8, 6, 4][R - 1];
                let mut k = 0;
                while k < count {
                    let n = (count - k).min(cap);
                    let z = vecs.add(k * B);
                    let o: [*mut f64; R] = std::array::from_fn(|r| outs[r].add(k));
                    match (n, R) {
                        (8, _) => tile_n::<R, 8, 1>(xs, z, o),
                        (7, _) => tile_n::<R, 7, 1>(xs, z, o),
                        (6, _) => tile_n::<R, 6, 1>(xs, z, o),
                        (5, _) => tile_n::<R, 5, 1>(xs, z, o),
                        (4, 1) => tile_n::<R, 4, 2>(xs, z, o),
                        (4, _) => tile_n::<R, 4, 1>(xs, z, o),
                        (3, 1) | (3, 2) => tile_n::<R, 3, 2>(xs, z, o),
                        (3, _) => tile_n::<R, 3, 1>(xs, z, o),
                        (2, 3) => tile_n::<R, 2, 2>(xs, z, o),
                        (2, _) => tile_n::<R, 2, 4>(xs, z, o),
                        (_, 3) => tile_n::<R, 1, 2>(xs, z, o),
                        _ => tile_n::<R, 1, 4>(xs, z, o),
                    }
                    k += n;
                }
            }

            #[inline]
            #[target_feature(enable = $feat)]
            unsafe fn tile_n<const R: usize, const NT: usize, const K: usize>(xs: [*const $t; R], vz: *const $t, outs: [*mut f64; R]) {
                let mut a = [[[$zero(); NT]; R]; K];
                let mut c = 0;
                while c < B {
                    for k in 0..K {
                        let cc = c + k * L;
                        let x: [_; R] = std::array::from_fn(|r| $load(xs[r].add(cc)));
                        for t in 0..NT {
                            let w = $load(vz.add(t * B + cc));
                            for r in 0..R {
                                a[k][r][t] = $fma(x[r], w, a[k][r][t]);
                            }
                        }
                    }
                    c += K * L;
                }
                for k in 1..K {
                    for r in 0..R {
                        for t in 0..NT {
                            a[0][r][t] = $add(a[0][r][t], a[k][r][t]);
                        }
                    }
                }
                for r in 0..R {
                    reduce::<NT>(&a[0][r], std::slice::from_raw_parts_mut(outs[r], NT));
                }
            }

            /// `acc[t] += sum_i x_i vecs_{t,i}` for `count` vectors: x = parent * z_var is
            /// computed in the first tile of up to eight (and stored in `me` when STORE asks, or
            /// when later tiles need it); later tiles read it back through [`run_n`].
            #[inline]
            #[allow(clippy::too_many_arguments)]
            #[target_feature(enable = $feat)]
            unsafe fn run(parent: *const $t, zvar: *const $t, me: *mut $t, vecs: *const $t, count: usize, acc: &mut [f64], store: bool) {
                if count == 0 {
                    return;
                }
                let m = count.min(8);
                let o = &mut acc[..m];
                // K accumulators per child break the FMA latency chain when a family has few
                // children (most have 1 to 3); the same K as run_n's for one node.
                macro_rules! go {
                    ($nt:literal, $k:literal) => {
                        if store {
                            tile::<$nt, $k, true>(parent, zvar, me, vecs, o)
                        } else {
                            tile::<$nt, $k, false>(parent, zvar, me, vecs, o)
                        }
                    };
                }
                match m {
                    8 => go!(8, 1),
                    7 => go!(7, 1),
                    6 => go!(6, 1),
                    5 => go!(5, 1),
                    4 => go!(4, 2),
                    3 => go!(3, 2),
                    2 => go!(2, 4),
                    _ => go!(1, 4),
                }
                if m < count {
                    if !store {
                        let mut c = 0;
                        while c < B {
                            $store(me.add(c), $mul($load(parent.add(c)), $load(zvar.add(c))));
                            c += L;
                        }
                    }
                    run_n::<1>([me as *const $t], vecs.add(m * B), count - m, [acc[m..count].as_mut_ptr()]);
                }
            }

            /// `out[t] += sum_i x_i vz_{t,i}` for NT children, x = parent * z_var computed on the
            /// fly and stored for the subtree when STORE.
            #[inline]
            #[target_feature(enable = $feat)]
            unsafe fn tile<const NT: usize, const K: usize, const STORE: bool>(parent: *const $t, zvar: *const $t, me: *mut $t, vz: *const $t, out: &mut [f64]) {
                let mut a = [[$zero(); NT]; K];
                let mut c = 0;
                while c < B {
                    for k in 0..K {
                        let cc = c + k * L;
                        let x = $mul($load(parent.add(cc)), $load(zvar.add(cc)));
                        if STORE {
                            $store(me.add(cc), x);
                        }
                        for t in 0..NT {
                            a[k][t] = $fma(x, $load(vz.add(t * B + cc)), a[k][t]);
                        }
                    }
                    c += K * L;
                }
                for k in 1..K {
                    for t in 0..NT {
                        a[0][t] = $add(a[0][t], a[k][t]);
                    }
                }
                reduce::<NT>(&a[0], out);
            }
        }
    };
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use std::arch::x86_64::*;

    /// [`super::shifted_child`] with AVX2: the same eight lane sums of each, the same bits.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn shifted_child_avx2(x: &[f64], z: &[f64], w: &[f64], k: f64) -> (f64, f64) {
        let n = x.len();
        assert!(n.is_multiple_of(8) && z.len() >= n && w.len() >= n);
        let (xp, zp, wp) = (x.as_ptr(), z.as_ptr(), w.as_ptr());
        let kv = _mm256_set1_pd(k);
        let (mut s0, mut s1) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        let (mut q0, mut q1) = (_mm256_setzero_pd(), _mm256_setzero_pd());
        let mut c = 0;
        while c < n {
            let d0 = _mm256_sub_pd(
                _mm256_mul_pd(_mm256_loadu_pd(xp.add(c)), _mm256_loadu_pd(zp.add(c))),
                kv,
            );
            let d1 = _mm256_sub_pd(
                _mm256_mul_pd(
                    _mm256_loadu_pd(xp.add(c + 4)),
                    _mm256_loadu_pd(zp.add(c + 4)),
                ),
                kv,
            );
            let t0 = _mm256_mul_pd(_mm256_loadu_pd(wp.add(c)), d0);
            let t1 = _mm256_mul_pd(_mm256_loadu_pd(wp.add(c + 4)), d1);
            s0 = _mm256_add_pd(s0, t0);
            s1 = _mm256_add_pd(s1, t1);
            q0 = _mm256_add_pd(q0, _mm256_mul_pd(t0, d0));
            q1 = _mm256_add_pd(q1, _mm256_mul_pd(t1, d1));
            c += 8;
        }
        let (mut ps, mut pq) = ([0.0f64; 8], [0.0f64; 8]);
        _mm256_storeu_pd(ps.as_mut_ptr(), s0);
        _mm256_storeu_pd(ps.as_mut_ptr().add(4), s1);
        _mm256_storeu_pd(pq.as_mut_ptr(), q0);
        _mm256_storeu_pd(pq.as_mut_ptr().add(4), q1);
        (ps.iter().sum::<f64>(), pq.iter().sum::<f64>())
    }

    /// [`super::shifted_child`] for `NC` children `x z_v` of one node at once with AVX-512: one
    /// 8-lane vector per sum holds the portable loop's eight lane sums (lane l, samples l mod 8),
    /// so the bits are the same; the node's values and the weights are loaded once for all
    /// `NC` (a third of the loads of one child at a time). `z` holds the children's variables,
    /// `bsz` samples each from `z[0]`, the child c's at `z[vars[c] * bsz..]`.
    #[inline]
    #[target_feature(enable = "avx512f")]
    pub unsafe fn shifted_children_avx512<const NC: usize>(
        x: &[f64],
        z: &[f64],
        vars: [usize; NC],
        w: &[f64],
        k: [f64; NC],
        out: &mut [(f64, f64); NC],
    ) {
        let n = x.len();
        assert!(n.is_multiple_of(8) && w.len() >= n);
        assert!(vars.iter().all(|&v| z.len() >= (v + 1) * n));
        let (xp, wp) = (x.as_ptr(), w.as_ptr());
        let kv = k.map(|k| _mm512_set1_pd(k));
        let (mut s, mut q) = ([_mm512_setzero_pd(); NC], [_mm512_setzero_pd(); NC]);
        let mut c = 0;
        while c < n {
            let xv = _mm512_loadu_pd(xp.add(c));
            let wv = _mm512_loadu_pd(wp.add(c));
            for i in 0..NC {
                let zv = _mm512_loadu_pd(z.as_ptr().add(vars[i] * n + c));
                let d = _mm512_sub_pd(_mm512_mul_pd(xv, zv), kv[i]);
                let t = _mm512_mul_pd(wv, d);
                s[i] = _mm512_add_pd(s[i], t);
                q[i] = _mm512_add_pd(q[i], _mm512_mul_pd(t, d));
            }
            c += 8;
        }
        for i in 0..NC {
            let (mut ps, mut pq) = ([0.0f64; 8], [0.0f64; 8]);
            _mm512_storeu_pd(ps.as_mut_ptr(), s[i]);
            _mm512_storeu_pd(pq.as_mut_ptr(), q[i]);
            out[i] = (ps.iter().sum::<f64>(), pq.iter().sum::<f64>());
        }
    }

    /// Adds the lane sums of up to 8 f32 accumulators to `out` with one horizontal-add tree
    /// (10 instructions for 8 candidates instead of a full reduction each).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn reduce8_f32<const NT: usize>(a: &[__m256; NT], out: &mut [f64]) {
        let mut v = [_mm256_setzero_ps(); 8];
        v[..NT].copy_from_slice(a);
        let h01 = _mm256_hadd_ps(v[0], v[1]);
        let h23 = _mm256_hadd_ps(v[2], v[3]);
        let h45 = _mm256_hadd_ps(v[4], v[5]);
        let h67 = _mm256_hadd_ps(v[6], v[7]);
        let q0 = _mm256_hadd_ps(h01, h23);
        let q1 = _mm256_hadd_ps(h45, h67);
        let s0 = _mm_add_ps(_mm256_castps256_ps128(q0), _mm256_extractf128_ps(q0, 1));
        let s1 = _mm_add_ps(_mm256_castps256_ps128(q1), _mm256_extractf128_ps(q1, 1));
        let mut buf = [0.0f64; 8];
        _mm256_storeu_pd(buf.as_mut_ptr(), _mm256_cvtps_pd(s0));
        _mm256_storeu_pd(buf.as_mut_ptr().add(4), _mm256_cvtps_pd(s1));
        for t in 0..NT {
            out[t] += buf[t];
        }
    }

    simd_families!(
        avx2_f32,
        "avx2,fma",
        f32,
        __m256,
        8,
        _mm256_loadu_ps,
        _mm256_storeu_ps,
        _mm256_mul_ps,
        _mm256_add_ps,
        _mm256_fmadd_ps,
        _mm256_setzero_ps,
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn reduce<const NT: usize>(a: &[__m256; NT], out: &mut [f64]) {
            super::reduce8_f32::<NT>(a, out)
        }
    );
    simd_families!(
        avx512_f32,
        "avx512f,avx2,fma",
        f32,
        __m512,
        16,
        _mm512_loadu_ps,
        _mm512_storeu_ps,
        _mm512_mul_ps,
        _mm512_add_ps,
        _mm512_fmadd_ps,
        _mm512_setzero_ps,
        #[inline]
        #[target_feature(enable = "avx512f,avx2,fma")]
        unsafe fn reduce<const NT: usize>(a: &[__m512; NT], out: &mut [f64]) {
            // Each accumulator's 16 lanes summed in f32 halves first (8 + 8), as the AVX2
            // kernel's 8 lanes, then through its horizontal-add tree.
            let halves: [__m256; NT] = std::array::from_fn(|t| {
                let lo = _mm512_castps512_ps256(a[t]);
                let hi = _mm256_castpd_ps(_mm512_extractf64x4_pd(_mm512_castps_pd(a[t]), 1));
                _mm256_add_ps(lo, hi)
            });
            super::reduce8_f32::<NT>(&halves, out)
        }
    );
    simd_families!(
        avx2_f64,
        "avx2,fma",
        f64,
        __m256d,
        4,
        _mm256_loadu_pd,
        _mm256_storeu_pd,
        _mm256_mul_pd,
        _mm256_add_pd,
        _mm256_fmadd_pd,
        _mm256_setzero_pd,
        #[inline]
        #[target_feature(enable = "avx2,fma")]
        unsafe fn reduce<const NT: usize>(a: &[__m256d; NT], out: &mut [f64]) {
            for t in 0..NT {
                let h = _mm_add_pd(_mm256_castpd256_pd128(a[t]), _mm256_extractf128_pd(a[t], 1));
                out[t] += _mm_cvtsd_f64(_mm_add_sd(h, _mm_unpackhi_pd(h, h)));
            }
        }
    );
}

/// The instruction set the sweeps use on this CPU (for reports): `avx512` where the CPU has
/// AVX-512F (the f32 family loop in 16 lanes; f64 sweeps and statistics stay on AVX2), `avx2`
/// with AVX2 + FMA. `CTSID_SIMD=avx2` keeps AVX2, `CTSID_SIMD=none` the portable loops. (AVX-512
/// f32 sweeps at 25,000 x 12,376 measured 5-14 % faster than AVX2 on a Cascade Lake host with two
/// 512-bit FMA units, 16 % at 497,420; an earlier host's measured no faster.)
pub fn simd_level() -> &'static str {
    static LEVEL: std::sync::OnceLock<&'static str> = std::sync::OnceLock::new();
    LEVEL.get_or_init(|| {
        let want = std::env::var("CTSID_SIMD").unwrap_or_default();
        #[cfg(target_arch = "x86_64")]
        {
            let avx2 = std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma");
            let avx512 = std::arch::is_x86_feature_detected!("avx512f");
            if avx2 && avx512 && want != "none" && want != "avx2" {
                return "avx512";
            }
            if avx2 && want != "none" {
                return "avx2";
            }
        }
        let _ = want;
        "none"
    })
}

/// Adds one block's `sum_i w_i (x_ij - k_j)` to `acc[j]` and `sum_i w_i (x_ij - k_j)^2` to
/// `acc[len + j]` (f64, `len` candidates; for column statistics in one pass).
///
/// With a shift `k_j` within a few standard deviations of the column's mean, the variance
/// `S2 - S1^2 / sw` keeps nearly all of f64's digits (the cancellation is `1 + (m - k)^2 / var`),
/// and the caller checks that it does.
pub fn shifted_block(
    plan: &Plan,
    zb: &[f64],
    bsz: usize,
    s: &mut Scratch<f64>,
    shift: &[f64],
    acc: &mut [f64],
) {
    shifted_block_at(simd_level(), plan, zb, bsz, s, shift, acc)
}

/// [`shifted_block`] with the instruction set `level` (one [`simd_level`] can give on this CPU).
fn shifted_block_at(
    level: &str,
    plan: &Plan,
    zb: &[f64],
    bsz: usize,
    s: &mut Scratch<f64>,
    shift: &[f64],
    acc: &mut [f64],
) {
    #[cfg(target_arch = "x86_64")]
    {
        if level == "avx512" && bsz.is_multiple_of(8) {
            // SAFETY: the CPU has AVX-512F (simd_level checked it).
            unsafe { shifted_block_avx512(plan, zb, bsz, s, shift, acc) };
            return;
        }
        if level != "none" && bsz.is_multiple_of(8) {
            #[target_feature(enable = "avx2,fma")]
            unsafe fn avx2(
                plan: &Plan,
                zb: &[f64],
                bsz: usize,
                s: &mut Scratch<f64>,
                shift: &[f64],
                acc: &mut [f64],
            ) {
                shifted_block_impl(plan, zb, bsz, s, shift, acc, |x, z, w, k| {
                    // SAFETY: called only here, where the CPU has AVX2 + FMA.
                    unsafe { simd::shifted_child_avx2(x, z, w, k) }
                })
            }
            // SAFETY: the CPU has AVX2 + FMA (simd_level checked it).
            unsafe { avx2(plan, zb, bsz, s, shift, acc) };
            return;
        }
    }
    shifted_block_impl(plan, zb, bsz, s, shift, acc, shifted_child)
}

/// [`shifted_block_impl`] with the children of each node four at a time
/// ([`simd::shifted_children_avx512`]; the same bits).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn shifted_block_avx512(
    plan: &Plan,
    zb: &[f64],
    bsz: usize,
    s: &mut Scratch<f64>,
    shift: &[f64],
    acc: &mut [f64],
) {
    let nv = plan.n_vars;
    let (sums, squares) = acc.split_at_mut(shift.len());
    constant_column(&s.vb, shift[0], sums, squares);
    for f in &plan.families {
        let lvl = f.level as usize;
        node_values(s, zb, bsz, f);
        let me = &s.vals[lvl * bsz..(lvl + 1) * bsz];
        let w = &s.vb;
        let j0 = f.child_start as usize;
        let v0 = f.first_var as usize;
        let mut v = v0;
        macro_rules! group {
            ($nc:literal) => {{
                let vars: [usize; $nc] = std::array::from_fn(|i| v + i);
                let k: [f64; $nc] = std::array::from_fn(|i| shift[j0 + v - v0 + i]);
                let mut out = [(0.0, 0.0); $nc];
                // SAFETY: the caller has AVX-512F; every variable's block is inside zb.
                unsafe { simd::shifted_children_avx512(me, zb, vars, w, k, &mut out) };
                for (i, (a, b)) in out.into_iter().enumerate() {
                    sums[j0 + v - v0 + i] += a;
                    squares[j0 + v - v0 + i] += b;
                }
                v += $nc;
            }};
        }
        while v + 4 <= nv {
            group!(4);
        }
        while v < nv {
            group!(1);
        }
    }
}

/// The constant candidate (index 0) in a block's shifted sums.
#[inline(always)]
fn constant_column(w: &[f64], k: f64, sums: &mut [f64], squares: &mut [f64]) {
    for wi in w {
        let d = 1.0 - k;
        sums[0] += wi * d;
        squares[0] += wi * d * d;
    }
}

/// A family's node values: its parent's times its variable (level 0 is the ones).
#[inline(always)]
fn node_values(s: &mut Scratch<f64>, zb: &[f64], bsz: usize, f: &Family) {
    let lvl = f.level as usize;
    if lvl > 0 {
        let (lo, hi) = s.vals.split_at_mut(lvl * bsz);
        let parent = &lo[(lvl - 1) * bsz..];
        let zk = &zb[f.var as usize * bsz..(f.var as usize + 1) * bsz];
        for i in 0..bsz {
            hi[i] = parent[i] * zk[i];
        }
    }
}

/// `sum_i w_i (x_i z_i - k)` and `sum_i w_i (x_i z_i - k)^2` over a block whose length is a
/// multiple of 8, as eight lane sums each added in order at the end (the AVX2 version,
/// [`simd::shifted_child_avx2`], gives the same bits).
fn shifted_child(x: &[f64], z: &[f64], w: &[f64], k: f64) -> (f64, f64) {
    let (mut ps, mut pq) = ([0.0f64; 8], [0.0f64; 8]);
    for ((x, z), wc) in x
        .chunks_exact(8)
        .zip(z.chunks_exact(8))
        .zip(w.chunks_exact(8))
    {
        for l in 0..8 {
            let d = x[l] * z[l] - k;
            let t = wc[l] * d;
            ps[l] += t;
            pq[l] += t * d;
        }
    }
    (ps.iter().sum::<f64>(), pq.iter().sum::<f64>())
}

#[inline(always)]
fn shifted_block_impl(
    plan: &Plan,
    zb: &[f64],
    bsz: usize,
    s: &mut Scratch<f64>,
    shift: &[f64],
    acc: &mut [f64],
    child: impl Fn(&[f64], &[f64], &[f64], f64) -> (f64, f64),
) {
    let nv = plan.n_vars;
    let (sums, squares) = acc.split_at_mut(shift.len());
    constant_column(&s.vb, shift[0], sums, squares);
    for f in &plan.families {
        let lvl = f.level as usize;
        node_values(s, zb, bsz, f);
        let me = &s.vals[lvl * bsz..(lvl + 1) * bsz];
        let w = &s.vb;
        for (t, v) in (f.first_var as usize..nv).enumerate() {
            let j = f.child_start as usize + t;
            let k = shift[j];
            let zk = &zb[v * bsz..(v + 1) * bsz];
            let (a, b) = if bsz.is_multiple_of(8) {
                child(me, zk, w, k)
            } else {
                (0..bsz).fold((0.0, 0.0), |(a, b), i| {
                    let d = me[i] * zk[i] - k;
                    (a + w[i] * d, b + w[i] * d * d)
                })
            };
            sums[j] += a;
            squares[j] += b;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::basis::{Basis, BasisLimits};

    /// The instruction sets [`simd_level`] can give on this CPU, the portable loops first.
    fn levels_here() -> Vec<&'static str> {
        let mut levels = vec!["none"];
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                levels.push("avx2");
            }
            if std::arch::is_x86_feature_detected!("avx512f") && levels.contains(&"avx2") {
                levels.push("avx512");
            }
        }
        levels
    }

    /// Uniform numbers in [-1, 1) from `seed` (a linear congruential generator).
    fn uniform(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        }
    }

    /// Every instruction set this CPU has gives the portable loops' shifted sums of the column
    /// statistics to the bit (eight lane sums each, added in order), and those are the sums
    /// written out per candidate.
    #[test]
    fn every_simd_instance_gives_the_portable_shifted_sums_to_the_bit() {
        let levels = levels_here();
        let mut next = uniform(13);
        for (nz, d) in [(4, 6), (7, 3), (11, 4), (3, 2), (6, 1)] {
            let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
            let basis = Basis::new(&names, d, BasisLimits::default()).unwrap();
            let plan = Plan::new(&basis);
            let zb: Vec<f64> = (0..nz * SIMD_B).map(|_| next()).collect();
            let w: Vec<f64> = (0..SIMD_B).map(|_| next().abs()).collect();
            let shift: Vec<f64> = (0..basis.len()).map(|_| 0.1 * next()).collect();
            let sums = |level: &str| {
                let mut s = Scratch::<f64>::new(d, nz, SIMD_B);
                s.load_v(&w, 1.0);
                let mut acc = vec![0.0; 2 * basis.len()];
                shifted_block_at(level, &plan, &zb, SIMD_B, &mut s, &shift, &mut acc);
                acc
            };
            let reference = sums("none");
            // Against sums written out for every candidate (the plan's slots are the basis's).
            for j in 0..basis.len() {
                let (mut a, mut b) = (0.0, 0.0);
                for i in 0..SIMD_B {
                    let x: f64 = basis.code(j).vars().map(|v| zb[v * SIMD_B + i]).product();
                    a += w[i] * (x - shift[j]);
                    b += w[i] * (x - shift[j]).powi(2);
                }
                assert!((reference[j] - a).abs() < 1e-12, "n {nz} d {d}, {j}");
                assert!(
                    (reference[basis.len() + j] - b).abs() < 1e-12,
                    "n {nz} d {d}, {j}"
                );
            }
            for level in &levels[1..] {
                assert_eq!(sums(level), reference, "{level}, n {nz} d {d}");
            }
        }
    }

    /// Every instruction set this CPU has gives the portable loops' block sums (f32, to the
    /// rounding of different summation orders): on a CPU with AVX-512 the engine no longer runs
    /// the AVX2 instance, which only this test then checks.
    #[test]
    fn every_simd_instance_gives_the_portable_block_sums() {
        let levels = levels_here();
        let mut next = uniform(11);
        for (nz, d) in [(4, 6), (7, 3), (11, 4), (3, 2)] {
            let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
            let basis = Basis::new(&names, d, BasisLimits::default()).unwrap();
            let plan = Plan::new(&basis);
            let zb: Vec<f32> = (0..nz * SIMD_B).map(|_| next() as f32).collect();
            let v: Vec<f64> = (0..SIMD_B).map(|_| next()).collect();
            let sums = |level: &str| {
                let mut s = Scratch::<f32>::new(d, nz, SIMD_B);
                s.load_v(&v, 1.0);
                let mut acc = vec![0.0; basis.len()];
                sweep_block_at(level, &plan, &zb, SIMD_B, &mut s, &mut acc);
                acc
            };
            let reference = sums("none");
            for level in &levels[1..] {
                let got = sums(level);
                for (p, (g, r)) in got.iter().zip(&reference).enumerate() {
                    // Sums of 256 products of values below 1: f32 rounding of either order.
                    assert!(
                        (g - r).abs() <= 1e-4,
                        "{level}, n {nz} d {d}, position {p}: {g} vs {r}"
                    );
                }
            }
        }
    }
}
