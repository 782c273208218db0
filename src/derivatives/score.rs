//! Scoring against exact derivatives, as defined in `shared/signals/README.md`:
//! p_q = percentile(|estimate - truth|, q) / (1e-12 + median(|truth|)), linear interpolation
//! between order statistics, on all samples ("full") or with round(0.05 N) samples removed at
//! each end ("trimmed"). Also the calibration of sigma: the share of errors within 2 sigma, and
//! the Spearman rank correlation between sigma and |error|.

pub use crate::metrics::percentile;

/// Normalised error percentile p_q on samples [from, to). Panics when `from > to` or when `est`
/// or `truth` is shorter than `to`.
pub fn normalised_percentile(est: &[f64], truth: &[f64], q: f64, from: usize, to: usize) -> f64 {
    let err: Vec<f64> = (from..to).map(|i| (est[i] - truth[i]).abs()).collect();
    let med = percentile(
        &truth[from..to].iter().map(|v| v.abs()).collect::<Vec<_>>(),
        50.0,
    );
    percentile(&err, q) / (1e-12 + med)
}

/// Trimmed range: round(0.05 N) removed at each end.
pub fn trimmed_range(n: usize) -> (usize, usize) {
    let cut = (0.05 * n as f64).round() as usize;
    (cut, n - cut)
}

/// Share of samples whose error is within `k` sigma. Counts over the shortest of the three slices
/// but divides by `est.len()`; an empty `est` gives NaN.
pub fn coverage(est: &[f64], truth: &[f64], sigma: &[f64], k: f64) -> f64 {
    let inside = est
        .iter()
        .zip(truth)
        .zip(sigma)
        .filter(|((e, t), s)| (*e - *t).abs() <= k * **s)
        .count();
    inside as f64 / est.len() as f64
}

fn ranks(v: &[f64]) -> Vec<f64> {
    let mut idx: Vec<usize> = (0..v.len()).collect();
    idx.sort_by(|&a, &b| v[a].total_cmp(&v[b]));
    let mut r = vec![0.0; v.len()];
    let mut i = 0;
    while i < idx.len() {
        let mut j = i;
        while j + 1 < idx.len() && v[idx[j + 1]] == v[idx[i]] {
            j += 1;
        }
        let avg = 0.5 * (i + j) as f64;
        for t in i..=j {
            r[idx[t]] = avg;
        }
        i = j + 1;
    }
    r
}

/// Spearman rank correlation. Empty slices and a constant one give 0. Panics when `b` is shorter
/// than `a`.
pub fn spearman(a: &[f64], b: &[f64]) -> f64 {
    let (ra, rb) = (ranks(a), ranks(b));
    let n = a.len() as f64;
    let (ma, mb) = (ra.iter().sum::<f64>() / n, rb.iter().sum::<f64>() / n);
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for i in 0..a.len() {
        let (x, y) = (ra[i] - ma, rb[i] - mb);
        sab += x * y;
        saa += x * x;
        sbb += y * y;
    }
    sab / (saa * sbb).sqrt().max(1e-300)
}
