//! GPU engine against an exact f64 reference computed here from `Code::eval`.
//!
//! Runs on any Vulkan adapter, lavapipe included (sizes are small because lavapipe is slow).
//! Without an adapter every test prints "skipping: no GPU adapter" and passes, unless
//! CTSID_REQUIRE_GPU=1, where that is a failure.
#![cfg(feature = "gpu")]

mod common;
use common::rng::SplitMix as Rng;
use ctsid::basis::{Basis, BasisLimits};
use ctsid::engine::gpu::{GpuEngine, GpuOptions, KernelShape};
use ctsid::engine::{Features, SweepEngine};
use ctsid::Error;

fn names(n: usize) -> Vec<String> {
    (0..n).map(|k| format!("z{k}")).collect()
}

fn features(rng: &mut Rng, n_s: usize, n_z: usize, lo: f64, hi: f64) -> Features {
    let cols = (0..n_z)
        .map(|_| (0..n_s).map(|_| rng.uniform(lo, hi)).collect())
        .collect();
    Features::new(names(n_z), cols).unwrap()
}

/// The engine, or None (with the notice) where there is no adapter and none is required.
fn engine_or_skip(f: &Features, b: &Basis, opts: GpuOptions) -> Option<GpuEngine> {
    match GpuEngine::new(f, b, opts) {
        Ok(e) => Some(e),
        Err(Error::NoGpu(msg)) => {
            if std::env::var("CTSID_REQUIRE_GPU").as_deref() == Ok("1") {
                panic!("CTSID_REQUIRE_GPU=1 but there is no GPU adapter: {msg}");
            }
            println!("skipping: no GPU adapter ({msg})");
            None
        }
        Err(e) => panic!("GPU engine construction failed: {e}"),
    }
}

fn row(f: &Features, i: usize) -> Vec<f64> {
    (0..f.n_vars()).map(|k| f.column(k)[i]).collect()
}

/// Exact f64 `X^T v` and `sum_i |x_ij v_i|` per candidate.
fn reference_sweep(f: &Features, b: &Basis, v: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let mut out = vec![0.0; b.len()];
    let mut mag = vec![0.0; b.len()];
    for (i, &vi) in v.iter().enumerate() {
        let z = row(f, i);
        for (j, c) in b.codes().iter().enumerate() {
            let t = c.eval(&z) * vi;
            out[j] += t;
            mag[j] += t.abs();
        }
    }
    (out, mag)
}

/// Every element: finite (the output was poisoned with NaN) and within `bound` of sum |terms|.
fn check_sweep_to(
    eng: &mut GpuEngine,
    f: &Features,
    b: &Basis,
    v: &[f64],
    label: &str,
    bound: f64,
) -> f64 {
    let mut out = vec![f64::NAN; b.len()];
    eng.sweep(v, &mut out).unwrap();
    let (want, mag) = reference_sweep(f, b, v);
    let mut worst = 0.0f64;
    for j in 0..b.len() {
        assert!(
            out[j].is_finite(),
            "{label}: candidate {j} ({}) was not written",
            b.name(j)
        );
        let rel = (out[j] - want[j]).abs() / mag[j].max(f64::MIN_POSITIVE);
        assert!(
            rel < bound,
            "{label}: candidate {j} ({}): gpu {} vs f64 {} (rel {rel:e})",
            b.name(j),
            out[j],
            want[j]
        );
        worst = worst.max(rel);
    }
    worst
}

/// [`check_sweep_to`] within 2e-7: measured on lavapipe up to 6.7e-8 (degree 12, where the f32
/// rounding of the factors dominates).
fn check_sweep(eng: &mut GpuEngine, f: &Features, b: &Basis, v: &[f64], label: &str) -> f64 {
    check_sweep_to(eng, f, b, v, label, 2e-7)
}

fn run_case(
    seed: u64,
    n_s: usize,
    n_z: usize,
    degree: usize,
    opts: GpuOptions,
) -> Option<GpuEngine> {
    let mut rng = Rng(seed);
    let f = features(&mut rng, n_s, n_z, -1.2, 1.2);
    let b = Basis::new(&names(n_z), degree, BasisLimits::default()).unwrap();
    let t0 = std::time::Instant::now();
    let mut eng = engine_or_skip(&f, &b, opts)?;
    let setup = t0.elapsed();
    for rep in 0..2 {
        // Fresh v per call; mixed signs and scales.
        let scale = rng.uniform(0.1, 10.0);
        let v: Vec<f64> = (0..n_s).map(|_| scale * rng.uniform(-1.0, 1.0)).collect();
        let t1 = std::time::Instant::now();
        let worst = check_sweep(
            &mut eng,
            &f,
            &b,
            &v,
            &format!("n_z={n_z} d={degree} rep {rep}"),
        );
        println!(
            "n_s={n_s} n_z={n_z} d={degree} candidates={}: worst rel err {worst:.2e}; setup {setup:?}, sweep+check {:?}; {}",
            b.len(),
            t1.elapsed(),
            eng.describe()
        );
    }
    Some(eng)
}

