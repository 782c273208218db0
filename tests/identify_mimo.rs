//! The MIMO plant (2 inputs, 3 outputs of relative degree 3, dim z = 11) identified noise-free at
//! d = 4 (1,365 candidates per output): every one of the 18 true terms, nothing else, and a
//! free-run simulation of the held-out runs that follows the true outputs. The structure search
//! is forward orthogonal least squares (identify's default); the lasso path misses most of the
//! terms (`ctsid demo mimo --degrees 4 --method lassolars`: 7 of 18).

use ctsid::demo::{coefficient_errors, nrmse_vs_truth, records};
use ctsid::identify::{identify, Orders, Selection, Settings, Split};
use ctsid::model::{Model, OutputEquation, Term};
use ctsid::plants::mimo::MimoPlant;
use ctsid::plants::{dataset, write_csv, Dynamics, Plant};
use ctsid::regression::EngineChoice;

/// The plant's truth, its runs (`n_runs` of 1000 samples, the first `n_train` train, the rest
/// test) and identify's model at d = 4 with the orders fixed at 3 on the CPU engine.
fn fixed_orders_fit(
    n_runs: usize,
    n_train: usize,
    noise: f64,
    seed: u64,
) -> (
    Model,
    Vec<ctsid::plants::Run>,
    ctsid::identify::Identification,
) {
    mimo_fit((n_runs, n_train), noise, seed, Orders::Fixed(vec![3; 3]))
}

/// The plant's truth, its runs (`n_runs` of 1000 samples at `noise`, the first `n_train` train,
/// the rest test) and identify's model at d = 4 with `orders` on the CPU engine.
fn mimo_fit(
    runs: (usize, usize),
    noise: f64,
    seed: u64,
    orders: Orders,
) -> (
    Model,
    Vec<ctsid::plants::Run>,
    ctsid::identify::Identification,
) {
    mimo_fit_with(runs, noise, seed, |s| s.orders = orders.clone())
}

/// [`mimo_fit`] with the settings (d = 4, CPU engine) changed by `tweak` before the fit.
fn mimo_fit_with(
    (n_runs, n_train): (usize, usize),
    noise: f64,
    seed: u64,
    tweak: impl Fn(&mut Settings),
) -> (
    Model,
    Vec<ctsid::plants::Run>,
    ctsid::identify::Identification,
) {
    let plant = Plant::mimo();
    let (inputs, outputs) = (plant.input_names(), plant.output_names());
    let truth = plant.true_model(Some(0.01)).unwrap();
    let runs = dataset(&plant, n_runs, 1000, 0.01, noise, seed).unwrap();
    let rs = records(&runs, &inputs, &outputs, 0.01).unwrap();
    let ids: Vec<String> = (0..n_runs).map(|i| i.to_string()).collect();
    let split = Split::new(
        (0..n_train).collect(),
        None,
        (n_train..n_runs).collect(),
        &ids,
    )
    .unwrap();
    let mut s = Settings::new(outputs, inputs, 4);
    s.engine = EngineChoice::Cpu;
    tweak(&mut s);
    let id = identify(&rs, &split, &s).unwrap();
    (truth, runs, id)
}

#[test]
fn mimo_plant_at_degree_four_gives_exactly_the_true_equations() {
    let (truth, runs, id) = fixed_orders_fit(16, 12, 0.0, 7);
    for i in 0..3 {
        let (rows, extra) = coefficient_errors(&id.model, &truth, i);
        assert!(
            extra.is_empty(),
            "output {i}: extra terms {extra:?}\n{}",
            id.model.outputs[i].to_text()
        );
        for (term, want, got, rel) in rows {
            assert!(
                rel.abs() < 1e-3,
                "output {i}: {term}: {got} vs {want}\n{}",
                id.model.outputs[i].to_text()
            );
        }
        let (_, _, pooled, diverged) = nrmse_vs_truth(&id, &runs, i);
        assert_eq!(diverged, 0);
        assert!(
            pooled < 1e-3,
            "output {i}: free-run NRMSE vs truth {pooled}"
        );
    }
}

