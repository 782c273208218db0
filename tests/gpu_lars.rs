//! Whole LARS / LassoLars paths on the GPU engine against the CPU engine in f64.
//!
//! The path algorithm is shared (`lars_path` over `dyn SweepEngine`); what differs is only where
//! the sweeps come from. The GPU builds monomials in f32 from f32-rounded Z and sums in f64, so
//! every correlation it returns carries an error of order 1e-7 of `sum_i |x_ij v_i|`. The path
//! uses those correlations to pick the entering candidate and the step lengths; the active-set
//! algebra is f64 on exact columns on both engines. Checked here, at every breakpoint:
//! the same active candidates in the same order, the same added/dropped events, alpha and every
//! coefficient within 1e-10 of the breakpoint's largest |coefficient| (1e-6, the bound,
//! on the fixtures with a near-duplicate column), and the same stop reason.
//!
//! Cases: (a) random polynomial problems, 3,000 samples x 924 candidates (n_z = 6, d = 6), drawn
//! fresh per case from their own seed, sparse truth plus noise, LAR and lasso; (b) every
//! scikit-learn fixture in tests/data/lars, with the candidates built from the fixture's Z
//! through the basis (as tests/regression_sklearn.rs does for the CPU engine); (c) the complete
//! `Regression::fit_with_engine` (path, eBIC choice, pruning, f64 refit) on the random problems,
//! for LAR, the lasso and forward orthogonal least squares.
//!
//! Why parity is exact and not merely close: `lars_path` takes from the sweeps only *choices*
//! (which candidate enters, which one limits the step); the numbers that make a breakpoint (the
//! entering candidate's correlation C, hence alpha, and the limiting candidate's correlation
//! and direction product, hence gamma and the coefficients) are recomputed from exact f64
//! columns on either engine. So both engines produce the same breakpoints to rounding as long as
//! the f32 sweeps make the same choices, which fails only when two candidates tie within the
//! f32 error (~1e-7 relative): then no f32 engine can promise the f64 order, and the test would
//! report the breakpoint where the choice differed.
//! Measured on lavapipe: no difference at all on every case but lar_collinear (1.2e-7), whose
//! near-duplicate column lets the f32 correlations move a step length. Without that recomputation the f32 sweeps
//! put 2e-6 .. 1e-5 relative errors into alphas and coefficients (seen on these cases), above the
//! issue's 1e-6.
//!
//! Runs on any Vulkan adapter, lavapipe included. Without one each test prints
//! "skipping: no GPU adapter" and passes, unless CTSID_REQUIRE_GPU=1, where that is a failure.
#![cfg(feature = "gpu")]

use std::time::Instant;

use ctsid::basis::{Basis, BasisLimits, Code};
use ctsid::engine::gpu::{GpuEngine, GpuOptions};
use ctsid::engine::{CpuEngine, CpuOptions, Features, Precision, SweepEngine};
use ctsid::regression::{lars_path, Event, Method, Path, PathOptions, Regression};
use ctsid::Error;
mod common;
use common::lars_fixtures::{load, problem};
use common::rng::SplitMix as Rng;

/// Relative tolerance of alphas and coefficients where a column nearly duplicates another (the
/// `*_collinear` fixtures): there the f32 correlations can move a step length (lar_collinear:
/// 1.2e-7 on lavapipe); issue 4's "coefficients to 1e-6 relative".
const TOL: f64 = 1e-6;

/// Everywhere else the parity is exact (measured 0 on lavapipe, see the module docs); this bound
/// leaves room for the f64 rounding of a different summation order only.
const TOL_EXACT: f64 = 1e-10;

fn require_gpu() -> bool {
    std::env::var("CTSID_REQUIRE_GPU").as_deref() == Ok("1")
}