#[test]
fn sweep_matches_f64_reference_typical_basis() {
    // 10 variables, degree 4: 1001 candidates, degree-2 factors.
    run_case(0x5EED_0001, 3000, 10, 4, GpuOptions::default());
}

#[test]
fn sweep_matches_f64_reference_at_the_degree_and_variable_limits() {
    // d = 12 (the largest degree): 455 candidates in 3 variables, products of four 3-factors.
    run_case(0x5EED_0002, 2000, 3, 12, GpuOptions::default());
    // n_z = 32 (the most variables), degree 2: 561 candidates.
    run_case(0x5EED_0003, 2000, 32, 2, GpuOptions::default());
    // Constant only.
    run_case(0x5EED_0004, 500, 4, 0, GpuOptions::default());
}

#[test]
fn every_kernel_shape_matches_the_reference() {
    // The shapes the H200 report compared (docs/gpu.md): scalar and array code, degree-3 and
    // degree-2 tables, small and large workgroups, a long chunk.
    for (k, (workgroup, per_invocation, max_factor_degree, scalar_code, max_chunk)) in [
        (64, 8, 3, false, 32),
        (64, 8, 3, true, 32),
        (128, 4, 2, true, 64),
        (256, 1, 1, true, 32),
        (1024, 2, 2, true, 32),
    ]
    .into_iter()
    .enumerate()
    {
        let kernel = KernelShape {
            workgroup,
            per_invocation,
            max_factor_degree,
            scalar_code,
            max_chunk,
        };
        let opts = GpuOptions {
            kernel,
            ..GpuOptions::default()
        };
        let Some(eng) = run_case(0x5EED_0100 + k as u64, 1500, 7, 5, opts) else {
            return;
        };
        assert!(eng.layout().factor_degree <= max_factor_degree);
    }
}

#[test]
fn sweep_is_tiled_into_windows_and_blocks() {
    // 6 variables, degree 6: 924 candidates in windows of 512 (2 windows, the second ragged)
    // and blocks of 96 samples over 2999 samples (32 blocks, the last ragged).
    // A small tile (64 x 8 = 512 candidates) so that a window can hold one.
    let small = KernelShape {
        workgroup: 64,
        per_invocation: 8,
        ..KernelShape::default()
    };
    let opts = GpuOptions {
        max_window_candidates: Some(512),
        max_block_samples: 96,
        kernel: small,
        ..GpuOptions::default()
    };
    let Some(eng) = run_case(0x5EED_0005, 2999, 6, 6, opts) else {
        return;
    };
    let l = eng.layout();
    assert!(l.windows.len() >= 2, "{l:?}");
    assert!(l.n_blocks >= 16, "{l:?}");
    assert!(l.windows.windows(2).all(|w| w[0].0 + w[0].1 == w[1].0));
    // Bounded dispatch size also forces windows.
    let opts = GpuOptions {
        max_pairs_per_dispatch: 600 * 1000,
        kernel: small,
        ..GpuOptions::default()
    };
    let Some(eng) = run_case(0x5EED_0006, 1000, 10, 4, opts) else {
        return;
    };
    assert!(eng.layout().windows.len() >= 2, "{:?}", eng.layout());
}

#[test]
fn long_blocks_keep_their_precision() {
    // Blocks of 4,000 samples (a software adapter gets at least 16 blocks) of positive products:
    // partial sums grow with every sample, the case where an uncompensated f32 sum loses most.
    // Measured on lavapipe: 1.7e-8 with the Kahan compensation, 2.1e-7 when the shader compiler
    // had deleted it (before `opaque` in sweep.wgsl); bound 6e-8.
    let mut rng = Rng(0x5EED_0007);
    let n_s = 64_000;
    let f = features(&mut rng, n_s, 3, 0.5, 1.5);
    let b = Basis::new(&names(3), 4, BasisLimits::default()).unwrap();
    let opts = GpuOptions {
        max_block_samples: 8192,
        // A discrete GPU's layout cuts samples into short blocks to fill its cores (on an H200:
        // 2,000 blocks of 32); force the long sums this test is about.
        min_block_samples: 4000,
        ..GpuOptions::default()
    };
    let Some(mut eng) = engine_or_skip(&f, &b, opts) else {
        return;
    };
    assert!(eng.layout().block_samples >= 4000, "{:?}", eng.layout());
    let v: Vec<f64> = (0..n_s).map(|_| rng.uniform(0.5, 2.0)).collect();
    let worst = check_sweep_to(&mut eng, &f, &b, &v, "long blocks", 6e-8);
    println!("long blocks: worst rel err {worst:.2e}");
}

