//! Hard limits of an output (an overflowing tank's level, an end stop): the model file's
//! `limits`, the one simulator keeping them (and their sensitivities), and `identify` reading one
//! from training runs that hold the output at its extreme value. The plant is known: a damped
//! oscillator `y'' = -4 y - 1.2 y' + 4 u` whose level cannot rise above 0.8.

use ctsid::identify::{identify, Orders, Settings, Split};
use ctsid::model::{Limits, Model, OutputEquation, Term};
use ctsid::plants::rng::Rng;
use ctsid::records::{RecordSet, Run};
use ctsid::simulate::{simulate_model, simulate_model_sensitivities, SimOptions};

mod common;
use common::cli::{ctsid, temp_file};

const TAU: f64 = 0.01;
const N: usize = 800;
const TOP: f64 = 0.8;

fn plant(limits: Limits) -> Model {
    let mut eq = OutputEquation::new(
        "y",
        2,
        vec![
            Term::new(&[("y", 1)], -4.0),
            Term::new(&[("y_d1", 1)], -1.2),
            Term::new(&[("u", 1)], 4.0),
        ],
    );
    eq.limits = limits;
    Model::new(&["u"], vec![eq], Some(TAU))
}

fn top() -> Limits {
    Limits {
        min: None,
        max: Some(TOP),
    }
}

fn times() -> Vec<f64> {
    (0..N).map(|k| k as f64 * TAU).collect()
}

fn accurate() -> SimOptions {
    SimOptions {
        rtol: 1e-10,
        atol: 1e-12,
        ..Default::default()
    }
}

