//! The candidate basis: every monomial of degree <= d in n_z named variables.
//!
//! # Order and encoding
//! Monomials are enumerated in *graded lexicographic* order: first the constant, then every
//! monomial of degree 1, 2, ..., d; within one degree, by the sorted list of variable indices
//! (with repetition) compared lexicographically. For n_z = 2 (a, b) and d = 2 that is
//! `1, a, b, a^2, a*b, b^2`.
//!
//! Each monomial is stored as a [`Code`]: its degree and its sorted variable indices packed
//! 5 bits each into one `u64` (so n_z <= 32 and d <= 12). Every monomial of degree k >= 1 has a
//! *parent*: the monomial with its last (largest) variable removed, which always comes earlier
//! in the order. An engine can therefore build every column with one multiply per
//! sample-candidate pair: `x_j = x_parent(j) * z_last(j)`.
//!
//! # Size
//! The count C(n_z + d, d) is computed exactly before anything is allocated; [`Basis::new`]
//! refuses a basis whose candidates exceed [`BasisLimits::max_candidates`] with an error that
//! gives the numbers.

use crate::error::{Error, Result};

/// Largest supported degree.
pub const MAX_DEGREE: usize = 12;
/// Largest supported number of variables.
pub const MAX_VARS: usize = 32;

/// Packed monomial: bits 60..64 hold the degree, bits 5k..5k+5 the k-th variable index
/// (non-decreasing in k).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Code(pub u64);

impl Code {
    pub const ONE: Code = Code(0);

    pub fn degree(self) -> usize {
        (self.0 >> 60) as usize
    }

    /// Variable index at position k (k < degree).
    pub fn var(self, k: usize) -> usize {
        ((self.0 >> (5 * k)) & 31) as usize
    }

    /// Iterator over the variable indices, with repetition, non-decreasing.
    pub fn vars(self) -> impl Iterator<Item = usize> {
        (0..self.degree()).map(move |k| self.var(k))
    }

    /// Exponent of every variable (length n_vars). Panics when a variable of the code is not
    /// below `n_vars`.
    pub fn exponents(self, n_vars: usize) -> Vec<u32> {
        let mut e = vec![0u32; n_vars];
        for v in self.vars() {
            e[v] += 1;
        }
        e
    }

    /// Appends variable `v` (which must be >= the current last one). When `self` already has
    /// degree [`MAX_DEGREE`] or `v` is [`MAX_VARS`] or more, debug builds panic and release
    /// builds return a wrong code; [`Code::from_exponents`] checks both limits.
    pub fn times(self, v: usize) -> Code {
        let d = self.degree();
        debug_assert!(d < MAX_DEGREE && v < MAX_VARS);
        let body = self.0 & ((1u64 << 60) - 1);
        Code(((d as u64 + 1) << 60) | body | ((v as u64) << (5 * d)))
    }

    /// Builds a code from exponents (length n_vars). Refuses a total degree above [`MAX_DEGREE`]
    /// and a positive exponent at an index of [`MAX_VARS`] or more.
    pub fn from_exponents(exps: &[u32]) -> Result<Code> {
        let mut c = Code::ONE;
        for (v, &e) in exps.iter().enumerate() {
            for _ in 0..e {
                if c.degree() >= MAX_DEGREE || v >= MAX_VARS {
                    return Err(Error::param(
                        "exponents",
                        format!("degree above {MAX_DEGREE} or more than {MAX_VARS} variables"),
                    ));
                }
                c = c.times(v);
            }
        }
        Ok(c)
    }

    /// Value of the monomial at one point `z`. Panics when one of the code's variables is not
    /// below `z.len()`.
    pub fn eval(self, z: &[f64]) -> f64 {
        self.vars().fold(1.0, |acc, v| acc * z[v])
    }

    /// The two 32-bit words the GPU shaders read: `lo` holds variables 0..6, `hi` variables
    /// 6..12 (5 bits each, low bits first) and the degree in bits 28..32 of `hi`.
    pub fn gpu_words(self) -> [u32; 2] {
        let d = self.degree();
        let mut lo = 0u32;
        let mut hi = (d as u32) << 28;
        for k in 0..d {
            let v = self.var(k) as u32;
            if k < 6 {
                lo |= v << (5 * k);
            } else {
                hi |= v << (5 * (k - 6));
            }
        }
        [lo, hi]
    }
}

/// Size limits checked before a basis is built.
#[derive(Debug, Clone, Copy)]
pub struct BasisLimits {
    pub max_candidates: u64,
}

impl Default for BasisLimits {
    fn default() -> Self {
        // 5e6 candidates keep the basis tables and per-candidate statistics well under 1 GiB.
        BasisLimits {
            max_candidates: 5_000_000,
        }
    }
}

