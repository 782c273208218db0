//! Conformance with scikit-learn's `lars_path` (fixtures copied from ../shared/fixtures/lars into
//! tests/data/lars; see the README there). Every breakpoint: same active set in the same order,
//! alphas and coefficients equal to 1e-8 relative.

use ctsid::engine::{CpuEngine, CpuOptions, DenseEngine, Precision, SweepEngine};
use ctsid::regression::{lars_path, PathOptions};

mod common;
use common::lars_fixtures::{load, problem, Fixture};

/// Runs the path on `engine` and compares with the fixture; `map` turns an engine candidate into a fixture column.
fn check(f: &Fixture, engine: &mut dyn SweepEngine, map: impl Fn(usize) -> usize, what: &str) {
    check_to(f, engine, map, what, 1e-8)
}

/// [`check`] to the relative tolerance `tol`.
fn check_to(
    f: &Fixture,
    engine: &mut dyn SweepEngine,
    map: impl Fn(usize) -> usize,
    what: &str,
    tol: f64,
) {
    let steps = f.alphas.len() - 1;
    let opts = PathOptions {
        method: f.method,
        max_terms: 10_000,
        max_steps: steps,
        ..PathOptions::default()
    };
    let path = lars_path(engine, &f.y, None, &opts).unwrap();
    assert_eq!(
        path.breakpoints.len(),
        f.alphas.len(),
        "{} ({what}): number of breakpoints, stop {:?}",
        f.name,
        path.stop
    );
    let a0 = f.alphas[0];
    for (k, bp) in path.breakpoints.iter().enumerate() {
        let want = f.alphas[k];
        assert!(
            (bp.alpha - want).abs() <= tol * want.abs() + 1e-14 * a0,
            "{} ({what}): alpha {k}: {} vs {want}",
            f.name,
            bp.alpha
        );
        let mut dense = vec![0.0; f.coefs[k].len()];
        for (id, c) in bp.active.iter().zip(&bp.coefs) {
            dense[map(*id)] = *c;
        }
        let scale = f.coefs[k].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (j, (got, want)) in dense.iter().zip(&f.coefs[k]).enumerate() {
            assert!(
                (got - want).abs() <= tol * scale,
                "{} ({what}): breakpoint {k} coef {j}: {got} vs {want}",
                f.name
            );
        }
    }
    let last: Vec<usize> = path
        .breakpoints
        .last()
        .unwrap()
        .active
        .iter()
        .map(|j| map(*j))
        .collect();
    assert_eq!(
        last, f.active,
        "{} ({what}): final active set and its order",
        f.name
    );
    assert!(path
        .events
        .iter()
        .all(|e| !matches!(e, ctsid::regression::Event::SkippedCollinear { .. })));
}

#[test]
fn sklearn_paths_on_the_given_design() {
    for f in load() {
        let mut e = DenseEngine::from_columns(&f.x_cols).unwrap();
        check(&f, &mut e, |j| j, "dense X");
    }
}

#[test]
fn sklearn_paths_from_z_through_the_basis_and_cpu_engine() {
    for f in load() {
        let (basis, feats) = problem(&f);
        for materialize in [0, usize::MAX] {
            let mut e = CpuEngine::new(
                &basis,
                &feats,
                CpuOptions {
                    precision: Precision::F64,
                    materialize_limit_bytes: materialize,
                },
            )
            .unwrap();
            assert_eq!(e.is_materialized(), materialize > 0);
            check(
                &f,
                &mut e,
                |j| j - 1,
                if materialize > 0 {
                    "basis, materialised"
                } else {
                    "basis, on the fly"
                },
            );
        }
    }
}

#[test]
fn exact_refreshes_do_not_change_the_path() {
    // refresh_tol = 0 recomputes every correlation by an exact sweep whenever a candidate enters.
    for f in load() {
        let mut e = DenseEngine::from_columns(&f.x_cols).unwrap();
        let steps = f.alphas.len() - 1;
        let opts = PathOptions {
            method: f.method,
            max_terms: 10_000,
            max_steps: steps,
            refresh_tol: 0.0,
            ..PathOptions::default()
        };
        let path = lars_path(&mut e, &f.y, None, &opts).unwrap();
        assert!(path.refreshes > 0, "{}", f.name);
        let scale = f
            .coefs
            .last()
            .unwrap()
            .iter()
            .fold(0.0f64, |m, x| m.max(x.abs()));
        let last = path.breakpoints.last().unwrap();
        assert_eq!(path.breakpoints.len(), f.alphas.len(), "{}", f.name);
        for (id, c) in last.active.iter().zip(&last.coefs) {
            assert!(
                (c - f.coefs.last().unwrap()[*id]).abs() <= 1e-8 * scale,
                "{}",
                f.name
            );
        }
    }
}

#[test]
fn alpha_min_interpolates_like_scikit_learn() {
    for f in load() {
        let k = 4;
        let alpha_min = 0.5 * (f.alphas[k - 1] + f.alphas[k]);
        let mut e = DenseEngine::from_columns(&f.x_cols).unwrap();
        let opts = PathOptions {
            method: f.method,
            max_terms: 10_000,
            max_steps: 10_000,
            alpha_min,
            ..PathOptions::default()
        };
        let path = lars_path(&mut e, &f.y, None, &opts).unwrap();
        assert_eq!(path.stop, ctsid::regression::StopReason::AlphaMin);
        assert_eq!(path.breakpoints.len(), k + 1, "{}", f.name);
        let last = path.breakpoints.last().unwrap();
        assert_eq!(last.alpha, alpha_min);
        let ss = (f.alphas[k - 1] - alpha_min) / (f.alphas[k - 1] - f.alphas[k]);
        let scale = f.coefs[k].iter().fold(0.0f64, |m, x| m.max(x.abs()));
        let mut dense = vec![0.0; f.coefs[k].len()];
        for (id, c) in last.active.iter().zip(&last.coefs) {
            dense[*id] = *c;
        }
        for (j, got) in dense.iter().enumerate() {
            let want = f.coefs[k - 1][j] + ss * (f.coefs[k][j] - f.coefs[k - 1][j]);
            assert!((got - want).abs() <= 1e-8 * scale, "{}: coef {j}", f.name);
        }
    }
}

#[test]
fn f32_sweeps_give_the_scikit_learn_paths() {
    // The f32 engine only steers the path (which candidate enters, which limits the step); the
    // breakpoints' numbers come from exact f64 columns, so every path, order of entry included,
    // matches scikit-learn's; on lar_collinear (a near-duplicate column) the f32 correlations
    // move a step length by 4.5e-8 relative, the others agree to 3e-8.
    for f in load() {
        let (basis, feats) = problem(&f);
        let mut e = CpuEngine::new(
            &basis,
            &feats,
            CpuOptions {
                precision: Precision::F32,
                materialize_limit_bytes: 0,
            },
        )
        .unwrap();
        check_to(&f, &mut e, |j| j - 1, "basis, f32 sweeps", 1e-7);
    }
}
