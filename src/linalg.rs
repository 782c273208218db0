//! Small dense linear algebra shared by the simulator and the controller design: eigenvalues
//! that converge on the matrices models produce (companion matrices, entries 1e6 apart).

use nalgebra::DMatrix;

use crate::error::{Error, Result};

/// Eigenvalues (re, im) of a square matrix, sorted by real part then imaginary part; an error
/// when the matrix is not finite or the Schur iteration does not converge. Panics when `m` is
/// not square.
pub fn eigenvalues(m: &DMatrix<f64>) -> Result<Vec<(f64, f64)>> {
    if m.iter().any(|v| !v.is_finite()) {
        return Err(Error::InvalidData(
            "a linearisation is not finite (the model or plant overflows there)".into(),
        ));
    }
    // Balanced first: companion matrices of fast plants hold entries 1e6 apart, and the Schur
    // iteration's error scales with the matrix norm.
    let mut bal = m.clone();
    balance(&mut bal);
    // The shifted QR iteration can stall on a matrix whose eigenvalues lie symmetric about the
    // origin (the companion matrix of y^(4) = -a y + u: the four roots of -a). An orthogonal
    // similarity keeps the eigenvalues and breaks that symmetry of the iteration: up to three
    // seeded rotations are tried before the error.
    let mut rng = crate::plants::rng::Rng::new(0x6569_6773);
    let mut attempt = bal.clone();
    let mut schur = None;
    for _ in 0..4 {
        schur = nalgebra::Schur::try_new(attempt.clone(), f64::EPSILON, 10_000);
        if schur.is_some() {
            break;
        }
        let n = bal.nrows();
        let r = DMatrix::from_fn(n, n, |_, _| rng.uniform() - 0.5);
        let q = r.qr().q();
        attempt = q.transpose() * &bal * &q;
    }
    let schur = schur.ok_or_else(|| {
        Error::InvalidData("the eigenvalues of a linearisation did not converge".into())
    })?;
    let mut e: Vec<(f64, f64)> = schur
        .complex_eigenvalues()
        .iter()
        .map(|c| (c.re, c.im))
        .collect();
    e.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    Ok(e)
}

/// Diagonal similarity scaling by powers of two (Parlett-Reinsch) that evens out each row's and
/// column's off-diagonal 1-norms; exact, so the eigenvalues do not change. Written here because
/// nalgebra's version squares the norms and never ends on entries beyond 1e154 (their squares
/// are infinite); this one takes each scale in one step and stops after a bounded number of sweeps.
fn balance(m: &mut DMatrix<f64>) {
    let n = m.nrows();
    for _ in 0..64 {
        let mut changed = false;
        for i in 0..n {
            let (mut c, mut r) = (0.0, 0.0);
            for j in (0..n).filter(|&j| j != i) {
                c += m[(j, i)].abs();
                r += m[(i, j)].abs();
            }
            if !(c > 0.0 && r > 0.0 && c.is_finite() && r.is_finite()) {
                continue;
            }
            // Column i times f and row i over f: c f = r / f at f = sqrt(r / c), to a power of 2.
            let e = (0.5 * (r.log2() - c.log2())).round().clamp(-500.0, 500.0) as i32;
            let f = 2f64.powi(e);
            if e != 0 && c * f + r / f < 0.95 * (c + r) {
                for j in (0..n).filter(|&j| j != i) {
                    m[(j, i)] *= f;
                    m[(i, j)] /= f;
                }
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
}
