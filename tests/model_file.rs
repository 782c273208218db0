//! The model file: round trip, hand-written files, and the one-line errors for bad files.

mod common;

use common::cli::{ctsid, temp_file};
use ctsid::model::{Model, Origin, OutputEquation, Term};
use ctsid::Error;

fn siso() -> Model {
    Model::new(
        &["u"],
        vec![OutputEquation::new(
            "y",
            3,
            vec![
                Term::new(&[], 37664.0),
                Term::new(&[("y", 1)], -23978.0),
                Term::new(&[("y_d1", 2), ("u", 1)], 0.125),
                Term::new(&[("y_d2", 1)], -675.7),
            ],
        )],
        Some(0.003),
    )
}

fn err_of(text: &str) -> String {
    match Model::from_json_str(text, "m.json") {
        Err(e @ Error::Model { .. }) => e.to_string(),
        Err(e) => panic!("wrong error kind: {e}"),
        Ok(_) => panic!("accepted a bad model: {text}"),
    }
}

/// A model with every kind of term and field of `ctsid-model/2`.
fn mixed() -> Model {
    let mut m = siso();
    m.outputs[0].terms.push(
        Term::expression("sign(y_d1)", -0.21)
            .with_origin(Origin::Effect("coulomb_friction".into())),
    );
    m.outputs[0]
        .terms
        .push(Term::expression("abs(y_d1)*y_d1", 0.5));
    m.outputs[0].terms[1].std_error = Some(1.5);
    m.outputs[0].terms[1].origin = Some(Origin::Identified);
    m.outputs[0].terms[4].interval = Some([-0.25, -0.17]);
    m.sign_smoothing.insert("y_d1".into(), 2.5e-5);
    m.extra.insert(
        "training".into(),
        serde_json::json!({"p50": 0.01, "runs": [0, 1, 2]}),
    );
    m
}