/// The engine, or None (with the notice) where there is no adapter and none is required.
fn gpu_or_skip(f: &Features, b: &Basis) -> Option<GpuEngine> {
    match GpuEngine::new(f, b, GpuOptions::default()) {
        Ok(e) => Some(e),
        Err(Error::NoGpu(msg)) => {
            if require_gpu() {
                panic!("CTSID_REQUIRE_GPU=1 but there is no GPU adapter: {msg}");
            }
            println!("skipping: no GPU adapter ({msg})");
            None
        }
        Err(e) => panic!("GPU engine construction failed: {e}"),
    }
}

fn cpu64(b: &Basis, f: &Features) -> CpuEngine {
    CpuEngine::new(
        b,
        f,
        CpuOptions {
            precision: Precision::F64,
            ..CpuOptions::default()
        },
    )
    .unwrap()
}

/// Added / dropped events in order (refreshes may differ between engines: they are a
/// numerical safeguard, not part of the path).
fn moves(p: &Path) -> Vec<(bool, usize, usize)> {
    p.events
        .iter()
        .filter_map(|e| match e {
            Event::Added { step, candidate } => Some((true, *step, *candidate)),
            Event::Dropped { step, candidate } => Some((false, *step, *candidate)),
            _ => None,
        })
        .collect()
}

/// Every breakpoint of `gpu` against `cpu` (see the module docs); returns the worst relative
/// coefficient difference.
fn compare_paths(cpu: &Path, gpu: &Path, label: &str, tol: f64) -> f64 {
    assert_eq!(
        moves(gpu),
        moves(cpu),
        "{label}: added/dropped events (entering order)"
    );
    assert_eq!(
        gpu.breakpoints.len(),
        cpu.breakpoints.len(),
        "{label}: number of breakpoints (stop cpu {:?}, gpu {:?})",
        cpu.stop,
        gpu.stop
    );
    assert_eq!(gpu.stop, cpu.stop, "{label}: stop reason");
    let a0 = cpu.breakpoints[0].alpha;
    let mut worst = 0.0f64;
    for (k, (c, g)) in cpu.breakpoints.iter().zip(&gpu.breakpoints).enumerate() {
        assert_eq!(g.active, c.active, "{label}: breakpoint {k}: active set");
        assert!(
            (g.alpha - c.alpha).abs() <= tol * c.alpha.abs() + 1e-12 * a0,
            "{label}: breakpoint {k}: alpha gpu {} vs cpu {}",
            g.alpha,
            c.alpha
        );
        let scale = c.coefs.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (q, (gc, cc)) in g.coefs.iter().zip(&c.coefs).enumerate() {
            let rel = (gc - cc).abs() / scale.max(f64::MIN_POSITIVE);
            assert!(
                rel <= tol,
                "{label}: breakpoint {k}: coefficient of candidate {}: gpu {gc} vs cpu {cc} (rel {rel:.2e})",
                c.active[q]
            );
            worst = worst.max(rel);
        }
    }
    worst
}

/// A random polynomial problem: Z uniform in [-1, 1], y = a few random monomials of the basis
/// with coefficients of either sign in [0.5, 2], plus 1 % noise.
fn random_problem(seed: u64, n_s: usize, n_z: usize, d: usize) -> (Basis, Features, Vec<f64>) {
    let mut rng = Rng(seed);
    let names: Vec<String> = (0..n_z).map(|k| format!("z{k}")).collect();
    let basis = Basis::new(&names, d, BasisLimits::default()).unwrap();
    let cols: Vec<Vec<f64>> = (0..n_z)
        .map(|_| (0..n_s).map(|_| rng.uniform(-1.0, 1.0)).collect())
        .collect();
    let f = Features::new(names, cols).unwrap();
    let n_terms = 3 + rng.below(4);
    let mut y = vec![0.0; n_s];
    for _ in 0..n_terms {
        let j = 1 + rng.below(basis.len() - 1);
        let c = rng.uniform(0.5, 2.0) * if rng.below(2) == 0 { -1.0 } else { 1.0 };
        let code: Code = basis.code(j);
        for (i, yi) in y.iter_mut().enumerate() {
            let z: Vec<f64> = (0..n_z).map(|k| f.column(k)[i]).collect();
            *yi += c * code.eval(&z);
        }
    }
    let sd = (y.iter().map(|v| v * v).sum::<f64>() / n_s as f64).sqrt();
    for yi in &mut y {
        *yi += 0.01 * sd * rng.normal12();
    }
    (basis, f, y)
}

