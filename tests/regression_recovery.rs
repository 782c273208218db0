//! Recovery of known sparse polynomials, edge cases (collinear, constant and zero columns,
//! weights) and settings validation.

mod common;
use common::rng::SplitMix as Rng;
use ctsid::engine::Features;
use ctsid::regression::{Method, Model, Regression};
use ctsid::Error;

struct Problem {
    features: Features,
    label: Vec<f64>,
    truth: Vec<(usize, f64)>,
}

/// `n_true` random terms (indices into the graded-lex basis) with coefficients of magnitude 0.5..2.
fn problem(seed: u64, nz: usize, d: usize, n: usize, n_true: usize, noise: f64) -> Problem {
    let mut rng = Rng(seed);
    let names: Vec<String> = (0..nz).map(|k| format!("z{k}")).collect();
    let cols: Vec<Vec<f64>> = (0..nz)
        .map(|_| (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect())
        .collect();
    let basis = ctsid::basis::Basis::new(&names, d, Default::default()).unwrap();
    let mut truth: Vec<(usize, f64)> = Vec::new();
    while truth.len() < n_true {
        let j = (rng.next() % basis.len() as u64) as usize;
        if truth.iter().all(|t| t.0 != j) {
            let c = (0.5 + 1.5 * (rng.uniform(-1.0, 1.0) + 1.0) / 2.0)
                * if rng.uniform(-1.0, 1.0) < 0.0 {
                    -1.0
                } else {
                    1.0
                };
            truth.push((j, c));
        }
    }
    truth.sort_by_key(|t| t.0);
    let mut label = vec![0.0; n];
    for &(j, c) in &truth {
        for (i, l) in label.iter_mut().enumerate() {
            let z: Vec<f64> = (0..nz).map(|k| cols[k][i]).collect();
            *l += c * basis.code(j).eval(&z);
        }
    }
    let rms = (label.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    for l in label.iter_mut() {
        *l += noise * rms * rng.normal();
    }
    Problem {
        features: Features::new(names, cols).unwrap(),
        label,
        truth,
    }
}

/// Each fitted coefficient within `rel` of the true one (the supports already agree).
fn assert_coefficients(m: &Model, truth: &[(usize, f64)], rel: f64) {
    for (t, (_, c)) in m.terms.iter().zip(truth) {
        assert!(
            (t.coefficient - c).abs() <= rel * c.abs(),
            "{}: {} vs {c}",
            t.name,
            t.coefficient
        );
    }
}

fn support(m: &Model) -> Vec<usize> {
    m.terms.iter().map(|t| t.index.unwrap()).collect()
}

#[test]
fn recovers_ten_terms_among_12376_without_noise() {
    let p = problem(11, 11, 6, 25_000, 10, 0.0);
    let model = Regression::builder()
        .degree(6)
        .max_terms(40)
        .build()
        .unwrap()
        .fit(&p.features, &p.label, "y", None)
        .unwrap();
    let want: Vec<usize> = p.truth.iter().map(|t| t.0).collect();
    assert_eq!(
        support(&model),
        want,
        "{}\n{:?}",
        model.equation(),
        model.diagnostics
    );
    assert_coefficients(&model, &p.truth, 1e-6);
    assert_eq!(model.diagnostics.n_candidates, 12_376);
}

#[test]
fn recovers_the_support_with_one_percent_noise() {
    for seed in [5, 6] {
        let p = problem(seed, 11, 6, 25_000, 10, 0.01);
        let model = Regression::builder()
            .degree(6)
            .max_terms(40)
            .build()
            .unwrap()
            .fit(&p.features, &p.label, "y", None)
            .unwrap();
        let want: Vec<usize> = p.truth.iter().map(|t| t.0).collect();
        assert_eq!(
            support(&model),
            want,
            "seed {seed}: {}\n{:?}",
            model.equation(),
            model.diagnostics
        );
        // 1 % noise on 25,000 samples: standard errors of a few 1e-4 of each coefficient
        // (high-degree monomials of uniform features spread little); measured at most 6.1e-4.
        assert_coefficients(&model, &p.truth, 0.003);
    }
}

#[test]
fn plain_lars_recovers_a_small_problem_too() {
    let p = problem(3, 4, 3, 2000, 4, 0.0);
    let model = Regression::builder()
        .degree(3)
        .method(Method::Lars)
        .build()
        .unwrap()
        .fit(&p.features, &p.label, "y", None)
        .unwrap();
    assert_eq!(
        support(&model),
        p.truth.iter().map(|t| t.0).collect::<Vec<_>>(),
        "{}",
        model.equation()
    );
    assert_coefficients(&model, &p.truth, 1e-9);
}

#[test]
fn relevance_threshold_stops_the_path() {
    // Noise keeps the path going after the true terms, with small gains per step.
    let p = problem(3, 4, 3, 2000, 4, 0.05);
    let reg = |eps: f64| {
        Regression::builder()
            .degree(3)
            .method(Method::Lars)
            .epsilon(eps)
            .build()
            .unwrap()
    };
    let full = reg(0.0).fit(&p.features, &p.label, "y", None).unwrap();
    let short = reg(0.05).fit(&p.features, &p.label, "y", None).unwrap();
    assert_eq!(
        short.diagnostics.stop,
        ctsid::regression::StopReason::Relevance
    );
    assert!(
        short.diagnostics.path_steps < full.diagnostics.path_steps,
        "{} vs {}",
        short.diagnostics.path_steps,
        full.diagnostics.path_steps
    );
    // Each step kept before the stop lowered the relative residual by at least epsilon.
    let steps = &short.path;
    assert!(steps.len() >= 4, "{} steps", steps.len());
    for k in 1..steps.len() - 1 {
        assert!(
            steps[k - 1].rel_residual - steps[k].rel_residual >= 0.05,
            "step {k}"
        );
    }
}

#[test]
fn duplicated_feature_is_skipped_without_nan() {
    // z1 is a copy of z0 (exactly, or up to 1e-10): every monomial in z1 duplicates one in z0.
    for offset in [0.0, 1e-10] {
        let mut rng = Rng(9);
        let n = 500;
        let a: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let a2: Vec<f64> = a
            .iter()
            .map(|x| x + offset * rng.uniform(-1.0, 1.0))
            .collect();
        let b: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
        let y: Vec<f64> = (0..n)
            .map(|i| 1.5 * a[i] - 2.0 * a[i] * b[i] + 0.3 + 0.05 * rng.normal())
            .collect();
        let f = Features::new(vec!["a".into(), "a2".into(), "b".into()], vec![a, a2, b]).unwrap();
        for method in [Method::Lars, Method::LassoLars] {
            let m = Regression::builder()
                .degree(2)
                .method(method)
                .max_terms(9)
                .build()
                .unwrap()
                .fit(&f, &y, "y", None)
                .unwrap();
            if offset > 0.0 {
                // The noise keeps the path going until every distinct monomial is in; then the
                // 4 near-duplicates (a2, a*a2, a2^2, a2*b) are tried and refused.
                assert_eq!(
                    m.diagnostics.skipped_collinear.len(),
                    4,
                    "{method:?}: {:?}",
                    m.diagnostics
                );
            }
            assert!(m
                .path
                .iter()
                .all(|p| p.coefficients.iter().all(|c| c.is_finite()) && p.alpha.is_finite()));
            // a and a2 are interchangeable.
            let names: Vec<String> = m.terms.iter().map(|t| t.name.replace("a2", "a")).collect();
            assert!(m.terms.iter().all(|t| t.coefficient.is_finite()));
            assert_eq!(
                names,
                ["1", "a", "a*b"],
                "{method:?}, offset {offset}: {}",
                m.equation()
            );
        }
    }
}

#[test]
fn zero_and_constant_features_are_excluded() {
    let mut rng = Rng(4);
    let n = 300;
    let a: Vec<f64> = (0..n).map(|_| rng.uniform(-1.0, 1.0)).collect();
    let y: Vec<f64> = a.iter().map(|x| 2.0 * x * x - 1.0).collect();
    let f = Features::new(
        vec!["a".into(), "zero".into(), "three".into()],
        vec![a, vec![0.0; n], vec![3.0; n]],
    )
    .unwrap();
    let m = Regression::builder()
        .degree(2)
        .build()
        .unwrap()
        .fit(&f, &y, "y", None)
        .unwrap();
    // Constant candidates: 1, zero, three, zero^2, zero*three, three^2, a*zero.
    assert_eq!(m.diagnostics.constant_candidates, 7, "{:?}", m.diagnostics);
    let names: Vec<&str> = m.terms.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["1", "a^2"], "{}", m.equation());
    assert!(
        (m.terms[0].coefficient + 1.0).abs() < 1e-9 && (m.terms[1].coefficient - 2.0).abs() < 1e-9
    );
    // A constant label: nothing to fit but the constant.
    let m = Regression::builder()
        .degree(2)
        .build()
        .unwrap()
        .fit(&f, &vec![4.0; n], "c", None)
        .unwrap();
    assert_eq!(m.equation(), "c = 4");
}

#[test]
fn weights_exclude_bad_samples() {
    let p = problem(21, 3, 3, 3000, 4, 0.0);
    let mut y = p.label.clone();
    let mut w = vec![1.0; y.len()];
    for i in (0..y.len()).step_by(10) {
        y[i] += 50.0;
        w[i] = 0.0;
    }
    let reg = Regression::builder().degree(3).build().unwrap();
    let m = reg.fit(&p.features, &y, "y", Some(&w)).unwrap();
    assert_eq!(
        support(&m),
        p.truth.iter().map(|t| t.0).collect::<Vec<_>>(),
        "{}",
        m.equation()
    );
    let unweighted = reg.fit(&p.features, &y, "y", None).unwrap();
    assert_ne!(
        support(&unweighted),
        support(&m),
        "the corrupted samples should matter without weights"
    );
    assert!(reg.fit(&p.features, &y, "y", Some(&w[1..])).is_err());
    let mut neg = w.clone();
    neg[3] = -1.0;
    assert!(matches!(
        reg.fit(&p.features, &y, "y", Some(&neg)),
        Err(Error::InvalidParameter { .. })
    ));
}

#[test]
fn model_json_and_equation() {
    let p = problem(8, 2, 2, 400, 3, 0.0);
    let f = Features::new(
        vec!["u".into(), "y".into()],
        vec![p.features.column(0).to_vec(), p.features.column(1).to_vec()],
    )
    .unwrap();
    let m = Regression::builder()
        .degree(2)
        .build()
        .unwrap()
        .fit(&f, &p.label, "y_d1", None)
        .unwrap();
    let json = serde_json::to_value(&m).unwrap();
    assert_eq!(json["label"], "y_d1");
    let terms = json["terms"].as_array().unwrap();
    assert_eq!(terms.len(), 3);
    for (t, (j, c)) in terms.iter().zip(&p.truth) {
        assert!((t["coefficient"].as_f64().unwrap() - c).abs() < 1e-9);
        let e = t["exponents"].as_object().unwrap();
        let sum: u64 = e.values().map(|v| v.as_u64().unwrap()).sum();
        assert_eq!(
            sum as usize,
            ctsid::basis::Basis::new(&f.names, 2, Default::default())
                .unwrap()
                .code(*j)
                .degree()
        );
    }
    let back: Model = serde_json::from_value(json).unwrap();
    assert_eq!(back.terms, m.terms);
    let eq = m.equation();
    assert!(eq.starts_with("y_d1 = "), "{eq}");
    assert!(!eq.contains("+ -"), "{eq}");
    // A hand-written model with just label and terms parses into terms.
    let t: Vec<ctsid::regression::Term> = serde_json::from_str(
        r#"[{"exponents": {"u": 1}, "coefficient": 2.5}, {"exponents": {}, "coefficient": -1}]"#,
    )
    .unwrap();
    assert_eq!(t[1].exponents.len(), 0);
}

#[test]
fn bad_settings_are_refused_before_fitting() {
    let b = || Regression::builder();
    assert!(matches!(
        b().degree(13).build(),
        Err(Error::InvalidParameter { .. })
    ));
    assert!(b().max_terms(0).build().is_err());
    assert!(b().max_steps(0).build().is_err());
    assert!(b().alpha_min(-1.0).build().is_err());
    assert!(b().alpha_min(f64::NAN).build().is_err());
    assert!(b().epsilon(1.0).build().is_err());
    assert!(b().ebic_gamma(1.5).build().is_err());
    assert!(b().collinearity_tol(0.0).build().is_err());
    assert!(b().refresh_tol(-1.0).build().is_err());
    assert!(b().degree(6).max_terms(10).build().is_ok());
    // Data errors are typed too.
    let f = Features::new(vec!["a".into()], vec![vec![0.0, 1.0, f64::NAN]]).unwrap();
    assert!(b()
        .build()
        .unwrap()
        .fit(&f, &[1.0, 2.0, 3.0], "y", None)
        .is_err());
    let f = Features::new(vec!["a".into()], vec![vec![0.0, 1.0, 2.0]]).unwrap();
    assert!(b()
        .build()
        .unwrap()
        .fit(&f, &[1.0, 2.0], "y", None)
        .is_err());
    assert!(b()
        .build()
        .unwrap()
        .fit(&f, &[1.0, f64::INFINITY, 2.0], "y", None)
        .is_err());
    let too_big = b().degree(12).max_candidates(1000).build().unwrap();
    let f = Features::new(
        (0..5).map(|k| format!("v{k}")).collect(),
        vec![vec![0.0; 3]; 5],
    )
    .unwrap();
    assert!(matches!(
        too_big.fit(&f, &[0.0; 3], "y", None),
        Err(Error::TooLarge { .. })
    ));
    // --engine gpu never falls back silently: without any adapter it is an error; with one,
    // its f32 sweeps find the same model.
    let p = problem(3, 3, 2, 300, 3, 0.0);
    let gpu = b()
        .degree(2)
        .engine(ctsid::regression::EngineChoice::Gpu)
        .build()
        .unwrap()
        .fit(&p.features, &p.label, "y", None);
    if ctsid::engine::select::probe().is_empty() {
        assert!(matches!(gpu, Err(Error::NoGpu(_))), "{gpu:?}");
    } else {
        let m = gpu.unwrap();
        assert_eq!(support(&m), p.truth.iter().map(|t| t.0).collect::<Vec<_>>());
        assert_coefficients(&m, &p.truth, 1e-9);
    }
}

/// The eBIC patience stop: on noisy data the chosen model is the one the whole path gives, and
/// the path really stops early (the breakpoints after a long run without improvement are the
/// ones eBIC can no longer choose).
#[test]
fn ebic_patience_stops_the_path_without_changing_the_choice() {
    for seed in [3u64, 4, 5] {
        let p = problem(seed, 5, 3, 4_000, 4, 0.05);
        let fit = |patience: usize| {
            Regression::builder()
                .degree(3)
                .ebic_patience(patience)
                .build()
                .unwrap()
                .fit(&p.features, &p.label, "y", None)
                .unwrap()
        };
        let (early, full) = (fit(10), fit(0));
        assert_eq!(support(&early), support(&full), "seed {seed}");
        for (a, b) in early.terms.iter().zip(&full.terms) {
            assert!((a.coefficient - b.coefficient).abs() <= 1e-12 * b.coefficient.abs());
        }
        assert_eq!(
            early.diagnostics.stop,
            ctsid::regression::StopReason::NoImprovement,
            "seed {seed}: {:?}",
            early.diagnostics
        );
        assert!(
            early.diagnostics.path_steps + 5 < full.diagnostics.path_steps,
            "seed {seed}: {} vs {} steps",
            early.diagnostics.path_steps,
            full.diagnostics.path_steps
        );
    }
}

/// Signals of a dynamic system: a multisine y with its exact derivatives y', y'' and an input u,
/// the kind of strongly correlated features identification regresses on.
fn dynamic_features(n: usize) -> Features {
    let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.01).collect();
    let (a, w, p) = ([1.0, 0.6, 0.3], [1.3, 2.9, 5.1], [0.2, 1.1, 2.5]);
    let y = |k: usize| -> Vec<f64> {
        t.iter()
            .map(|&t| {
                (0..3)
                    .map(|i| {
                        let x = w[i] * t + p[i];
                        a[i] * w[i].powi(k as i32)
                            * match k % 4 {
                                0 => x.sin(),
                                1 => x.cos(),
                                2 => -x.sin(),
                                _ => -x.cos(),
                            }
                    })
                    .sum()
            })
            .collect()
    };
    let u: Vec<f64> = t
        .iter()
        .map(|&t| (0.7 * t).sin() + 0.5 * (3.7 * t + 0.4).sin())
        .collect();
    Features::new(
        ["y", "y_d1", "y_d2", "u"]
            .iter()
            .map(|s| s.to_string())
            .collect(),
        vec![y(0), y(1), y(2), u],
    )
    .unwrap()
}