/// The orders of a MIMO plant are chosen on free-run simulation, each candidate order of an
/// output simulated with the other outputs fed from their smoothed measurements. On the
/// noise-free plant at d = 3 the paper's derivative-domain profiles chose wrong orders (y1 got
/// order 1 with 40 terms, its p100 set by a few samples at input kinks); truth (3, 3, 3).
#[test]
fn mimo_orders_are_chosen_on_free_run_simulation() {
    let plant = Plant::mimo();
    let (inputs, outputs) = (plant.input_names(), plant.output_names());
    let runs = dataset(&plant, 40, 1000, 0.01, 0.0, 1).unwrap();
    let rs = records(&runs, &inputs, &outputs, 0.01).unwrap();
    let ids: Vec<String> = (0..40).map(|i| i.to_string()).collect();
    let split = Split::new((0..25).collect(), None, (25..40).collect(), &ids).unwrap();
    let mut s = Settings::new(outputs.clone(), inputs.clone(), 3);
    s.orders = Orders::Search(vec![1, 2, 3, 4]);
    s.engine = EngineChoice::Cpu;
    s.refine = false;
    let orders = |s: &Settings| -> (Vec<usize>, bool) {
        let t = std::time::Instant::now();
        let id = identify(&rs, &split, s).unwrap();
        let orders: Vec<usize> = id.model.outputs.iter().map(|o| o.order).collect();
        eprintln!(
            "{:?}: orders {orders:?} in {:.1} s",
            s.selection,
            t.elapsed().as_secs_f64()
        );
        for o in &id.outputs {
            for c in &o.candidates {
                eprintln!(
                    "  {} order {}: derivative p95 {:.3e} p100 {:.3e}, free run {:?}",
                    o.name,
                    c.order,
                    c.validation.p95(),
                    c.validation.p100(),
                    c.simulation.map(|p| (p.p95(), p.p100()))
                );
            }
        }
        // Every candidate carries the free-run profile it was chosen on.
        let simulated = id
            .outputs
            .iter()
            .all(|o| o.candidates.iter().all(|c| c.simulation.is_some()));
        (orders, simulated)
    };
    s.selection = Selection::Derivative;
    let (paper, _) = orders(&s);
    s.selection = Selection::Simulation;
    let (ours, simulated) = orders(&s);
    assert_eq!(ours, vec![3, 3, 3]);
    assert!(simulated);
    // The case this selection exists for: the derivative profiles alone choose wrong here.
    assert_ne!(paper, vec![3, 3, 3]);
}

/// A 2-input 3-output record of our own (not the built-in plant): outputs of orders 2, 3 and 1
/// coupled through products, 20 runs at `noise`, written as CSV and identified by `ctsid
/// identify` with the orders searched (1..4 each, chosen on free-run simulation) at d = 3.
/// Returns the true model and the model file written.
/// `ctsid identify CSV` (runs in column `run`, time in `t`, the CPU engine, quietly) with `args`,
/// which must succeed; the model file it writes beside the record.
/// The model `ctsid identify` writes for `csv` with `args`, and the report it prints.
fn identify_csv(csv: &std::path::Path, args: &[&str]) -> (Model, String) {
    let out = csv.with_extension("model.json");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_ctsid"))
        .args(["identify", csv.to_str().unwrap()])
        .args([
            "--run-column",
            "run",
            "--time-column",
            "t",
            "--engine",
            "cpu",
            "--quiet",
        ])
        .args(args)
        .args(["-o", out.to_str().unwrap()])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    (
        Model::read(out.to_str().unwrap()).unwrap(),
        String::from_utf8_lossy(&run.stdout).into_owned(),
    )
}