/// Number of monomials of degree <= d in n variables, C(n + d, d); `None` on overflow.
pub fn count(n_vars: usize, degree: usize) -> Option<u64> {
    let mut c: u128 = 1;
    for k in 1..=degree as u128 {
        c = c.checked_mul(n_vars as u128 + k)? / k;
        if c > u64::MAX as u128 {
            return None;
        }
    }
    Some(c as u64)
}

/// Bytes of per-candidate bookkeeping (code, parent, last variable, mean, norm, correlation).
pub const BYTES_PER_CANDIDATE: u64 = 8 + 4 + 1 + 8 + 8 + 8;

/// All monomials of degree <= d in named variables, in the documented order.
#[derive(Debug, Clone)]
pub struct Basis {
    names: Vec<String>,
    degree: usize,
    codes: Vec<Code>,
    parents: Vec<u32>,
}

/// A model or basis degree a user may ask for: 1..=[`MAX_DEGREE`] (0 leaves only the constant).
/// Refuses 0 and degrees above [`MAX_DEGREE`].
pub fn check_degree(degree: usize) -> Result<()> {
    if (1..=MAX_DEGREE).contains(&degree) {
        Ok(())
    } else {
        Err(Error::param(
            "degree",
            format!("{degree} is outside 1..={MAX_DEGREE}"),
        ))
    }
}

impl Basis {
    /// Enumerates the basis, refusing sizes beyond `limits` before allocating. Refuses an empty
    /// name list, more than [`MAX_VARS`] names, a name given twice, a degree above [`MAX_DEGREE`]
    /// and more candidates than `limits.max_candidates`.
    ///
    /// ```
    /// use ctsid::basis::{Basis, BasisLimits};
    /// let names = ["y".to_string(), "y_d1".into(), "u".into()];
    /// let b = Basis::new(&names, 2, BasisLimits::default())?;
    /// // 1, three linear and six quadratic monomials.
    /// assert_eq!(b.len(), 10);
    /// assert!((0..b.len()).any(|j| b.name(j) == "y*u"));
    /// // The paper's size: 11 variables at degree 6 is 12,376 candidates.
    /// let eleven: Vec<String> = (0..11).map(|k| format!("z{k}")).collect();
    /// assert_eq!(Basis::new(&eleven, 6, BasisLimits::default())?.len(), 12_376);
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn new(names: &[String], degree: usize, limits: BasisLimits) -> Result<Basis> {
        let n = names.len();
        if n == 0 {
            return Err(Error::param("features", "at least one variable is needed"));
        }
        if n > MAX_VARS {
            return Err(Error::param(
                "features",
                format!("{n} variables; at most {MAX_VARS} are supported"),
            ));
        }
        if degree > MAX_DEGREE {
            return Err(Error::param(
                "degree",
                format!("{degree}; at most {MAX_DEGREE} is supported"),
            ));
        }
        if let Some((first, i)) = crate::util::first_repeat(names) {
            return Err(Error::param(
                "features",
                format!(
                    "'{}' is named twice (positions {} and {})",
                    names[i],
                    first + 1,
                    i + 1
                ),
            ));
        }
        // The constant candidate is named `1`: a variable named like a number would share its
        // name (and an expression could not tell it from the number), so that a channel named
        // `1` gave another model than the same data named `u`.
        if let Some(v) = names.iter().find(|v| crate::util::reads_as_number(v)) {
            return Err(Error::param(
                "features",
                format!("'{v}' {}; rename the channel", crate::util::READS_AS_NUMBER),
            ));
        }
        let total = count(n, degree).unwrap_or(u64::MAX);
        if total > limits.max_candidates {
            let mib = |c: u64| c as f64 * BYTES_PER_CANDIDATE as f64 / 1048576.0;
            return Err(Error::TooLarge {
                what: format!("the basis of degree {degree} in {n} variables ({total} candidates)"),
                needed_mib: mib(total),
                budget_mib: mib(limits.max_candidates),
                hint: format!(
                    "lower the degree or the number of features (limit: {} candidates)",
                    limits.max_candidates
                ),
            });
        }
        let total = total as usize;
        let mut codes = Vec::with_capacity(total);
        let mut parents = Vec::with_capacity(total);
        codes.push(Code::ONE);
        parents.push(u32::MAX);
        let mut prev_start = 0;
        for _ in 1..=degree {
            let prev_end = codes.len();
            for p in prev_start..prev_end {
                let pc = codes[p];
                let first = if pc.degree() == 0 {
                    0
                } else {
                    pc.var(pc.degree() - 1)
                };
                for v in first..n {
                    codes.push(pc.times(v));
                    parents.push(p as u32);
                }
            }
            prev_start = prev_end;
        }
        debug_assert_eq!(codes.len(), total);
        Ok(Basis {
            names: names.to_vec(),
            degree,
            codes,
            parents,
        })
    }

    pub fn len(&self) -> usize {
        self.codes.len()
    }

    pub fn is_empty(&self) -> bool {
        self.codes.is_empty()
    }

    pub fn degree(&self) -> usize {
        self.degree
    }

    pub fn n_vars(&self) -> usize {
        self.names.len()
    }