#[test]
fn round_trip_is_byte_identical_and_keeps_sections() {
    let m = mixed();
    let dir = std::env::temp_dir().join(format!("ctsid-model-rt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (p1, p2) = (dir.join("a.json"), dir.join("b.json"));
    m.write(p1.to_str().unwrap()).unwrap();
    let back = Model::read(p1.to_str().unwrap()).unwrap();
    assert_eq!(back, m);
    back.write(p2.to_str().unwrap()).unwrap();
    let (a, b) = (std::fs::read(&p1).unwrap(), std::fs::read(&p2).unwrap());
    assert_eq!(a, b, "write -> read -> write changed the bytes");
    let text = String::from_utf8(a).unwrap();
    assert!(text.contains("\"format\": \"ctsid-model/2\""), "{text}");
    assert!(text.contains("\"expression\": \"sign(y_d1)\""), "{text}");
    assert!(text.contains("\"effect\": \"coulomb_friction\""), "{text}");
    // Coefficients survive bit for bit.
    assert_eq!(
        back.outputs[0].terms[3].coefficient.to_bits(),
        (-675.7f64).to_bits()
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn expression_terms_evaluate_with_their_smoothing_and_exact_gradients() {
    let m = mixed();
    let c = m.compile().unwrap();
    // z = [y, y_d1, y_d2, u]
    let z = [0.3, 1e-5, -0.7, 2.0];
    let w = 2.5e-5f64;
    let smooth_sign = 1e-5 / (1e-10f64 + w * w).sqrt();
    let expect = 37664.0 - 23978.0 * 0.3 + 0.125 * 1e-10 * 2.0 - 675.7 * -0.7 - 0.21 * smooth_sign
        + 0.5 * 1e-5 * 1e-5;
    assert!((c.eval_output(0, &z).unwrap() - expect).abs() < 1e-9 * expect.abs());
    let g = c.grad_output(0, &z).unwrap();
    for k in 0..4 {
        let h = 1e-7 * z[k].abs().max(0.1);
        let (mut a, mut b) = (z, z);
        a[k] += h;
        b[k] -= h;
        let fd = (c.eval_output(0, &a).unwrap() - c.eval_output(0, &b).unwrap()) / (2.0 * h);
        assert!(
            (fd - g[k]).abs() < 1e-5 * (1.0 + fd.abs()),
            "d/dz{k}: {} vs {fd}",
            g[k]
        );
    }
}

#[test]
fn unknown_and_misspelt_keys_are_named() {
    let v2 = |terms: &str| {
        format!(
            r#"{{"format":"ctsid-model/2","inputs":["u"],"outputs":[{{"name":"y","order":2,"terms":[{terms}]}}]}}"#
        )
    };
    let e = err_of(&v2(r#"{"exponent":{"y":1},"coefficient":-1}"#));
    assert!(e.contains("term 1") && e.contains("\"exponent\""), "{e}");
    assert_eq!(e.lines().count(), 1);
    let e = err_of(&v2(
        r#"{"exponents":{"y":1},"expression":"sign(y_d1)","coefficient":-1}"#,
    ));
    assert!(e.contains("both"), "{e}");
    let e = err_of(&v2(r#"{"expression":"sign(v)","coefficient":-1}"#));
    assert!(e.contains("unknown variable 'v'"), "{e}");
    let e = err_of(&v2(r#"{"expression":"sgn(y_d1)","coefficient":-1}"#));
    assert!(e.contains("unknown function 'sgn'"), "{e}");
    let e = err_of(&v2(
        r#"{"exponents":{"y":1},"coefficient":-1,"stderr":0.1}"#,
    ));
    assert!(e.contains("\"stderr\""), "{e}");
    let e = err_of(
        r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[],"selected_order":2}]}"#,
    );
    assert!(
        e.contains("output 'y'") && e.contains("selected_order"),
        "{e}"
    );
    let e = err_of(
        r#"{"format":"ctsid-model/2","inputs":["u"],"extras":1,"outputs":[{"name":"y","order":2,"terms":[]}]}"#,
    );
    assert!(e.contains("\"extras\""), "{e}");
    let e = err_of(
        r#"{"format":"ctsid-model/2","inputs":["u"],"sign_smoothing":{"w":1},"outputs":[{"name":"y","order":2,"terms":[]}]}"#,
    );
    assert!(e.contains("'w'"), "{e}");
    // A width whose square underflows made the smoothed sign 0/0 at zero; whose cube does, its
    // slope infinite.
    for w in ["1e-170", "1e-120", "1e170"] {
        let e = err_of(&format!(
            r#"{{"format":"ctsid-model/2","inputs":["u"],"sign_smoothing":{{"y_d1":{w}}},"outputs":[{{"name":"y","order":2,"terms":[]}}]}}"#
        ));
        assert!(e.contains("between 1e-100 and 1e100"), "{e}");
    }
    // Expressions need the second version.
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[{"expression":"sign(y_d1)","coefficient":-1}]}]}"#,
    );
    assert!(e.contains("ctsid-model/2"), "{e}");
}

#[test]
fn hand_written_minimal_file_is_valid_and_evaluates() {
    let text = r#"{"format": "ctsid-model/1", "tau": 0.01, "degree": 2, "inputs": ["u"],
        "outputs": [{"name": "y", "order": 2, "terms": [
            {"exponents": {"y_d0": 1}, "coefficient": -2.0},
            {"exponents": {"y_d1": 1, "u": 1}, "coefficient": 3.0},
            {"exponents": {}, "coefficient": 0.5}]}]}"#;
    let m = Model::from_json_str(text, "hand.json").unwrap();
    assert_eq!(m.variable_names(), ["y", "y_d1", "u"]);
    let c = m.compile().unwrap();
    // z = (y, y', u) = (1, 2, 4): -2 + 3*8 + 0.5
    assert_eq!(c.eval_output(0, &[1.0, 2.0, 4.0]).unwrap(), 22.5);
    let mut dx = [0.0; 2];
    c.rhs(&[1.0, 2.0], &[4.0], &mut dx).unwrap();
    assert_eq!(dx, [2.0, 22.5]);
    // Coefficients can be swapped without recompiling.
    let mut c = c;
    assert_eq!(c.coefficients(), vec![-2.0, 3.0, 0.5]);
    c.set_coefficients(&[1.0, 0.0, 0.0]).unwrap();
    assert_eq!(c.eval_output(0, &[1.0, 2.0, 4.0]).unwrap(), 1.0);
    assert!(c.set_coefficients(&[1.0]).is_err());
    // No tau, no degree: still valid, degree inferred.
    let m2 = Model::from_json_str(
        r#"{"format":"ctsid-model/1","inputs":[],"outputs":[{"name":"x","order":1,"terms":[{"exponents":{"x":2},"coefficient":-1}]}]}"#,
        "m",
    )
    .unwrap();
    assert_eq!(m2.degree, 2);
    assert_eq!(m2.tau, None);
}

#[test]
fn mimo_layout_and_cross_derivatives() {
    let text = r#"{"format":"ctsid-model/1","tau":0.01,"degree":3,"inputs":["u1","u2"],
      "outputs":[{"name":"a","order":2,"terms":[{"exponents":{"b_d2":1,"a":1},"coefficient":2}]},
                 {"name":"b","order":3,"terms":[{"exponents":{"a_d1":1,"u2":2},"coefficient":-1}]}]}"#;
    let m = Model::from_json_str(text, "m").unwrap();
    assert_eq!(
        m.variable_names(),
        ["a", "a_d1", "b", "b_d1", "b_d2", "u1", "u2"]
    );
    let c = m.compile().unwrap();
    let x = [1.0, 2.0, 3.0, 4.0, 5.0];
    let u = [7.0, 3.0];
    let mut dx = [0.0; 5];
    c.rhs(&x, &u, &mut dx).unwrap();
    assert_eq!(dx, [2.0, 2.0 * 5.0 * 1.0, 4.0, 5.0, -2.0 * 9.0]);
    // Analytic Jacobian against central differences.
    let mut jx = [0.0; 25];
    let mut ju = [0.0; 10];
    c.jacobians(&x, &u, &mut jx, &mut ju).unwrap();
    for k in 0..5 {
        let mut xp = x;
        let mut xm = x;
        xp[k] += 1e-6;
        xm[k] -= 1e-6;
        let (mut fp, mut fm) = ([0.0; 5], [0.0; 5]);
        c.rhs(&xp, &u, &mut fp).unwrap();
        c.rhs(&xm, &u, &mut fm).unwrap();
        for r in 0..5 {
            assert!(
                (jx[r * 5 + k] - (fp[r] - fm[r]) / 2e-6).abs() < 1e-6,
                "J[{r}][{k}]"
            );
        }
    }
    assert_eq!(ju[4 * 2 + 1], -2.0 * 2.0 * 3.0); // d(-a_d1*u2^2)/du2
}

#[test]
fn unparsable_json_names_line_and_column() {
    let e = err_of("{\"format\": \"ctsid-model/1\",\n \"inputs\": [u]}");
    assert!(e.contains("m.json") && e.contains("line 2"), "{e}");
    assert!(!e.contains('\n'));
}

#[test]
fn input_interpolation_is_optional_written_when_not_linear_and_checked() {
    let text = r#"{"format": "ctsid-model/2", "inputs": ["u"], "input_interpolation": "cubic",
      "outputs": [{"name": "y", "order": 1, "terms": [{"exponents": {"u": 1}, "coefficient": 1}]}]}"#;
    let m = Model::from_json_str(text, "m.json").unwrap();
    assert_eq!(m.input_interpolation, ctsid::model::Interpolation::Cubic);
    assert!(m
        .to_json_string()
        .unwrap()
        .contains("\"input_interpolation\": \"cubic\""));
    // Absent means linear, and a linear model's file does not carry the key.
    assert!(!siso()
        .to_json_string()
        .unwrap()
        .contains("input_interpolation"));
    let e = err_of(&text.replace("\"cubic\"", "\"spline\""));
    assert!(e.contains("spline") && e.contains("cubic"), "{e}");
}