fn own_record_through_identify(noise: f64) -> (Model, Model, String) {
    let t = Term::new;
    let truth = Model::new(
        &["u1", "u2"],
        vec![
            OutputEquation::new(
                "a",
                2,
                vec![
                    t(&[("a", 1)], -4.0),
                    t(&[("a_d1", 1)], -3.0),
                    t(&[("u1", 1)], 5.0),
                    t(&[("b", 1), ("c", 1)], 0.5),
                ],
            ),
            OutputEquation::new(
                "b",
                3,
                vec![
                    t(&[("b", 1)], -6.0),
                    t(&[("b_d1", 1)], -11.0),
                    t(&[("b_d2", 1)], -6.0),
                    t(&[("u2", 1)], 10.0),
                    t(&[("a", 1), ("u1", 1)], 1.0),
                ],
            ),
            OutputEquation::new(
                "c",
                1,
                vec![
                    t(&[("c", 1)], -2.0),
                    t(&[("u2", 1)], 3.0),
                    t(&[("a", 2)], -0.5),
                ],
            ),
        ],
        Some(0.01),
    );
    let plant = Plant {
        name: "own".into(),
        dynamics: Dynamics::Mimo(Box::new(MimoPlant {
            model: truth.clone(),
            compiled: truth.compile().unwrap(),
        })),
        excitation: Plant::mimo().excitation,
    };
    let runs = dataset(&plant, 20, 1000, 0.01, noise, 11).unwrap();
    let dir = std::env::temp_dir().join(format!("ctsid-mimo-csv-{}-{noise}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("own.csv");
    write_csv(&plant, &runs, csv.to_str().unwrap(), false).unwrap();
    let t0 = std::time::Instant::now();
    let (found, printed) = identify_csv(
        &csv,
        &[
            "--output", "a,b,c", "--input", "u1,u2", "--degree", "3", "--orders", "1..4",
            "--train", "0-13", "--test", "14-19",
        ],
    );
    eprintln!(
        "noise {noise}: identified in {:.1} s",
        t0.elapsed().as_secs_f64()
    );
    let _ = std::fs::remove_dir_all(&dir);
    (truth, found, printed)
}

/// Noise-free: the true orders and exactly the true terms. At 1 % noise: the true orders and
/// every true term within 5 %, at most one other. Measured: 13 / 13, none other, coefficients
/// within 4.3 % (b's `a*u1` 1.043); the derivative fit keeps `b*u1` and four small products for
/// `a*u1` (a and b move together); the completion adds `a*u1` (z = 13.1 on the gate runs) and
/// pruning then removes `b*u1` and the products. The screen used to set `a*u1` aside both as an
/// addition (the residual under the pooled noise floor) and as a swap for `b*u1` (a predicted
/// drop of 11.9 under the threshold of 25; `complete::DROP_SCREEN` is 9 and serves both now):
/// 12 / 13 and seven others, b's free run 0.81 % from the noise-free truth (0.15 % now).
#[test]
fn mimo_csv_record_of_mixed_orders_through_identify() {
    let (truth, found, _) = own_record_through_identify(0.0);
    let orders: Vec<usize> = found.outputs.iter().map(|o| o.order).collect();
    assert_eq!(orders, vec![2, 3, 1], "{found}");
    for i in 0..3 {
        let (rows, extra) = coefficient_errors(&found, &truth, i);
        assert!(extra.is_empty(), "output {i}: extra {extra:?}\n{found}");
        for (term, want, got, rel) in rows {
            assert!(
                rel.abs() < 1e-3,
                "output {i}: {term}: {got} vs {want}\n{found}"
            );
        }
    }
    let (_, found, printed) = own_record_through_identify(0.01);
    let orders: Vec<usize> = found.outputs.iter().map(|o| o.order).collect();
    assert_eq!(orders, vec![2, 3, 1], "{found}");
    let mut extras = Vec::new();
    for i in 0..3 {
        let (rows, extra) = coefficient_errors(&found, &truth, i);
        eprintln!("1 % noise, output {i}: {rows:?}, extra {extra:?}");
        for (term, want, got, rel) in rows {
            assert!(
                rel.abs() < 0.05,
                "output {i}: {term}: {got} vs {want}\n{found}"
            );
        }
        extras.extend(extra);
    }
    assert!(extras.len() <= 1, "extra terms {extras:?}\n{found}");
    // The report says what the completion tried and kept.
    let line = printed
        .lines()
        .find(|l| l.starts_with("Completion on simulation error"))
        .unwrap_or_else(|| panic!("no completion line\n{printed}"));
    assert!(
        line.contains("kept a*u1 added to 'b' (z ")
            || line.contains("kept a*u1 in place of b*u1 in 'b' (z "),
        "{line}"
    );
}

/// At 1 % noise (d = 4, the demo's 40 runs, orders fixed at 3), every true term of the three
/// outputs is found, each coefficient within 5 %, with at most one extra term, and every output
/// simulates the test runs within 2 % of the noise-free truth. The derivative fit alone
/// attenuates y1's coefficients and masks `y1^3` (found by the completion among the terms of the
/// fit through the label's own filter), and it keeps y3's `u1*y2_d1*y3` for the true
/// `u1*y2*y2_d1` (y2 and y3 move together; the completion's swaps tell them apart on held-out
/// free runs). Measured: 18 / 18, no extra term, 0.18 / 0.19 / 0.25 % (17 / 18 and 0.21 / 0.20
/// / 0.61 % without the swaps, 8.25 / 0.81 / 1.96 % without the completion's filtered terms).
#[test]
fn mimo_plant_at_one_percent_noise_finds_every_true_term() {
    let (truth, runs, id) = fixed_orders_fit(40, 25, 0.01, 1);
    let mut extras = Vec::new();
    for i in 0..3 {
        let (rows, extra) = coefficient_errors(&id.model, &truth, i);
        for (term, want, got, rel) in rows {
            assert!(
                rel.abs() < 0.05,
                "output {i}: {term}: {got} vs {want}\n{}",
                id.model
            );
        }
        extras.extend(extra);
    }
    assert!(extras.len() <= 1, "extra terms {extras:?}\n{}", id.model);
    for i in 0..3 {
        let (_, _, pooled, diverged) = nrmse_vs_truth(&id, &runs, i);
        assert_eq!(diverged, 0);
        assert!(
            pooled < 0.02,
            "output {i}: NRMSE vs truth {pooled}\n{}",
            id.model
        );
    }
}

/// At 3 % noise (d = 4, the demo's 40 runs and seed, orders searched 1..4 on free-run
/// simulation) every output gets its true order 3, at least 16 of the 18 true terms with at most
/// two others, and a free run within 2.5 % of the noise-free truth. Measured: orders (3, 3, 3),
/// 17 / 18 (`u1*y2*y2_d1` in y3's equation given as `u1*y2*y3`), 0.57 / 0.57 / 1.54 %; before
/// the cap on the label floor (`identify::FLOOR_CAP`) orders (4, 3, 3), 15 / 18, 10 others.
#[test]
fn mimo_plant_at_three_percent_noise_gets_the_true_orders() {
    let (truth, runs, id) = searched_at_three_percent(1);
    assert_true_orders((&truth, &runs, &id), "seed 1", 0.025, (16, 2));
    // Its search settled: (4, 3, 3), then (3, 3, 3) twice.
    assert!(
        !id.notes.iter().any(|n| n.contains("did not settle")),
        "{:?}",
        id.notes
    );
}

/// Seed 4 at d = 6, 3 % noise (`demo mimo --degrees 6 --noise 0.03 --seed 4`): the sweeps
/// settle at (3, 3, 1) (y3's order 1, 13 terms, within eta of order 3's 6 and taken as the lower)
/// after (3, 3, 3) was scored in full with the smaller sum of free-run p95 (5.33 against 5.66):
/// the search takes the configuration scored best in full (`identify::best_configuration`). Its
/// final fits carry every coefficient at about half the truth's and do not follow the outputs in
/// free run; refined from their linear part (as before) the model was 101 / 42 / 34 % from the
/// truth, from their terms up to degree 5 (`RefineOptions::every_lower_start`) it is
/// 0.66 / 0.78 / 1.30 %, 17 / 18 true terms and none other (docs/method/identification.md).
#[test]
fn mimo_plant_at_three_percent_noise_degree_six_seed_four_gets_the_true_orders() {
    let (truth, runs, id) = mimo_fit_with((40, 25), 0.03, 4, |s| {
        s.degree = 6;
        s.orders = Orders::Search(vec![1, 2, 3, 4]);
    });
    assert_true_orders((&truth, &runs, &id), "seed 4, d = 6", 0.02, (17, 1));
}

/// Orders (3, 3, 3), at least `found_min` of the 18 true terms with at most `extras_max` others,
/// and every output's free run on the test runs within `nrmse_max` of the truth, none diverged.
fn assert_true_orders(
    (truth, runs, id): (
        &Model,
        &[ctsid::plants::Run],
        &ctsid::identify::Identification,
    ),
    what: &str,
    nrmse_max: f64,
    (found_min, extras_max): (usize, usize),
) {
    let orders: Vec<usize> = id.model.outputs.iter().map(|o| o.order).collect();
    assert_eq!(orders, vec![3, 3, 3], "{what}: {}", id.model);
    let (mut found, mut extras) = (0, 0);
    for i in 0..3 {
        let (rows, extra) = coefficient_errors(&id.model, truth, i);
        found += rows.iter().filter(|r| r.2 != 0.0).count();
        extras += extra.len();
        let (_, _, pooled, diverged) = nrmse_vs_truth(id, runs, i);
        eprintln!("{what}, output {i}: NRMSE vs truth {pooled}");
        assert_eq!(diverged, 0, "{what}");
        assert!(
            pooled < nrmse_max,
            "{what}, output {i}: {pooled}\n{}",
            id.model
        );
    }
    assert!(
        found >= found_min && extras <= extras_max,
        "{what}: {found} / 18, {extras} others\n{}",
        id.model
    );
}

/// The plant's truth, its runs (the demo's 40, 3 % noise, `seed`) and identify's model at d = 4
/// with the orders searched 1..4 on the CPU engine.
fn searched_at_three_percent(
    seed: u64,
) -> (
    Model,
    Vec<ctsid::plants::Run>,
    ctsid::identify::Identification,
) {
    mimo_fit((40, 25), 0.03, seed, Orders::Search(vec![1, 2, 3, 4]))
}

/// Seed 3 of the same (d = 4, 3 %): the search's first sweep finds y2's orders 3 and 4 within
/// 1.2 % of each other (free-run p95 1.4486 against 1.4308); the paper's eta-rule took order 4,
/// and with y1 and y2 at order 4 y3 fell to order 1: (4, 4, 1), 9 / 18 true terms. The MIMO
/// search takes the lowest of near-equal orders (`profile::eta_rule_parsimonious`). Measured
/// with it: orders (3, 3, 3), 16 / 18 true terms, free run within 4.98 / 0.61 / 2.20 % of the
/// truth (docs/method/identification.md, "The MIMO search over seeds"). Since the completion
/// tries stand-ins of lower degree (`identify::lower_degree_offers`, which give d = 6 at 1 % all
/// 18 true terms on seeds 1 and 2), y1 takes one here, `u1*u2*y1_d2` for `y1^2*y2*y3` (better
/// on the gate runs by z = 208), and its free run ended 7.67-7.79 % from the truth, y1^3 missing:
/// the linearised screen set it aside (a predicted drop of 350 noise variances) because the
/// residual sat under the pooled noise floor (21,435 against 30,000; the plant's noise is a share
/// of each run's amplitude). Where no excess over the floor can be measured the screen now
/// passes an addition on the drop's significance (`complete::DROP_SCREEN`): 17 / 18, no other,
/// 0.61 / 0.57 / 1.83 %.
#[test]
fn mimo_plant_at_three_percent_noise_seed_three_gets_the_true_orders() {
    let (truth, runs, id) = searched_at_three_percent(3);
    assert_true_orders((&truth, &runs, &id), "seed 3", 0.025, (17, usize::MAX));
    // Its search ended in the third sweep on a change, (4, 3, 4) -> (3, 3, 3): right by the
    // truth, and said, with the orders before to compare.
    assert!(
        id.notes
            .iter()
            .any(|n| n.contains("did not settle in 3 sweeps")
                && n.contains("--order 4,3,4 fits the orders before")),
        "{:?}",
        id.notes
    );
}

/// Seed 6 of the same (d = 4, 3 %): the search settles at (4, 3, 3), y1's order 3 kept out by
/// its free-run p100 (4.24 against order 4's 3.50, over eta = 1.2) although its p95 is within 2 %
/// (1.4591 against 1.4318). The near-equal lower order is fitted and refined as a whole model
/// beside the search's own and the coupled free runs of the gate runs compared
/// (`identify::near_configurations`): sums of p95 5.7915 for (4, 3, 3), 5.4476 for (3, 3, 3).
/// Measured: (3, 3, 3), 17 / 18, one other, 0.73 / 0.57 / 1.60 % against the truth (before:
/// (4, 3, 3), 15 / 18, 7.13 / 0.75 / 1.23 %; docs/method/identification.md, session 26).
#[test]
fn mimo_plant_at_three_percent_noise_seed_six_gets_the_true_orders_from_near_equals() {
    let (truth, runs, id) = searched_at_three_percent(6);
    assert_true_orders((&truth, &runs, &id), "seed 6", 0.025, (17, 1));
    assert!(
        id.notes.iter().any(|n| n.contains("near-equal orders")
            && n.contains("orders 'y1' 3, 'y2' 3, 'y3' 3 taken")),
        "{:?}",
        id.notes
    );
}

/// A two-output record with Coulomb friction on the first output, identified with
/// `--term 'sign(a_d1)'`: each output's candidate order is scored as a model of its own, and the
/// sign's smoothing width was looked up with the whole search's orders for a one-output model
/// (an index out of range: a panic before the fix). Truth: `a'' = -2 a - 0.8 a' + u - 0.3
/// sign(a')`, `b' = -b + a`; measured: orders (2, 1), the sign term at -0.2999.
#[test]
fn mimo_identify_with_a_sign_term_scores_each_order_without_a_panic() {
    let dir = std::env::temp_dir().join(format!("ctsid-mimo-sign-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let csv = dir.join("sign.csv");
    let mut text = String::from("run,t,u,a,b\n");
    let mut seed = 3u64;
    for r in 0..10 {
        let (mut a, mut ad, mut b, mut u) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for k in 0..1000 {
            if k % 50 == 0 {
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                u = ((seed >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0;
            }
            text += &format!("{r},{:.4},{u:.6},{a:.8},{b:.8}\n", k as f64 * 0.01);
            for _ in 0..10 {
                let h = 0.001;
                let add = -2.0 * a - 0.8 * ad + u - 0.3 * (ad / 1e-3).tanh();
                ad += h * add;
                a += h * ad;
                b += h * (a - b);
            }
        }
    }
    std::fs::write(&csv, text).unwrap();
    let (found, _) = identify_csv(
        &csv,
        &[
            "--output",
            "a,b",
            "--input",
            "u",
            "--degree",
            "1",
            "--orders",
            "1..2",
            "--term",
            "sign(a_d1)",
            "--train",
            "0-6",
            "--test",
            "7-9",
        ],
    );
    let _ = std::fs::remove_dir_all(&dir);
    let orders: Vec<usize> = found.outputs.iter().map(|o| o.order).collect();
    assert_eq!(orders, vec![2, 1], "{found}");
    let sign = found.outputs[0]
        .terms
        .iter()
        .find(|t| t.expression.as_deref() == Some("sign(a_d1)"))
        .unwrap_or_else(|| panic!("no sign term\n{found}"));
    assert!((sign.coefficient + 0.3).abs() < 0.03, "{found}");
}

/// One training run and no validation runs: the MIMO gate's "held-out" runs are the training
/// run itself. Its residuals were shown as the validation profile; now there is none, and the
/// refinement names its gate a proxy.
#[test]
fn a_mimo_search_on_one_training_run_shows_no_validation_profile() {
    let (tau, n) = (0.05, 400);
    let (mut y1, mut y2) = (0.0f64, 0.0f64);
    let (mut c0, mut c1, mut c2) = (vec![], vec![], vec![]);
    for k in 0..n {
        let u = (0.3 * k as f64 * tau).sin() + (0.05 * k as f64).cos().signum() * 0.5;
        c0.push(y1);
        c1.push(y2);
        c2.push(u);
        // Euler at a tenth of tau: y1' = -y1 + u, y2' = -2 y2 + y1.
        for _ in 0..10 {
            let (d1, d2) = (-y1 + u, -2.0 * y2 + y1);
            y1 += 0.1 * tau * d1;
            y2 += 0.1 * tau * d2;
        }
    }
    let run = ctsid::records::Run {
        id: "0".into(),
        channels: vec![c0, c1, c2],
        t0: 0.0,
        rows: (2..n + 2).collect(),
    };
    let rs =
        ctsid::RecordSet::new(tau, vec!["y1".into(), "y2".into(), "u".into()], vec![run]).unwrap();
    let split = Split::new(vec![0], None, vec![], &["0".to_string()]).unwrap();
    let mut s = Settings::new(vec!["y1".into(), "y2".into()], vec!["u".into()], 1);
    s.orders = Orders::Search(vec![1, 2]);
    s.engine = EngineChoice::Cpu;
    let id = identify(&rs, &split, &s).unwrap();
    for o in &id.outputs {
        for c in &o.candidates {
            assert!(c.validation.p50().is_nan(), "{} order {}", o.name, c.order);
            assert!(c.simulation.is_some());
        }
    }
    let gate = id
        .refinement
        .as_ref()
        .map(|r| r.gate.clone())
        .unwrap_or_default();
    assert!(gate.contains("proxy"), "{gate}");
}

/// The model does not hang on the machine's core count. The CPU engine splits each sweep's
/// samples into tasks by the thread count (eight per thread), which changes only the order in
/// which f64 partial sums are added; on the MIMO plant at 1 % noise, d = 3, the derivative fit
/// (the part the engine computes; the refinement's runs are simulated apart and gathered in
/// order) is the same to the last bit on one thread and on three. (`ctsid demo mimo --degrees 4
/// --noise 0.03` with `RAYON_NUM_THREADS` 1-4 and `CTSID_SIMD` avx512 / avx2 / none, and
/// `--degrees 6` at 3 % with avx512 / avx2, printed the same models too, refinement and all:
/// docs/method/regression.md.)
#[test]
fn the_model_is_the_same_on_one_thread_and_on_three() {
    let fit = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let (_, _, id) = pool.install(|| {
            mimo_fit_with((6, 5), 0.01, 3, |s| {
                s.degree = 3;
                s.orders = Orders::Fixed(vec![3; 3]);
                s.refine = false;
            })
        });
        id.model.to_json_string().unwrap()
    };
    let (one, three) = (fit(1), fit(3));
    assert!(one == three, "one thread:\n{one}\nthree threads:\n{three}");
}