#[test]
fn column_stats_match_f64_reference_with_large_means() {
    let mut rng = Rng(0x5EED_0010);
    let (n_s, n_z, degree) = (3000, 7, 4);
    // Shifted away from zero: means dominate, which is what breaks one-pass f32 formulas.
    let f = features(&mut rng, n_s, n_z, 2.0, 4.0);
    let b = Basis::new(&names(n_z), degree, BasisLimits::default()).unwrap();
    let Some(mut eng) = engine_or_skip(
        &f,
        &b,
        GpuOptions {
            max_block_samples: 512,
            ..GpuOptions::default()
        },
    ) else {
        return;
    };
    for weighted in [false, true] {
        let w: Vec<f64> = (0..n_s).map(|_| rng.uniform(0.0, 2.0)).collect();
        let t0 = std::time::Instant::now();
        let st = eng.column_stats(weighted.then_some(&w[..])).unwrap();
        let el = t0.elapsed();
        let w: Vec<f64> = if weighted {
            w.iter().map(|&a| a as f32 as f64).collect()
        } else {
            vec![1.0; n_s]
        };
        let wsum: f64 = w.iter().sum();
        let rows: Vec<Vec<f64>> = (0..n_s).map(|i| row(&f, i)).collect();
        let (mut worst_m, mut worst_n) = (0.0f64, 0.0f64);
        for j in 0..b.len() {
            let c = b.code(j);
            let x: Vec<f64> = rows.iter().map(|z| c.eval(z)).collect();
            let m = x.iter().zip(&w).map(|(x, w)| x * w).sum::<f64>() / wsum;
            let ss: f64 = x.iter().zip(&w).map(|(x, w)| w * (x - m) * (x - m)).sum();
            let sq: f64 = x.iter().zip(&w).map(|(x, w)| w * x * x).sum();
            let mag = x.iter().zip(&w).map(|(x, w)| (x * w).abs()).sum::<f64>() / wsum;
            let em = (st.mean[j] - m).abs() / mag;
            // f32 values of x carry ~6e-8 |x| each, so the centred sum can only be as good as
            // that relative to sum w x^2; the bound applies to the spread itself. Measured on
            // lavapipe: up to 5.3e-8 (1.8e-7 to 2.1e-7 when the compiler deleted the Kahan
            // compensation).
            let en = (st.norm[j] * st.norm[j] - ss).abs() / (ss + 1e-6 * sq);
            assert!(em < 1e-7, "mean of {}: {} vs {m}", b.name(j), st.mean[j]);
            assert!(
                en < 1e-7,
                "norm of {}: {} vs {} (weighted {weighted})",
                b.name(j),
                st.norm[j],
                ss.sqrt()
            );
            worst_m = worst_m.max(em);
            worst_n = worst_n.max(en);
        }
        println!("column_stats weighted={weighted}: {} candidates in {el:?}; worst mean err {worst_m:.2e}, norm^2 err {worst_n:.2e}", b.len());
    }
}

#[test]
fn columns_are_exact_and_bad_input_is_refused() {
    let mut rng = Rng(0x5EED_0020);
    let f = features(&mut rng, 300, 5, -2.0, 2.0);
    let b = Basis::new(&names(5), 3, BasisLimits::default()).unwrap();
    let Some(mut eng) = engine_or_skip(&f, &b, GpuOptions::default()) else {
        return;
    };
    let idx = [0, 3, b.len() - 1, 17];
    let cols = eng.columns(&idx).unwrap();
    assert_eq!(cols.len(), idx.len());
    for (c, &j) in cols.iter().zip(&idx) {
        assert_eq!(c.len(), 300);
        for (i, &x) in c.iter().enumerate() {
            assert_eq!(x, b.code(j).eval(&row(&f, i)));
        }
    }
    assert!(matches!(
        eng.columns(&[b.len()]),
        Err(Error::InvalidParameter { .. })
    ));
    let mut out = vec![0.0; b.len()];
    assert!(matches!(
        eng.sweep(&[1.0; 299], &mut out),
        Err(Error::InvalidParameter { .. })
    ));
    let mut bad = vec![1.0; 300];
    bad[7] = f64::NAN;
    assert!(matches!(
        eng.sweep(&bad, &mut out),
        Err(Error::InvalidData(_))
    ));
    assert!(eng.column_stats(Some(&[0.0; 300])).is_err());
    assert!(eng.column_stats(Some(&vec![-1.0; 300])).is_err());
    // The engine still works after refusing bad input.
    let v: Vec<f64> = (0..300).map(|_| rng.uniform(-1.0, 1.0)).collect();
    check_sweep(&mut eng, &f, &b, &v, "after errors");
}

#[test]
fn memory_budget_is_checked_before_allocating() {
    let mut rng = Rng(0x5EED_0030);
    let f = features(&mut rng, 2000, 6, -1.0, 1.0);
    let b = Basis::new(&names(6), 4, BasisLimits::default()).unwrap();
    match GpuEngine::new(
        &f,
        &b,
        GpuOptions {
            memory_budget_bytes: 10_000,
            ..GpuOptions::default()
        },
    ) {
        Err(Error::TooLarge {
            needed_mib,
            budget_mib,
            ..
        }) => assert!(needed_mib > budget_mib),
        Err(Error::NoGpu(msg)) => {
            if std::env::var("CTSID_REQUIRE_GPU").as_deref() == Ok("1") {
                panic!("CTSID_REQUIRE_GPU=1 but there is no GPU adapter: {msg}");
            }
            println!("skipping: no GPU adapter ({msg})");
        }
        other => panic!("expected TooLarge, got {:?}", other.map(|e| e.describe())),
    }
}