#[test]
fn random_polynomial_paths_match_the_cpu_engine() {
    // Fresh data per case (its own seed); LAR and lasso. About 3,000 x 924 as the issue asks.
    let cases = [
        (0x1A55_0001u64, Method::Lars),
        (0x1A55_0002, Method::LassoLars),
        (0x1A55_0003, Method::LassoLars),
    ];
    for (seed, method) in cases {
        let (basis, f, y) = random_problem(seed, 3000, 6, 6);
        let Some(mut gpu) = gpu_or_skip(&f, &basis) else {
            return;
        };
        // Not a CPU-against-CPU comparison: the GPU's raw sweeps differ from f64 ones (f32 products).
        let (mut sg, mut sc) = (vec![0.0; basis.len()], vec![0.0; basis.len()]);
        gpu.sweep(&y, &mut sg).unwrap();
        cpu64(&basis, &f).sweep(&y, &mut sc).unwrap();
        assert!(
            sg.iter().zip(&sc).any(|(a, b)| a != b),
            "seed {seed:#x}: the GPU sweep is bit-identical to f64"
        );
        let opts = PathOptions {
            method,
            max_terms: 25,
            max_steps: 40,
            ..PathOptions::default()
        };
        let t = Instant::now();
        let cpu_path = lars_path(&mut cpu64(&basis, &f), &y, None, &opts).unwrap();
        let t_cpu = t.elapsed();
        let t = Instant::now();
        let gpu_path = lars_path(&mut gpu, &y, None, &opts).unwrap();
        let t_gpu = t.elapsed();
        let label = format!("seed {seed:#x} {method:?} ({} candidates)", basis.len());
        let worst = compare_paths(&cpu_path, &gpu_path, &label, TOL_EXACT);
        assert!(
            cpu_path.breakpoints.len() > 20,
            "{label}: the path is too short to test anything ({} breakpoints)",
            cpu_path.breakpoints.len()
        );
        println!(
            "{label}: {} breakpoints, {} gpu sweeps ({} refreshes), worst coef diff {worst:.1e}; cpu f64 {t_cpu:?}, gpu {t_gpu:?}",
            gpu_path.breakpoints.len(),
            gpu_path.sweeps,
            gpu_path.refreshes
        );
    }
}

#[test]
fn weighted_path_matches_the_cpu_engine() {
    let (basis, f, y) = random_problem(0x1A55_0010, 3000, 6, 6);
    let Some(mut gpu) = gpu_or_skip(&f, &basis) else {
        return;
    };
    let mut rng = Rng(0x1A55_0011);
    let w: Vec<f64> = (0..y.len()).map(|_| rng.uniform(0.2, 3.0)).collect();
    let opts = PathOptions {
        max_terms: 20,
        max_steps: 30,
        ..PathOptions::default()
    };
    let cpu_path = lars_path(&mut cpu64(&basis, &f), &y, Some(&w), &opts).unwrap();
    let gpu_path = lars_path(&mut gpu, &y, Some(&w), &opts).unwrap();
    let worst = compare_paths(&cpu_path, &gpu_path, "weighted lasso", TOL_EXACT);
    println!(
        "weighted lasso: {} breakpoints, worst coef diff {worst:.1e}",
        gpu_path.breakpoints.len()
    );
}