#[test]
fn unknown_format_is_refused() {
    let e = err_of(
        r#"{"format":"ctsid-model/9","inputs":[],"outputs":[{"name":"y","order":1,"terms":[]}]}"#,
    );
    assert!(
        e.contains("unknown format") && e.contains("ctsid-model/9"),
        "{e}"
    );
    let e = err_of(r#"{"inputs":[],"outputs":[{"name":"y","order":1,"terms":[]}]}"#);
    assert!(e.contains("format"), "{e}");
}

#[test]
fn unknown_variable_names_the_term_and_name() {
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[
        {"exponents":{"y":1},"coefficient":1},{"exponents":{"v":1},"coefficient":1}]}]}"#,
    );
    assert!(
        e.contains("term 2") && e.contains("'v'") && e.contains("unknown variable"),
        "{e}"
    );
}

/// An exponent of 0 drops the name from the term, but a name that is no variable is still a
/// typo to name (it was dropped without a word); known names with 0 read as before.
#[test]
fn a_zero_exponent_on_an_unknown_name_is_refused() {
    let e = err_of(
        r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[
        {"exponents":{"y":1},"coefficient":1},{"exponents":{"u":1,"nosuchvar":0},"coefficient":1}]}]}"#,
    );
    assert!(
        e.contains("term 2") && e.contains("'nosuchvar'") && e.contains("exponent 0"),
        "{e}"
    );
    let e = err_of(
        r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[
        {"exponents":{"y_d2":0, "u":1},"coefficient":1}]}]}"#,
    );
    assert!(e.contains("y_d2") && e.contains("y..y_d1"), "{e}");
    let m = Model::from_json_str(
        r#"{"format":"ctsid-model/2","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[
        {"exponents":{"y_d1":0, "u":1, "y_d0":0},"coefficient":1}]}]}"#,
        "m.json",
    )
    .unwrap();
    assert_eq!(m.to_string().trim(), "y_d2 = 1*u");
}

