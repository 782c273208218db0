//! The library's entry point, used as `examples/identify_csv.rs` and the crate docs use it: a
//! CSV record of a known system, `RecordSet::read_csv`, `Split::from_lists`, `Identifier`,
//! `Model::simulate`. Judged against the true equation and against the measured test run.

use ctsid::{Identifier, RecordSet, Split};

/// `y'' = -4 y - 0.8 y' + 2 u - 0.5 y^3`, six runs of 600 samples at tau 0.01 s under steps
/// and sines, integrated finely (RK4, 20 substeps), 0.2 % noise from a fixed sequence.
fn record() -> String {
    let mut s = String::from("run,y,u\n");
    let f = |y: f64, v: f64, u: f64| (v, -4.0 * y - 0.8 * v + 2.0 * u - 0.5 * y * y * y);
    let mut noise = 0x9E37_79B9_7F4A_7C15u64;
    for r in 0..6 {
        let (mut y, mut v) = (0.0, 0.0);
        for k in 0..600 {
            let t = k as f64 * 0.01;
            let u = |t: f64| {
                (1.0 + r as f64 * 0.3) * ((1.1 + 0.2 * r as f64) * t).sin()
                    + if t > 2.0 + 0.3 * r as f64 { 0.7 } else { -0.2 }
            };
            noise = noise
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let e = ((noise >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.004;
            s += &format!("{r},{},{}\n", y + e, u(t));
            let h = 0.01 / 20.0;
            for j in 0..20 {
                let tt = t + j as f64 * h;
                let (k1y, k1v) = f(y, v, u(tt));
                let (k2y, k2v) = f(y + 0.5 * h * k1y, v + 0.5 * h * k1v, u(tt + 0.5 * h));
                let (k3y, k3v) = f(y + 0.5 * h * k2y, v + 0.5 * h * k2v, u(tt + 0.5 * h));
                let (k4y, k4v) = f(y + h * k3y, v + h * k3v, u(tt + h));
                y += h / 6.0 * (k1y + 2.0 * k2y + 2.0 * k3y + k4y);
                v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v);
            }
        }
    }
    s
}

#[test]
fn identify_and_simulate_a_csv_record_through_the_entry_point() {
    let dir = std::env::temp_dir().join(format!("ctsid-entry-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("osc.csv");
    std::fs::write(&path, record()).unwrap();

    let records = RecordSet::read_csv(&path, &["y", "u"], Some("run"), 0.01).unwrap();
    let split = Split::from_lists(&records, "0-3", Some("4"), "5").unwrap();
    // Progress goes to a closure that holds its own state (it took a plain `fn`).
    let lines = std::sync::Arc::new(std::sync::Mutex::new(Vec::<String>::new()));
    let sink = lines.clone();
    let fit = Identifier::new()
        .outputs(["y"])
        .inputs(["u"])
        .degree(3)
        .progress(move |l| sink.lock().unwrap().push(l.to_string()))
        .fit(&records, &split)
        .unwrap();
    let said = lines.lock().unwrap();
    assert!(said.iter().any(|l| l.contains("order")), "{said:?}");
    // The model file as `identify -o` writes it: the same model with its provenance.
    let file = fit.model_file();
    let training = &file.extra["training"];
    assert_eq!(
        training["settings"]["train"],
        serde_json::json!(["0", "1", "2", "3"])
    );
    assert_eq!(training["settings"]["degree"], 3);
    assert_eq!(file.outputs, fit.model.outputs);
    assert!(fit.model.extra.is_empty());
    let eq = &fit.model.outputs[0];
    assert_eq!(eq.order, 2, "{}", fit.model);
    // The coefficient of the monomial var^power.
    let coef = |var: &str, power: u32| {
        eq.terms
            .iter()
            .find(|t| {
                t.expression.is_none()
                    && t.exponents.len() == 1
                    && t.exponents.get(var) == Some(&power)
            })
            .map(|t| t.coefficient)
    };
    for (var, power, want) in [
        ("y", 1, -4.0),
        ("y_d1", 1, -0.8),
        ("u", 1, 2.0),
        ("y", 3, -0.5),
    ] {
        let got =
            coef(var, power).unwrap_or_else(|| panic!("{var}^{power} missing from {}", fit.model));
        assert!(
            (got - want).abs() < 0.05 * want.abs(),
            "{var}^{power}: {got} vs {want}\n{}",
            fit.model
        );
    }

    let sim = fit.model.simulate(&records).unwrap();
    assert_eq!(sim.runs.len(), 6);
    let test = sim.runs.iter().find(|r| r.id == "5").unwrap();
    assert!(
        test.fit_percent()[0] > 95.0,
        "test fit {:?}",
        test.fit_percent()
    );
    // Bad use is an error, not a panic: a channel the record set lacks, an unknown run.
    assert!(RecordSet::read_csv(&path, &["y", "w"], Some("run"), 0.01).is_err());
    assert!(Split::from_lists(&records, "0-3", None, "9").is_err());
    assert!(Identifier::new()
        .inputs(["u"])
        .fit(&records, &split)
        .is_err());
    std::fs::remove_dir_all(&dir).ok();
}

/// Without the refinement the coefficients are the derivative fit's, and so are the standard
/// errors written with them: every term has one, and the truth lies within a few of them.
#[test]
fn an_unrefined_model_carries_the_derivative_fits_standard_errors() {
    let dir = std::env::temp_dir().join(format!("ctsid-entry-se-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("osc.csv");
    std::fs::write(&path, record()).unwrap();
    let records = RecordSet::read_csv(&path, &["y", "u"], Some("run"), 0.01).unwrap();
    let split = Split::from_lists(&records, "0-3", Some("4"), "5").unwrap();
    let mut id = Identifier::new()
        .outputs(["y"])
        .inputs(["u"])
        .degree(3)
        .order(2);
    id.settings_mut().refine = false;
    let fit = id.fit(&records, &split).unwrap();
    assert!(fit.refinement.is_none());
    let truth = [
        ("y", 1, -4.0),
        ("y_d1", 1, -0.8),
        ("u", 1, 2.0),
        ("y", 3, -0.5),
    ];
    for t in &fit.model.outputs[0].terms {
        let se = t
            .std_error
            .unwrap_or_else(|| panic!("no standard error in {}", fit.model));
        let want = truth
            .iter()
            .find(|(v, p, _)| t.exponents.len() == 1 && t.exponents.get(*v) == Some(p))
            .map_or(0.0, |w| w.2);
        let z = (t.coefficient - want) / se;
        eprintln!(
            "{:?}: {} +- {se} (truth {want}, {z:.1} se)",
            t.exponents, t.coefficient
        );
        assert!(
            se > 0.0 && z.abs() < 4.0,
            "{:?}: {} +- {se}, truth {want}",
            t.exponents,
            t.coefficient
        );
    }
    std::fs::remove_dir_all(&dir).ok();
}