/// Forward orthogonal least squares: every breakpoint is the least-squares fit of its support
/// (checked against an independent QR solve), and the true sparse polynomial is found exactly
/// among 70 correlated candidates.
#[test]
fn forward_ols_breakpoints_are_least_squares_fits_and_recover_the_truth() {
    let f = dynamic_features(3000);
    let c = |k: usize| f.column(k).to_vec();
    let (y, y1, y2, u) = (c(0), c(1), c(2), c(3));
    let label: Vec<f64> = (0..y.len())
        .map(|i| {
            -6.0 * y[i] - 11.0 * y1[i] - 6.0 * y2[i] + 18.0 * u[i] + 2.0 * y[i] * u[i]
                - 0.3 * y[i].powi(3)
        })
        .collect();
    let basis = ctsid::basis::Basis::new(&f.names, 4, Default::default()).unwrap();
    let mut engine = ctsid::engine::CpuEngine::new(
        &basis,
        &f,
        ctsid::engine::CpuOptions {
            precision: ctsid::engine::Precision::F64,
            ..Default::default()
        },
    )
    .unwrap();
    let opts = ctsid::regression::PathOptions {
        method: Method::ForwardOls,
        max_terms: 12,
        ..Default::default()
    };
    let path = ctsid::regression::lars_path(&mut engine, &label, None, &opts).unwrap();
    assert!(path.breakpoints.len() > 6);
    for (k, bp) in path.breakpoints.iter().enumerate().skip(1) {
        let cols: Vec<Vec<f64>> = bp
            .active
            .iter()
            .map(|id| path.store.cols[path.store.position(*id).unwrap()].clone())
            .collect();
        let ls = ctsid::regression::select::least_squares(&cols, &path.y_tilde).unwrap();
        let scale = ls.coef.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        for (a, b) in bp.coefs.iter().zip(&ls.coef) {
            assert!((a - b).abs() <= 1e-8 * scale, "breakpoint {k}: {a} vs {b}");
        }
        // Nested supports: each breakpoint adds one candidate.
        assert_eq!(bp.active.len(), k);
    }
    let model = Regression::builder()
        .degree(4)
        .method(Method::ForwardOls)
        .build()
        .unwrap()
        .fit(&f, &label, "y_d3", None)
        .unwrap();
    let mut names: Vec<String> = model.terms.iter().map(|t| t.name.clone()).collect();
    names.sort();
    assert_eq!(
        names,
        ["u", "y", "y*u", "y^3", "y_d1", "y_d2"],
        "{}",
        model.equation()
    );
    for (name, want) in [
        ("y", -6.0),
        ("y_d1", -11.0),
        ("y_d2", -6.0),
        ("u", 18.0),
        ("y*u", 2.0),
        ("y^3", -0.3),
    ] {
        let got = model
            .terms
            .iter()
            .find(|t| t.name == name)
            .unwrap()
            .coefficient;
        assert!(
            (got - want).abs() <= 1e-6 * want.abs(),
            "{name}: {got} vs {want}"
        );
    }
}

