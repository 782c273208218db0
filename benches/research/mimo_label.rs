//! Diagnostic: is the MIMO plant's derivative-fit attenuation in the label or in the regressors?
//! y2's equation at 1 % noise, d = 1 (its linear terms plus the true y1*y3_d1): least squares of
//! (a) the smoothed noisy label on the true states through the same smoother, (b) the smoothed
//! noise-free label on the same, (c) the true label on the true states.
//! `cargo bench --bench mimo_label -- NOISE`
use ctsid::derivatives::{differentiate_runs, DerivativeOptions};
use ctsid::plants::{dataset, Plant};

fn lstsq(cols: &[Vec<f64>], y: &[f64]) -> Vec<f64> {
    let p = cols.len();
    let mut a = nalgebra::DMatrix::<f64>::zeros(p, p);
    let mut b = nalgebra::DVector::<f64>::zeros(p);
    for i in 0..p {
        for j in 0..p {
            a[(i, j)] = cols[i].iter().zip(&cols[j]).map(|(x, z)| x * z).sum();
        }
        b[i] = cols[i].iter().zip(y).map(|(x, z)| x * z).sum();
    }
    a.lu().solve(&b).unwrap().iter().copied().collect()
}

fn main() {
    let a: Vec<String> = std::env::args().filter(|a| a != "--bench").collect();
    let noise: f64 = a.get(1).and_then(|v| v.parse().ok()).unwrap_or(0.01);
    let plant = Plant::mimo();
    let runs = dataset(&plant, 25, 1000, 0.01, noise, 1).unwrap();
    let tau = 0.01;
    // The self-tuned smoother of y2 at order 4 (what identify's MIMO preparation uses).
    let noisy: Vec<&[f64]> = runs.iter().map(|r| r.y[1].as_slice()).collect();
    let tuned = differentiate_runs(&noisy, tau, 4, &DerivativeOptions::default()).unwrap();
    let (states, h) = (tuned[0].states, tuned[0].h);
    println!("y2 smoother: {states} states, h = {h}");
    let lin = DerivativeOptions {
        states: Some(states),
        h: Some(h),
        adaptive: false,
        end_blend: false,
        exp_sum: false,
        ..Default::default()
    };
    let smooth =
        |series: Vec<&[f64]>, order: usize| differentiate_runs(&series, tau, order, &lin).unwrap();
    let label_noisy = smooth(noisy.clone(), 3);
    let clean: Vec<&[f64]> = runs.iter().map(|r| r.y_true[1].as_slice()).collect();
    let label_clean = smooth(clean, 3);
    // Regressors: true y2, y2_d1, y2_d2, u2, y1*y3_d1 through the smoother at order 0.
    let sm0 = |f: &dyn Fn(&ctsid::plants::Run) -> Vec<f64>| -> Vec<f64> {
        let s: Vec<Vec<f64>> = runs.iter().map(f).collect();
        let r: Vec<&[f64]> = s.iter().map(|v| v.as_slice()).collect();
        smooth(r, 0)
            .into_iter()
            .flat_map(|d| d.values[0].clone())
            .collect()
    };
    let cols = vec![
        sm0(&|r| r.derivatives[1][0].clone()),
        sm0(&|r| r.derivatives[1][1].clone()),
        sm0(&|r| r.derivatives[1][2].clone()),
        sm0(&|r| r.u[1].clone()),
        sm0(&|r| {
            r.derivatives[0][0]
                .iter()
                .zip(&r.derivatives[2][1])
                .map(|(a, b)| a * b)
                .collect()
        }),
    ];
    // Leave out the first and last 50 samples of each run (ends).
    let keep: Vec<bool> = runs
        .iter()
        .flat_map(|r| (0..r.t.len()).map(|k| k >= 50 && k + 50 < r.t.len()))
        .collect();
    let sel = |v: &[f64]| -> Vec<f64> {
        v.iter()
            .zip(&keep)
            .filter(|(_, k)| **k)
            .map(|(x, _)| *x)
            .collect()
    };
    let cols: Vec<Vec<f64>> = cols.iter().map(|c| sel(c)).collect();
    let flat = |ds: &[ctsid::derivatives::Derivatives]| -> Vec<f64> {
        sel(&ds
            .iter()
            .flat_map(|d| d.values[3].clone())
            .collect::<Vec<_>>())
    };
    let truth: Vec<f64> = sel(&runs
        .iter()
        .flat_map(|r| r.derivatives[1][3].clone())
        .collect::<Vec<_>>());
    let true_cols: Vec<Vec<f64>> = [
        |r: &ctsid::plants::Run| r.derivatives[1][0].clone(),
        |r: &ctsid::plants::Run| r.derivatives[1][1].clone(),
        |r: &ctsid::plants::Run| r.derivatives[1][2].clone(),
        |r: &ctsid::plants::Run| r.u[1].clone(),
        |r: &ctsid::plants::Run| {
            r.derivatives[0][0]
                .iter()
                .zip(&r.derivatives[2][1])
                .map(|(a, b)| a * b)
                .collect()
        },
    ]
    .iter()
    .map(|f| sel(&runs.iter().flat_map(f).collect::<Vec<_>>()))
    .collect();
    // (d) every regressor from a smoothing at the label's order (values[0] of an order-3 call).
    let sm3 = |f: &dyn Fn(&ctsid::plants::Run) -> Vec<f64>| -> Vec<f64> {
        let s: Vec<Vec<f64>> = runs.iter().map(f).collect();
        let r: Vec<&[f64]> = s.iter().map(|v| v.as_slice()).collect();
        sel(&smooth(r, 3)
            .into_iter()
            .flat_map(|d| d.values[0].clone())
            .collect::<Vec<_>>())
    };
    let cols3 = vec![
        sm3(&|r| r.derivatives[1][0].clone()),
        sm3(&|r| r.derivatives[1][1].clone()),
        sm3(&|r| r.derivatives[1][2].clone()),
        sm3(&|r| r.u[1].clone()),
        sm3(&|r| {
            r.derivatives[0][0]
                .iter()
                .zip(&r.derivatives[2][1])
                .map(|(a, b)| a * b)
                .collect()
        }),
    ];
    println!(
        "(d) clean label, H3 x:  {:?}",
        lstsq(&cols3, &flat(&label_clean))
    );
    println!(
        "(e) noisy label, H3 x:  {:?}",
        lstsq(&cols3, &flat(&label_noisy))
    );
    // (f) every regressor through the label's own filter: the order-3 smoother's third
    // derivative of the regressor integrated three times (cumulative trapezoid per run).
    let integrate = |v: &[f64], times: usize| -> Vec<f64> {
        let mut x = v.to_vec();
        for _ in 0..times {
            let mut acc = 0.0;
            let mut out = vec![0.0; x.len()];
            for k in 1..x.len() {
                acc += 0.5 * tau * (x[k] + x[k - 1]);
                out[k] = acc;
            }
            x = out;
        }
        x
    };
    let g = |f: &dyn Fn(&ctsid::plants::Run) -> Vec<f64>, times: usize| -> Vec<f64> {
        let s: Vec<Vec<f64>> = runs.iter().map(|r| integrate(&f(r), times)).collect();
        let r: Vec<&[f64]> = s.iter().map(|v| v.as_slice()).collect();
        sel(&smooth(r, 3)
            .into_iter()
            .flat_map(|d| d.values[3].clone())
            .collect::<Vec<_>>())
    };
    let colsg = vec![
        g(&|r| r.derivatives[1][0].clone(), 3),
        g(&|r| r.derivatives[1][1].clone(), 3),
        g(&|r| r.derivatives[1][2].clone(), 3),
        g(&|r| r.u[1].clone(), 3),
        g(
            &|r| {
                r.derivatives[0][0]
                    .iter()
                    .zip(&r.derivatives[2][1])
                    .map(|(a, b)| a * b)
                    .collect()
            },
            3,
        ),
    ];
    println!(
        "(f) clean label, G x:   {:?}",
        lstsq(&colsg, &flat(&label_clean))
    );
    println!(
        "(g) noisy label, G x:   {:?}",
        lstsq(&colsg, &flat(&label_noisy))
    );
    // (h) measured signals only: y2's own derivatives as G of the noisy y2 integrated 3 - k
    // times, u2 and the product as in (f) but from the noisy y1, y3 (product of measured y1 and
    // the smoothed y3_d1).
    let colsm = vec![
        g(&|r| r.y[1].clone(), 3),
        g(&|r| r.y[1].clone(), 2),
        g(&|r| r.y[1].clone(), 1),
        g(&|r| r.u[1].clone(), 3),
        g(
            &|r| {
                r.derivatives[0][0]
                    .iter()
                    .zip(&r.derivatives[2][1])
                    .map(|(a, b)| a * b)
                    .collect()
            },
            3,
        ),
    ];
    println!(
        "(h) noisy label, G y:   {:?}",
        lstsq(&colsm, &flat(&label_noisy))
    );
    println!("truth:                  -8 -14 -7 24 2");
    println!(
        "(a) noisy label, H x:   {:?}",
        lstsq(&cols, &flat(&label_noisy))
    );
    println!(
        "(b) clean label, H x:   {:?}",
        lstsq(&cols, &flat(&label_clean))
    );
    println!("(c) true label, x:      {:?}", lstsq(&true_cols, &truth));
}
