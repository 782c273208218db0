//! The inner loops of the CPU engine: one block of samples against every candidate.
//!
//! The f32 path has an explicit AVX2 + FMA version (chosen at run time when the CPU has them);
//! f64 and CPUs without AVX2 use the portable loops, which LLVM vectorises for the baseline target.

use crate::basis::Basis;
use crate::engine::Features;
use std::ops::{Add, Mul, Sub};

/// The working precision of monomial products (f32 or f64).
pub trait Elem: Copy + Send + Sync + Default + Add<Output = Self> + Mul<Output = Self> + Sub<Output = Self> + 'static {
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
}

/// Depth-first list of the internal nodes of a basis (see the module docs of `cpu`).
#[derive(Debug, Clone)]
pub struct Plan {
    families: Vec<Family>,
    degree: usize,
    n_vars: usize,
}

impl Plan {
    pub fn new(basis: &Basis) -> Plan {
        let nc = basis.len();
        let mut first_child = vec![u32::MAX; nc];
        for j in 1..nc {
            let p = basis.parent(j).expect("non-constant monomials have parents");
            if first_child[p] == u32::MAX {
                first_child[p] = j as u32;
            }
        }
        let degree = basis.degree();
        let n_vars = basis.n_vars();
        let mut families = Vec::new();
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
                });
                if code.degree() + 1 < degree {
                    let start = first_child[j] as usize;
                    for c in (start..start + (n_vars - first_var)).rev() {
                        stack.push(c);
                    }
                }
            }
        }
        Plan { families, degree, n_vars }
    }

    pub fn degree(&self) -> usize {
        self.degree
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
}

impl<T: Elem> Scratch<T> {
    pub fn new(degree: usize, n_vars: usize, bsz: usize) -> Self {
        let mut vals = vec![T::ZERO; degree.max(1) * bsz];
        vals[..bsz].fill(T::ONE);
        Scratch { vals, vb: vec![T::ZERO; bsz], vz: vec![T::ZERO; n_vars * bsz] }
    }

    /// Loads one block of v (shorter than the block at the end: the rest is zero).
    pub fn load_v(&mut self, v: &[f64]) {
        for (d, s) in self.vb.iter_mut().zip(v) {
            *d = T::from_f64(*s);
        }
        self.vb[v.len()..].fill(T::ZERO);
    }
}

/// Adds one block's contribution `sum_i x_ij v_i` to `acc[j]` for every candidate j.
///
/// Per block, `vz_k = v * z_k` is formed once for every variable; the correlation of child
/// `p * z_k` is then `sum_i x_p,i vz_k,i`, one multiply-add per pair, with the parent values
/// `x_p` (themselves `x_parent(p) * z_var`) computed in the same pass.
pub fn sweep_block<T: Elem>(plan: &Plan, zb: &[T], bsz: usize, s: &mut Scratch<T>, acc: &mut [f64]) {
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
        if bsz == avx2::B && std::any::TypeId::of::<T>() == std::any::TypeId::of::<f32>() && avx2::available() {
            // SAFETY: T is f32 (checked above), so the slices can be reinterpreted; the CPU has AVX2 + FMA.
            unsafe {
                let zb = std::slice::from_raw_parts(zb.as_ptr() as *const f32, zb.len());
                let vz = std::slice::from_raw_parts(s.vz.as_ptr() as *const f32, s.vz.len());
                let vals = std::slice::from_raw_parts_mut(s.vals.as_mut_ptr() as *mut f32, s.vals.len());
                avx2::families_f32(plan, zb, vz, vals, acc);
            }
            return;
        }
    }
    families_generic(plan, zb, bsz, s, acc);
}