#[test]
fn the_model_does_not_depend_on_the_units_of_the_label_or_the_weights() {
    // A label of 1e-15 once gave `y = 0` (the path's equality tolerance was absolute) and
    // uniform weights of 1e-30 lost a term; every method must give the same support, with the
    // coefficients in the label's units.
    let p = problem(5, 3, 2, 400, 3, 0.01);
    for method in [Method::LassoLars, Method::Lars, Method::ForwardOls] {
        let reg = Regression::builder()
            .degree(2)
            .method(method)
            .build()
            .unwrap();
        let base = reg.fit(&p.features, &p.label, "y", None).unwrap();
        assert_eq!(
            support(&base)
                .into_iter()
                .filter(|j| *j != 0)
                .collect::<Vec<_>>(),
            p.truth.iter().map(|t| t.0).collect::<Vec<_>>(),
            "{method:?}: {}",
            base.equation()
        );
        for (scale, w) in [
            (1e-15, 1.0),
            (1e15, 1.0),
            (1.0, 1e-30),
            (1.0, 1e-200),
            (1.0, 1e306),
            (1e-15, 1e30),
        ] {
            let y: Vec<f64> = p.label.iter().map(|v| v * scale).collect();
            let weights = vec![w; y.len()];
            let m = reg.fit(&p.features, &y, "y", Some(&weights)).unwrap();
            assert_eq!(
                support(&m),
                support(&base),
                "{method:?} x{scale:e} w {w:e}: {}",
                m.equation()
            );
            for (a, b) in m.terms.iter().zip(&base.terms) {
                assert!(
                    (a.coefficient / scale - b.coefficient).abs() <= 1e-9 * b.coefficient.abs(),
                    "{method:?} x{scale:e} w {w:e}: {} vs {}",
                    a.coefficient / scale,
                    b.coefficient
                );
            }
        }
    }
}