#[test]
fn sklearn_fixture_paths_match_the_cpu_engine() {
    let mut ran = 0;
    for fx in load() {
        let (basis, feats) = problem(&fx);
        let Some(mut gpu) = gpu_or_skip(&feats, &basis) else {
            return;
        };
        let opts = PathOptions {
            method: fx.method,
            max_terms: 10_000,
            max_steps: fx.steps(),
            ..PathOptions::default()
        };
        let cpu_path = lars_path(&mut cpu64(&basis, &feats), &fx.y, None, &opts).unwrap();
        assert_eq!(
            cpu_path.breakpoints.len(),
            fx.steps() + 1,
            "{}: the CPU engine's path is not the fixture's",
            fx.name
        );
        let gpu_path = lars_path(&mut gpu, &fx.y, None, &opts).unwrap();
        let tol = if fx.name.contains("collinear") {
            TOL
        } else {
            TOL_EXACT
        };
        let worst = compare_paths(&cpu_path, &gpu_path, &fx.name, tol);
        println!(
            "{}: {} breakpoints, {} candidates, worst coef diff {worst:.1e}, {} refreshes",
            fx.name,
            gpu_path.breakpoints.len(),
            basis.len(),
            gpu_path.refreshes
        );
        ran += 1;
    }
    assert!(ran >= 7);
}

#[test]
fn whole_regression_fit_matches_the_cpu_engine() {
    for (seed, method) in [
        (0x1A55_0020u64, Method::LassoLars),
        (0x1A55_0021, Method::Lars),
        (0x1A55_0022, Method::ForwardOls),
    ] {
        let (basis, f, y) = random_problem(seed, 3000, 6, 6);
        let Some(mut gpu) = gpu_or_skip(&f, &basis) else {
            return;
        };
        let reg = Regression::builder()
            .degree(6)
            .method(method)
            .max_terms(20)
            .build()
            .unwrap();
        let cpu_model = reg
            .fit_with_engine(&basis, &mut cpu64(&basis, &f), &y, "y", None)
            .unwrap();
        let gpu_model = reg
            .fit_with_engine(&basis, &mut gpu, &y, "y", None)
            .unwrap();
        let label = format!("fit seed {seed:#x} {method:?}");
        let (cd, gd) = (&cpu_model.diagnostics, &gpu_model.diagnostics);
        assert!(gd.engine.starts_with("gpu"), "{}", gd.engine);
        assert_eq!(gd.path_steps, cd.path_steps, "{label}: path steps");
        assert_eq!(gd.stop, cd.stop, "{label}: stop");
        assert_eq!(
            gd.chosen_breakpoint, cd.chosen_breakpoint,
            "{label}: eBIC choice"
        );
        assert_eq!(gd.pruned, cd.pruned, "{label}: pruned terms");
        // The path in original units, breakpoint by breakpoint.
        for (k, (c, g)) in cpu_model.path.iter().zip(&gpu_model.path).enumerate() {
            assert_eq!(g.active_index, c.active_index, "{label}: breakpoint {k}");
            let scale = c.coefficients.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (gc, cc) in g.coefficients.iter().zip(&c.coefficients) {
                assert!(
                    (gc - cc).abs() <= TOL_EXACT * scale,
                    "{label}: breakpoint {k}: {gc} vs {cc}"
                );
            }
        }
        // The final model: same terms; the refit is exact f64 on exact columns on both engines,
        // so once the support agrees the coefficients agree to rounding.
        let names = |m: &ctsid::regression::Model| -> Vec<String> {
            m.terms.iter().map(|t| t.name.clone()).collect()
        };
        assert_eq!(names(&gpu_model), names(&cpu_model), "{label}: terms");
        assert!(cpu_model.terms.len() >= 3, "{label}: nothing was found");
        for (g, c) in gpu_model.terms.iter().zip(&cpu_model.terms) {
            assert!(
                (g.coefficient - c.coefficient).abs() <= 1e-9 * c.coefficient.abs().max(1e-12),
                "{label}: {}: {} vs {}",
                c.name,
                g.coefficient,
                c.coefficient
            );
        }
        assert!((gd.rss - cd.rss).abs() <= 1e-9 * cd.rss.max(1e-300));
        println!("{label}: {}", gpu_model.equation());
    }
}