    pub fn names(&self) -> &[String] {
        &self.names
    }

    /// Code of monomial `j`. Panics when `j` is not below [`Basis::len`].
    pub fn code(&self, j: usize) -> Code {
        self.codes[j]
    }

    pub fn codes(&self) -> &[Code] {
        &self.codes
    }

    /// Index of the parent monomial (`None` for the constant). Panics when `j` is not below
    /// [`Basis::len`].
    pub fn parent(&self, j: usize) -> Option<usize> {
        let p = self.parents[j];
        (p != u32::MAX).then_some(p as usize)
    }

    /// Variable that multiplies the parent to give monomial j (`None` for the constant). Panics
    /// when `j` is not below [`Basis::len`].
    pub fn last_var(&self, j: usize) -> Option<usize> {
        let c = self.codes[j];
        (c.degree() > 0).then(|| c.var(c.degree() - 1))
    }

    /// Index of a monomial given by its code, if it is in the basis. `None` otherwise.
    pub fn index_of(&self, code: Code) -> Option<usize> {
        // Graded-lex order: codes of one degree are sorted by variable list; search by degree block.
        let d = code.degree();
        if d > self.degree {
            return None;
        }
        // (Not `count(n, d - 1)` for d = 0: a wrapped degree made it loop for 2^64 steps.)
        let start = match d {
            0 => 0,
            _ => count(self.n_vars(), d - 1).unwrap_or(0) as usize,
        };
        let end = count(self.n_vars(), d).unwrap() as usize;
        let key = |c: Code| c.vars().collect::<Vec<_>>();
        let target = key(code);
        self.codes[start..end]
            .binary_search_by(|c| key(*c).cmp(&target))
            .ok()
            .map(|i| start + i)
    }

    /// The monomial as people write it: `y_d1^2*u`, `1` for the constant. Panics when `j` is
    /// not below [`Basis::len`].
    pub fn name(&self, j: usize) -> String {
        monomial_name(self.codes[j], &self.names)
    }
}

/// Writes a monomial with variable names: `a^2*b`, `1` for the constant. Panics when a
/// variable of `code` is not below `names.len()`.
pub fn monomial_name(code: Code, names: &[String]) -> String {
    if code.degree() == 0 {
        return "1".to_string();
    }
    let e = code.exponents(names.len());
    let parts: Vec<String> = e
        .iter()
        .enumerate()
        .filter(|(_, &k)| k > 0)
        .map(|(v, &k)| {
            if k == 1 {
                names[v].clone()
            } else {
                format!("{}^{}", names[v], k)
            }
        })
        .collect();
    parts.join("*")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(n: usize) -> Vec<String> {
        (0..n).map(|i| format!("z{i}")).collect()
    }

    #[test]
    fn counts_match_binomials() {
        assert_eq!(count(11, 2), Some(78));
        assert_eq!(count(11, 4), Some(1365));
        assert_eq!(count(11, 6), Some(12376));
        assert_eq!(count(13, 9), Some(497420));
        for (n, d) in [(1, 0), (3, 3), (5, 4), (11, 6)] {
            assert_eq!(
                Basis::new(&names(n), d, BasisLimits::default())
                    .unwrap()
                    .len() as u64,
                count(n, d).unwrap()
            );
        }
    }

    #[test]
    fn order_parents_and_names() {
        let b = Basis::new(&["a".into(), "b".into()], 2, BasisLimits::default()).unwrap();
        let got: Vec<String> = (0..b.len()).map(|j| b.name(j)).collect();
        assert_eq!(got, ["1", "a", "b", "a^2", "a*b", "b^2"]);
        for j in 1..b.len() {
            let p = b.parent(j).unwrap();
            assert!(p < j);
            assert_eq!(b.code(p).times(b.last_var(j).unwrap()), b.code(j));
            assert_eq!(b.index_of(b.code(j)), Some(j));
        }
        let z = [2.0, 3.0];
        assert_eq!(b.code(4).eval(&z), 6.0);
        // The constant of a one-variable basis (its lookup once looped for 2^64 steps).
        let one = Basis::new(&["a".into()], 3, BasisLimits::default()).unwrap();
        assert_eq!(one.index_of(Code::ONE), Some(0));
        assert_eq!(one.index_of(one.code(3)), Some(3));
    }

    #[test]
    fn refuses_oversized_basis_with_numbers() {
        let err = Basis::new(&names(32), 12, BasisLimits::default()).unwrap_err();
        let msg = err.to_string();
        assert!(msg.contains("candidates") && msg.contains("MiB"), "{msg}");
    }

    #[test]
    fn gpu_words_roundtrip() {
        let b = Basis::new(&names(32), 3, BasisLimits::default()).unwrap();
        let c = b.code(b.len() - 1);
        let [lo, hi] = c.gpu_words();
        assert_eq!((hi >> 28) as usize, c.degree());
        assert_eq!((lo & 31) as usize, c.var(0));
    }
}