#[test]
fn derivative_at_or_above_the_order_is_refused() {
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":3,"terms":[
        {"exponents":{"y_d3":1},"coefficient":1}]}]}"#,
    );
    assert!(
        e.contains("term 1")
            && e.contains("y_d3")
            && e.contains("order 3")
            && e.contains("y..y_d2"),
        "{e}"
    );
    // MIMO: b's derivatives only up to b's own order - 1, also in a's equation.
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":[],"outputs":[{"name":"a","order":3,"terms":[
        {"exponents":{"b_d2":1},"coefficient":1}]},{"name":"b","order":2,"terms":[]}]}"#,
    );
    assert!(e.contains("output 'a'") && e.contains("b_d2"), "{e}");
}

#[test]
fn bad_exponents_and_coefficients_are_refused() {
    for bad in ["-1", "1.5", "\"2\""] {
        let e = err_of(&format!(
            r#"{{"format":"ctsid-model/1","inputs":["u"],"outputs":[{{"name":"y","order":1,"terms":[
            {{"exponents":{{"u":{bad}}},"coefficient":1}}]}}]}}"#
        ));
        assert!(
            e.contains("term 1") && e.contains("'u'") && e.contains("integers in 0..=64"),
            "{bad}: {e}"
        );
    }
    // Non-finite coefficients cannot be written in JSON; they are refused when built in code.
    let mut m = siso();
    m.outputs[0].terms[0].coefficient = f64::NAN;
    let e = m.to_json_string().unwrap_err().to_string();
    assert!(e.contains("term 1") && e.contains("not finite"), "{e}");
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{},"coefficient":1e999}]}]}"#,
    );
    assert!(e.contains("m.json"), "{e}");
}

#[test]
fn name_clashes_and_degree_are_checked() {
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["y"],"outputs":[{"name":"y","order":1,"terms":[]}]}"#,
    );
    assert!(e.contains("'y'") && e.contains("twice"), "{e}");
    let e = err_of(
        r#"{"format":"ctsid-model/1","degree":1,"inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[{"exponents":{"u":2},"coefficient":1}]}]}"#,
    );
    assert!(e.contains("degree 2") && e.contains("degree 1"), "{e}");
}

#[test]
fn typos_huge_orders_and_foreign_files_are_named() {
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":2,"termz":[]}]}"#,
    );
    assert!(
        e.contains("no \"terms\" list") && e.contains("termz"),
        "{e}"
    );
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":2,"terms":[{"exponents":{"y":1,"y":2},"coefficient":1}]}]}"#,
    );
    assert!(e.contains("'y' appears twice"), "{e}");
    let e = err_of(
        r#"{"format":"ctsid-model/1","inputs":["u"],"outputs":[{"name":"y","order":100000000,"terms":[]}]}"#,
    );
    assert!(
        e.contains("order 100000000") && e.contains("up to 8"),
        "{e}"
    );
    // A regression result is not a model file: named as such, not by its first missing field.
    let e = err_of(r#"{"terms":[],"diagnostics":{}}"#);
    assert!(e.contains("no \"format\" field"), "{e}");
    // A byte-order mark (as some editors write) is not an error.
    let text = format!("\u{feff}{}", siso().to_json_string().unwrap());
    Model::from_json_str(&text, "bom.json").unwrap();
}