#[test]
fn a_limit_in_the_model_file_is_read_written_and_checked() {
    let text = r#"{"format": "ctsid-model/2", "inputs": ["u"], "outputs": [{"name": "y", "order": 1,
        "terms": [{"exponents": {"u": 1}, "coefficient": 1.0}], "limits": {"max": 2.5}}]}"#;
    let m = Model::from_json_str(text, "m.json").unwrap();
    assert_eq!(
        m.outputs[0].limits,
        Limits {
            min: None,
            max: Some(2.5)
        }
    );
    let again = Model::from_json_str(&m.to_json_string().unwrap(), "again.json").unwrap();
    assert_eq!(again, m);
    // Without limits the key is not written (files of before read and write the same).
    assert!(!plant(Limits::default())
        .to_json_string()
        .unwrap()
        .contains("limits"));
    for (limits, needle) in [
        (r#"{"min": 3, "max": 2.5}"#, "min 3 is not below max 2.5"),
        (r#"{"top": 2.5}"#, "unknown field `top`"),
    ] {
        let bad = text.replace(r#"{"max": 2.5}"#, limits);
        let e = Model::from_json_str(&bad, "m.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains(needle) && !e.contains('\n'), "{e}");
    }
    // The polynomial-only format of before has no limits.
    let v1 = text.replace("ctsid-model/2", "ctsid-model/1");
    let e = Model::from_json_str(&v1, "m.json").unwrap_err().to_string();
    assert!(
        e.contains("limits need \"format\": \"ctsid-model/2\""),
        "{e}"
    );
}

#[test]
fn the_simulation_stays_on_the_limit_while_pushed_and_leaves_it_when_the_input_turns() {
    // A unit input for 4 s drives the free level to 1.0: with the limit it rests on 0.8 with
    // zero velocity; the input then turns to -1 and the level falls away from the limit.
    let (t, u) = pushed_then_pulled();
    let tr = run(&plant(top()), &t, &u);
    let (y, v) = (tr.series(0).unwrap(), tr.series(1).unwrap());
    assert!(y.iter().all(|&y| y <= TOP), "above the limit");
    assert_eq!(
        (y[390], v[390]),
        (TOP, 0.0),
        "resting on the limit at 3.9 s"
    );
    assert!(
        y[500] < 0.0 && y[799] < -0.5,
        "left the limit: {} {}",
        y[500],
        y[799]
    );
    // Without the limit the same run overshoots 0.8.
    let free = run(&plant(Limits::default()), &t, &u).series(0).unwrap();
    assert!(free[390] > TOP + 0.05);
}

/// A unit input for 4 s, then -1: its times and samples.
fn pushed_then_pulled() -> (Vec<f64>, Vec<f64>) {
    let t = times();
    let u = t
        .iter()
        .map(|&t| if t < 4.0 { 1.0 } else { -1.0 })
        .collect();
    (t, u)
}

/// The model's accurate simulation from rest under the input `u` at times `t`.
fn run(model: &Model, t: &[f64], u: &[f64]) -> ctsid::simulate::Trajectory {
    let c = model.compile().unwrap();
    simulate_model(&c, &[0.0, 0.0], t, &[u.to_vec()], &accurate()).unwrap()
}

#[test]
fn sensitivities_on_the_limit_are_zero_and_elsewhere_match_finite_differences() {
    let (t, u) = pushed_then_pulled();
    let model = plant(top());
    let c = model.compile().unwrap();
    let inputs = std::slice::from_ref(&u);
    let (tr, s) =
        simulate_model_sensitivities(&c, &[0.0, 0.0], &t, inputs, &accurate(), &[1]).unwrap();
    // Columns: the coefficient of y_d1, then the two initial states; rows: y, y_d1.
    let q = 3;
    let at = |k: usize, state: usize, col: usize| s[(k * 2 + state) * q + col];
    assert_eq!((at(390, 0, 0), at(390, 1, 0)), (0.0, 0.0), "on the limit");
    // After the limit, the level depends on the damping only through the time it left it.
    let k = 700;
    let y0 = tr.series(0).unwrap()[k];
    let mut bumped = model.clone();
    let h = 1e-6;
    bumped.outputs[0].terms[1].coefficient += h;
    let fd = (run(&bumped, &t, &u).series(0).unwrap()[k] - y0) / h;
    assert!(
        (at(k, 0, 0) - fd).abs() <= 1e-3 * fd.abs().max(1e-3),
        "sensitivity {} against finite differences {fd}",
        at(k, 0, 0)
    );
}

/// Runs of the plant with its limit, from rest, under seeded multisines that push it onto the
/// limit now and then; noise-free, so the record holds the level at exactly 0.8 there.
fn record(runs: usize) -> RecordSet {
    let c = plant(top()).compile().unwrap();
    let mut rng = Rng::new(11);
    let t = times();
    let out = (0..runs)
        .map(|r| {
            let comps: Vec<(f64, f64, f64)> = (0..5)
                .map(|_| {
                    (
                        rng.uniform_in(0.2, 0.5),
                        rng.uniform_in(0.5, 4.0),
                        rng.uniform_in(0.0, 6.0),
                    )
                })
                .collect();
            let u: Vec<f64> = t
                .iter()
                .map(|&t| comps.iter().map(|(a, w, p)| a * (w * t + p).sin()).sum())
                .collect();
            let x0 = [rng.uniform_in(-0.3, 0.3), 0.0];
            let tr = simulate_model(&c, &x0, &t, std::slice::from_ref(&u), &accurate()).unwrap();
            Run::new(r.to_string(), vec![tr.series(0).unwrap(), u])
        })
        .collect();
    RecordSet::new(TAU, vec!["y".into(), "u".into()], out).unwrap()
}

#[test]
fn identify_reads_the_held_level_as_a_limit_and_simulates_unseen_runs_with_it() {
    let rs = record(10);
    let held = (0..8)
        .map(|r| rs.runs[r].channels[0].iter().filter(|&&y| y == TOP).count())
        .sum::<usize>();
    assert!(
        held > 50,
        "the runs must hold the level on its limit ({held} samples)"
    );
    let ids: Vec<String> = (0..10).map(|i| i.to_string()).collect();
    let split = Split::new((0..6).collect(), Some(vec![6, 7]), vec![8, 9], &ids).unwrap();
    let mut s = Settings::new(vec!["y".into()], vec!["u".into()], 1);
    s.orders = Orders::Search(vec![1, 2, 3]);
    s.engine = ctsid::regression::EngineChoice::Cpu;
    let id = identify(&rs, &split, &s).unwrap();
    assert_eq!(id.outputs[0].order, 2);
    assert_eq!(id.model.outputs[0].limits, top(), "{:?}", id.notes);
    assert!(
        id.notes
            .iter()
            .any(|n| n.contains("holds its largest value 0.8")),
        "{:?}",
        id.notes
    );
    let with = id.test_nrmse()[0];
    // Measured: the test runs' free-run NRMSE 6.2e-5 with the limit read, 0.43 with it left out.
    s.limits = false;
    let without = identify(&rs, &split, &s).unwrap();
    assert!(without.model.outputs[0].limits.is_none());
    let without = without.test_nrmse()[0];
    println!("test NRMSE with the limit {with}, without {without}");
    assert!(
        with < 0.01 && with < 0.5 * without,
        "with {with}, without {without}"
    );
}

#[test]
fn a_lower_limit_of_an_order_three_output_beside_another_output_is_kept_from_the_start() {
    // Output a (order 1) beside output b (order 3, states 1-3) with b at least -0.5: b is
    // started below its limit and pulled down by its input; a is not limited and moves freely.
    let mut b = OutputEquation::new(
        "b",
        3,
        vec![
            Term::new(&[("b", 1)], -1.0),
            Term::new(&[("b_d1", 1)], -3.0),
            Term::new(&[("b_d2", 1)], -3.0),
            Term::new(&[("u", 1)], 1.0),
        ],
    );
    b.limits = Limits {
        min: Some(-0.5),
        max: Some(5.0),
    };
    let a = OutputEquation::new("a", 1, vec![Term::new(&[("u", 1)], 1.0)]);
    let c = Model::new(&["u"], vec![a, b], Some(TAU)).compile().unwrap();
    let t = times();
    let u = vec![-2.0; N];
    let x0 = [0.0, -0.7, -0.1, 0.3];
    let tr = simulate_model(&c, &x0, &t, std::slice::from_ref(&u), &accurate()).unwrap();
    // From the start: b on its lower limit, its downward velocity at zero, the rest as given.
    assert_eq!(tr.state(0).unwrap(), &[0.0, -0.5, 0.0, 0.3]);
    let (a, b) = (tr.series(0).unwrap(), tr.series(1).unwrap());
    assert!(b.iter().all(|&v| v >= -0.5), "below the limit");
    assert_eq!(b[N - 1], -0.5, "the input holds b on its limit");
    assert!(
        (a[N - 1] + 2.0 * t[N - 1]).abs() < 1e-6,
        "a is free: {}",
        a[N - 1]
    );
}

#[test]
fn the_command_line_notes_the_limit_and_no_limits_leaves_it_out() {
    let rs = record(4);
    let mut csv = String::from("run,y,u\n");
    for run in &rs.runs {
        for k in 0..N {
            csv += &format!(
                "{},{:e},{:e}\n",
                run.id, run.channels[0][k], run.channels[1][k]
            );
        }
    }
    let data = temp_file("limits", "held.csv", &csv);
    let model = temp_file("limits", "held.json", "");
    let args = "--output y --input u --run-column run --tau 0.01 --train 0,1 --validation 2 --test 3 --degree 1 --order 2 --quiet -o";
    let (ok, out, err) = ctsid(&["identify", &data, args, &model]);
    assert!(ok, "{err}");
    assert!(
        format!("{out}{err}").contains("holds its largest value 0.8 for"),
        "{out}{err}"
    );
    assert_eq!(Model::read(&model).unwrap().outputs[0].limits, top());
    let (ok, shown, err) = ctsid(&["show", &model]);
    assert!(
        ok && shown.contains("limits: y at most 0.8 (held there"),
        "{shown}{err}"
    );
    let (ok, out, err) = ctsid(&["identify", &data, args, &model, "--no-limits"]);
    assert!(ok && !format!("{out}{err}").contains("holds its"), "{err}");
    assert!(Model::read(&model).unwrap().outputs[0].limits.is_none());
}