fn families_generic<T: Elem>(plan: &Plan, zb: &[T], bsz: usize, s: &mut Scratch<T>, acc: &mut [f64]) {
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
            acc[f.child_start as usize + t] += part.iter().map(|x| x.to_f64()).sum::<f64>();
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::Plan;
    use std::arch::x86_64::*;

    pub const B: usize = 128;

    pub fn available() -> bool {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }

    /// All families but the constant one (handled by the caller), f32 lanes, f64 totals.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn families_f32(plan: &Plan, zb: &[f32], vz: &[f32], vals: &mut [f32], acc: &mut [f64]) {
        let nv = plan.n_vars;
        let deg = plan.degree;
        assert!(zb.len() >= nv * B && vz.len() >= nv * B && vals.len() >= deg * B);
        let zp = zb.as_ptr();
        let vzp = vz.as_ptr();
        let vp = vals.as_mut_ptr();
        for f in plan.families.iter().skip(1) {
            let lvl = f.level as usize;
            let parent = vp.add((lvl - 1) * B) as *const f32;
            let me = vp.add(lvl * B);
            let zvar = zp.add(f.var as usize * B);
            // Leaves' parents (level d-1) never need their values again.
            let store = lvl + 1 < deg;
            let mut k = f.first_var as usize;
            let mut out = f.child_start as usize;
            let mut first = true;
            while k < nv {
                let m = (nv - k).min(8);
                let o = &mut acc[out..out + m];
                let z = vzp.add(k * B);
                macro_rules! go {
                    ($nt:literal) => {
                        if first && store {
                            tile::<$nt, true, true>(parent, zvar, me, z, o)
                        } else if first {
                            tile::<$nt, true, false>(parent, zvar, me, z, o)
                        } else {
                            tile::<$nt, false, false>(parent, zvar, me, z, o)
                        }
                    };
                }
                match m {
                    8 => go!(8),
                    7 => go!(7),
                    6 => go!(6),
                    5 => go!(5),
                    4 => go!(4),
                    3 => go!(3),
                    2 => go!(2),
                    _ => go!(1),
                }
                // Later tiles of the same family re-read the stored values.
                if first && !store && k + m < nv {
                    let mut c = 0;
                    while c < B {
                        _mm256_storeu_ps(me.add(c), _mm256_mul_ps(_mm256_loadu_ps(parent.add(c)), _mm256_loadu_ps(zvar.add(c))));
                        c += 8;
                    }
                }
                first = false;
                k += m;
                out += m;
            }
        }
    }

    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn tile<const NT: usize, const COMPUTE: bool, const STORE: bool>(
        parent: *const f32,
        zvar: *const f32,
        me: *mut f32,
        vz: *const f32,
        out: &mut [f64],
    ) {
        let mut a = [_mm256_setzero_ps(); NT];
        let mut c = 0;
        while c < B {
            let x = if COMPUTE {
                let x = _mm256_mul_ps(_mm256_loadu_ps(parent.add(c)), _mm256_loadu_ps(zvar.add(c)));
                if STORE {
                    _mm256_storeu_ps(me.add(c), x);
                }
                x
            } else {
                _mm256_loadu_ps(me.add(c))
            };
            for t in 0..NT {
                a[t] = _mm256_fmadd_ps(x, _mm256_loadu_ps(vz.add(t * B + c)), a[t]);
            }
            c += 8;
        }
        for t in 0..NT {
            let lo = _mm256_cvtps_pd(_mm256_castps256_ps128(a[t]));
            let hi = _mm256_cvtps_pd(_mm256_extractf128_ps(a[t], 1));
            let s = _mm256_add_pd(lo, hi);
            let mut buf = [0.0f64; 4];
            _mm256_storeu_pd(buf.as_mut_ptr(), s);
            out[t] += (buf[0] + buf[1]) + (buf[2] + buf[3]);
        }
    }
}

/// Adds one block's `sum_i w_i (x_ij - mean_j)^2` to `acc[j]` (f64; for column statistics).
pub fn centred_block(plan: &Plan, zb: &[f64], bsz: usize, s: &mut Scratch<f64>, mean: &[f64], acc: &mut [f64]) {
    let nv = plan.n_vars;
    let w = &s.vb;
    acc[0] += w.iter().map(|wi| wi * (1.0 - mean[0]).powi(2)).sum::<f64>();
    for f in &plan.families {
        let lvl = f.level as usize;
        if lvl > 0 {
            let (lo, hi) = s.vals.split_at_mut(lvl * bsz);
            let parent = &lo[(lvl - 1) * bsz..];
            let zk = &zb[f.var as usize * bsz..(f.var as usize + 1) * bsz];
            for i in 0..bsz {
                hi[i] = parent[i] * zk[i];
            }
        }
        let me = &s.vals[lvl * bsz..(lvl + 1) * bsz];
        for (t, k) in (f.first_var as usize..nv).enumerate() {
            let j = f.child_start as usize + t;
            let m = mean[j];
            let zk = &zb[k * bsz..(k + 1) * bsz];
            let mut sum = 0.0;
            for i in 0..bsz {
                let d = me[i] * zk[i] - m;
                sum += w[i] * d * d;
            }
            acc[j] += sum;
        }
    }
}