/// A written model reads back to the last bit: serde_json's default float parser was one ulp off
/// on -25.55346732693508 (the Python package's model and the CLI's file then differed).
#[test]
fn coefficients_round_trip_to_the_last_bit() {
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let mut values: Vec<f64> = vec![-25.55346732693508, 33.46124586447356, 1e-300, -7.5e300];
    for _ in 0..2000 {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        // Finite doubles of every magnitude.
        let v = f64::from_bits(state & !(0x7FFu64 << 52) | ((state % 2000 + 24) << 52));
        values.push(v);
    }
    let terms: Vec<String> = values
        .iter()
        .enumerate()
        .map(|(k, v)| {
            let (a, b) = (1 + k % 64, k / 64);
            format!(r#"{{"exponents": {{"y": {a}, "u": {b}}}, "coefficient": {v:e}}}"#)
        })
        .collect();
    let text = format!(
        r#"{{"format": "ctsid-model/2", "inputs": ["u"], "outputs": [{{"name": "y", "order": 1, "terms": [{}]}}]}}"#,
        terms.join(",").replace(r#", "u": 0"#, "")
    );
    let m = ctsid::Model::from_json_str(&text, "t").unwrap();
    let again = ctsid::Model::from_json_str(&m.to_json_string().unwrap(), "t").unwrap();
    for (k, (a, b)) in m.outputs[0]
        .terms
        .iter()
        .zip(&again.outputs[0].terms)
        .enumerate()
    {
        assert_eq!(
            a.coefficient.to_bits(),
            values[k].to_bits(),
            "parse of {:e}",
            values[k]
        );
        assert_eq!(
            a.coefficient.to_bits(),
            b.coefficient.to_bits(),
            "write and read of {:e}",
            values[k]
        );
    }
}

/// `ctsid show` says what an empty interval column means and counts the terms whose standard
/// error exceeds half their coefficient (both were shown without a word).
#[test]
fn show_explains_empty_intervals_and_poorly_determined_terms() {
    let text = r#"{"format":"ctsid-model/2","tau":0.01,"inputs":["u"],"outputs":[{"name":"y","order":1,"terms":[
        {"exponents":{"y":1},"coefficient":-2.0,"std_error":0.1},
        {"exponents":{"u":1},"coefficient":3.0,"std_error":2.0},
        {"exponents":{"u":2},"coefficient":0.1,"std_error":0.01,"interval":[0.08,0.12]}]}]}"#;
    let path = temp_file("show_notes", "m.json", text);
    let (ok, out, err) = ctsid(&["show", &path]);
    assert!(ok, "{err}");
    assert!(
        out.contains("95 % interval '-': intervals are discover's bootstrap"),
        "{out}"
    );
    assert!(
        out.contains("1 term(s) with a standard error above half"),
        "{out}"
    );
    // Every term with an interval and a small standard error: neither note.
    let tight = text.replace("\"std_error\":2.0", "\"std_error\":0.2");
    let tight = tight.replace(
        "\"coefficient\":-2.0,\"std_error\":0.1}",
        "\"coefficient\":-2.0,\"std_error\":0.1,\"interval\":[-2.2,-1.8]}",
    );
    let tight = tight.replace(
        "\"coefficient\":3.0,\"std_error\":0.2}",
        "\"coefficient\":3.0,\"std_error\":0.2,\"interval\":[2.6,3.4]}",
    );
    let path = temp_file("show_notes", "tight.json", &tight);
    let (ok, out, err) = ctsid(&["show", &path]);
    assert!(ok, "{err}");
    assert!(
        !out.contains("95 % interval '-'") && !out.contains("above half"),
        "{out}"
    );
}