#[test]
fn features_of_any_finite_scale_give_the_same_model_in_their_units() {
    // Three variables, degree 3, four true terms with 1 % noise; then variable z0 multiplied by
    // 1e60, 1e-60 and 1e52. Before the features were scaled internally, a cubic in z0 ~ 1e60
    // overflowed the column statistics and the term was dropped silently (R^2 0.995).
    let p = problem(29, 3, 3, 2_000, 4, 0.01);
    let reg = Regression::builder().degree(3).build().unwrap();
    let base = reg.fit(&p.features, &p.label, "y", None).unwrap();
    assert_eq!(
        support(&base),
        p.truth.iter().map(|t| t.0).collect::<Vec<_>>()
    );
    let basis = ctsid::basis::Basis::new(&p.features.names, 3, Default::default()).unwrap();
    for scale in [1e60, 1e-60, 1e52, 3.7e-9] {
        let mut f = p.features.clone();
        f.data[..f.n_samples].iter_mut().for_each(|v| *v *= scale);
        let m = reg.fit(&f, &p.label, "y", None).unwrap();
        assert_eq!(support(&m), support(&base), "scale {scale:e}");
        for (t, b) in m.terms.iter().zip(&base.terms) {
            let e0 = basis.code(t.index.unwrap()).exponents(3)[0];
            let want = b.coefficient / scale.powi(e0 as i32);
            assert!(
                (t.coefficient - want).abs() <= 1e-9 * want.abs(),
                "scale {scale:e}, {}: {} vs {want}",
                t.name,
                t.coefficient
            );
        }
    }
}
