//! `ctsid control MODEL.json --setpoint R --from Y0 [--bandwidth W] [--observer-speed F]
//! [--tau T] [--plant PLANT.json] [--noise SD] [--seed S] [--duration T] [--u-min A --u-max B]
//! [-o TRACE.csv] [--report DIR] [--reference FILE.csv|steps] [--law placement|profile]
//! [--sigma S] [--block K] [--observer linearised|chain]`
//!
//! Designs an observer and state feedback with integral action on a one-output, one-input model
//! ([`ctsid::control`]), prints the operating point, the linearisation's poles, the gains and
//! the placed poles, then runs the digital loop for a setpoint step from rest at `--from` around
//! the plant (the model itself, or `--plant`, another model file: say the design was made on a
//! simple model and the plant is a richer one) and prints the step figures. `-o` writes the
//! trace (t, reference, y, measured y, estimates, u). With `--reference`, `--law profile` or
//! `--block`, the loop follows the reference under the chosen law instead
//! ([`ctsid::control::tracking`]) and prints the tracking figures.

use clap::Args;
use ctsid::control::{self, DesignOptions, Scenario};
use ctsid::model::Model;
use ctsid::util::{num4, short};
use ctsid::{Error, Result};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct ControlArgs {
    /// Model file (ctsid-model/2 or /1, one output and one input) the controller is designed on;
    /// named terms (friction, drag) are linearised with their exact derivatives.
    pub model: PathBuf,
    /// The output value to hold.
    #[arg(long, allow_hyphen_values = true)]
    pub setpoint: f64,
    /// The plant starts at rest at this output value.
    #[arg(long, allow_hyphen_values = true)]
    pub from: f64,
    /// Closed-loop bandwidth in rad/s (default: the geometric mean of the open-loop eigenvalue
    /// magnitudes at the setpoint).
    #[arg(long)]
    pub bandwidth: Option<f64>,
    /// Observer poles at this factor times the bandwidth.
    #[arg(long, default_value_t = 3.0)]
    pub observer_speed: f64,
    /// Controller sampling period in seconds (default: the model's tau).
    #[arg(long)]
    pub tau: Option<f64>,
    /// The plant the loop runs around (default: the model itself).
    #[arg(long)]
    pub plant: Option<PathBuf>,
    /// Standard deviation of the measurement noise.
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulated time in seconds (default: (3 (n + 1) + 6) / bandwidth for a model of order n).
    #[arg(long)]
    pub duration: Option<f64>,
    /// Lower input limit (with --u-max): the input is clipped, and the integrator holds what
    /// would wind up.
    #[arg(long, allow_hyphen_values = true, requires = "u_max")]
    pub u_min: Option<f64>,
    /// Upper input limit (with --u-min).
    #[arg(long, allow_hyphen_values = true, requires = "u_min")]
    pub u_max: Option<f64>,
    /// Write the loop's trace here (CSV).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// Write plots into this folder: step.svg (output, measured, designed response, setpoint)
    /// and input.svg; with a reference, the profile law or --block above 1, tracking.svg
    /// (reference, output, tracking error, observer error, input) and report.md.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// The control law: `placement` (state feedback with integral action, poles at
    /// -bandwidth) or `profile` (the source paper's exponential-profile law: the input whose
    /// predicted y^(n) follows an exponential profile of rates sigma, 2 sigma, ..., n sigma).
    #[arg(long, value_enum, default_value_t = LawArg::Placement)]
    pub law: LawArg,
    /// Rate of the profile law's slowest exponential, in 1/s (default: the bandwidth).
    #[arg(long, allow_hyphen_values = true)]
    pub sigma: Option<f64>,
    /// Decide the input every K samples and hold it in between (the paper's blocking kappa).
    #[arg(long, default_value_t = 1)]
    pub block: usize,
    /// A reference to follow instead of one step: a CSV file of (time s, reference), or
    /// `steps` for the built-in scenario after the paper's (steps and ramps between --from and
    /// --setpoint over --duration, 5 s by default).
    #[arg(long)]
    pub reference: Option<String>,
    /// The observer's gains: `linearised` (poles placed on the model's linearisation) or
    /// `chain` (the paper's: a chain of integrators with every pole at -observer-speed x
    /// bandwidth, the model as the known leading term).
    #[arg(long, value_enum, default_value_t = ObserverArg::Linearised)]
    pub observer: ObserverArg,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LawArg {
    Placement,
    Profile,
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ObserverArg {
    Linearised,
    Chain,
}

pub fn run(a: ControlArgs) -> Result<()> {
    check_args(&a)?;
    let model = Model::read(&a.model)?;
    let tau = a.tau.or(model.tau).ok_or_else(|| {
        Error::param(
            "tau",
            "the model file has no tau; give the controller's sampling period with --tau",
        )
    })?;
    let mut o = DesignOptions::new(a.setpoint, tau);
    o.bandwidth = a.bandwidth;
    o.observer_speed = a.observer_speed;
    let d = designed(&model, &o, a.observer)?;
    let tracking = tracking_settings(&a, &d)?;
    let plant_model = plant_model(&a, &model)?;
    let (compiled, x0, u0) = control::model_at_rest(&plant_model, a.from, d.u_star)?;
    let default_duration = match &tracking {
        // A reference file that ends within the first ten samples (a constant of one knot, or
        // knots before t = 0) gives no duration of its own: the run was ten samples long without
        // a word; it now lasts as a step would, and says so. (The built-in `steps` scenario
        // lasts --duration, 5 s by default.)
        Some(tk) if a.reference.is_some() => {
            let end = tk.reference.end();
            let file = a.reference.as_deref() != Some("steps");
            if file && a.duration.is_none() && end < 10.0 * d.tau {
                let t = control::default_duration(&d);
                eprintln!(
                    "note: the reference ends at t = {} s, within the first 10 samples; the run lasts {} s as a step's would (give --duration to choose)",
                    ctsid::util::short(end),
                    ctsid::util::num4(t)
                );
                t
            } else {
                end.max(10.0 * d.tau)
            }
        }
        _ => control::default_duration(&d),
    };
    let scenario = Scenario {
        duration: a.duration.unwrap_or(default_duration),
        noise_sd: a.noise,
        seed: a.seed,
        u_limits: a.u_min.zip(a.u_max),
    };
    let plant = control::Plant {
        system: &compiled,
        output: 0,
        x0,
        u0,
    };

    // Before the design is printed: a setting that makes the run meaningless is the answer.
    let law = tracking
        .as_ref()
        .map_or(&control::Law::PolePlacement, |tk| &tk.law);
    control::check_scenario(&d, &scenario, law)?;
    if let Some(tk) = &tracking {
        control::check_block(&d, &scenario, tk)?;
    }
    let names = print_design(&a, &d, law)?;
    if let Some(tk) = tracking {
        return run_tracking(&a, &d, &plant, &scenario, &tk, &names);
    }
    // The design is printed before the loop runs: when the loop fails, it explains why.
    let tr = control::run(&d, &plant, &scenario)?;
    let m = control::metrics(&tr, &d, a.from)?;
    let plant_name = a
        .plant
        .as_ref()
        .map_or("the model itself".to_string(), |p| p.display().to_string());
    outln!(
        "step {} -> {} around {plant_name} (rest input {:.6e}), {} s, noise sd {}:",
        short(a.from),
        short(a.setpoint),
        u0,
        num4(scenario.duration),
        short(a.noise)
    )?;
    let settling = if m.settling_time.is_nan() {
        format!("none within the {} s run", num4(scenario.duration))
    } else {
        format!("{} s", num4(m.settling_time))
    };
    // The final error of a loop that has not settled is a snapshot of its swing (-0.207 % of a
    // loop ringing at +-4 % printed as its final error).
    let final_error = if m.settling_time.is_nan() {
        format!(
            "mean over the last 10 % {:.3} % of the step (not settled)",
            m.final_error
        )
    } else {
        format!("final error {:.3} % of the step", m.final_error)
    };
    let at_limit = scenario.u_limits.map_or(String::new(), |(lo, hi)| {
        let n = tr.u.iter().filter(|&&u| u <= lo || u >= hi).count();
        format!(", input at a limit in {n} of {} samples", tr.u.len())
    });
    let rise = if m.rise_time.is_nan() {
        "never".to_string()
    } else {
        format!("{} s", num4(m.rise_time))
    };
    outln!(
        "rise time (10-90 %) {rise}, overshoot {:.2} %, settling (2 %) {settling}, {final_error}, input {:.4e}..{:.4e}{at_limit}, observer RMS error {:.3e}; largest difference from the designed response {:.2} % of the step",
        m.overshoot,
        m.u_min,
        m.u_max,
        m.observer_rms,
        m.design_deviation
    )?;
    // Around its own model and without noise the loop must do what it was designed for; where
    // it strays from the designed response and does not settle, the sampling (or the model's
    // order) breaks the design, and the figures above are not a controller to use: an error,
    // with no files written. Following the design but unsettled is a short run.
    let unsettled = m.settling_time.is_nan();
    if a.plant.is_none() && a.noise == 0.0 && unsettled && m.design_deviation > DESIGN_STRAY {
        return Err(diagnose_stray(&a, (&model, &o, &d), &plant, &scenario, &m));
    }
    if a.plant.is_none() && a.noise == 0.0 && unsettled {
        eprintln!(
            "note: the loop follows the designed response ({:.2} % off) but has not settled within the {} s run; give a longer --duration to see it settle",
            m.design_deviation,
            num4(scenario.duration)
        );
    }
    if let Some(path) = &a.output {
        // The designed response beside the output: the printed "largest difference from the
        // designed response" could not be checked from the trace.
        let designed = control::designed_response(&d, a.from, tr.t.len())?;
        write_trace(path, &tr, (&names, &d.input), Some(&designed))?;
        super::written(format!("wrote {}", path.display()));
    }
    if let Some(dir) = &a.report {
        write_plots(dir, &d, &tr, a.from)?;
        super::written(format!("plots written to {}", dir.display()));
    }
    Ok(())
}

/// Refuses output paths that would overwrite an input, and a step of no size or from a value
/// that is not finite.
fn check_args(a: &ControlArgs) -> Result<()> {
    let mut inputs = vec![a.model.as_path()];
    if let Some(p) = &a.plant {
        inputs.push(p.as_path());
    }
    // A reference file is an input too (`-o` onto it replaced the user's reference).
    if let Some(r) = a.reference.as_deref().filter(|r| *r != "steps") {
        inputs.push(std::path::Path::new(r));
    }
    if let Some(o) = &a.output {
        super::check_output_file(o, &inputs)?;
    }
    if let Some(d) = &a.report {
        super::check_output_dir(d)?;
        if let Some(o) = &a.output {
            super::check_output_outside_report(o.as_ref(), d)?;
        }
    }
    if !a.from.is_finite() {
        return Err(Error::param(
            "from",
            format!("{}; give a finite value", a.from),
        ));
    }
    if a.from == a.setpoint {
        return Err(Error::param(
            "from",
            "the same as --setpoint: there is no step; give another starting output",
        ));
    }
    Ok(())
}

/// The plant the loop runs around: `--plant`'s model (a SISO model of the same output and input
/// names), else the design model itself.
fn plant_model(a: &ControlArgs, model: &Model) -> Result<Model> {
    Ok(match &a.plant {
        Some(p) => {
            let m = Model::read(p)?;
            control::design::siso_order(&m).map_err(|e| match e {
                Error::InvalidParameter { reason, .. } => Error::param("plant", reason),
                e => e,
            })?;
            // The loop connects the model's input and output to the plant's: by name, so that a
            // plant file of another machine is not used by mistake.
            if m.outputs[0].name != model.outputs[0].name || m.inputs != model.inputs {
                return Err(Error::param(
                    "plant",
                    format!(
                        "{} has output '{}' and input '{}', the model '{}' and '{}'; give a plant of the same machine",
                        p.display(),
                        m.outputs[0].name,
                        m.inputs[0],
                        model.outputs[0].name,
                        model.inputs[0]
                    ),
                ));
            }
            m
        }
        None => model.clone(),
    })
}

/// Prints the design (operating point, poles, gains) and returns the state names.
fn print_design(a: &ControlArgs, d: &control::Design, law: &control::Law) -> Result<Vec<String>> {
    let y = &d.output;
    outln!(
        "# Feedback on {} ({} -> {y}, order {})",
        a.model.display(),
        d.input,
        d.order
    )?;
    outln!("")?;
    outln!(
        "operating point: {y} = {}, steady {} = {:.6e}",
        short(d.setpoint),
        d.input,
        d.u_star
    )?;
    outln!(
        "open-loop poles at the setpoint: {}",
        control::format_poles(&d.open_loop)
    )?;
    let names: Vec<String> = (0..d.order)
        .map(|k| ctsid::model::derivative_name(y, k))
        .collect();
    if let control::Law::Profile(p) = law {
        // The placement's poles and gains were printed here though the profile law never uses
        // them: only its observer is the design's.
        let last = ctsid::model::derivative_name(y, d.order);
        outln!(
            "law: exponential profile, rates {} .. {} 1/s: the input whose predicted {last} brings {y} to the reference along them; tau {} s",
            short(p.sigma),
            short(p.sigma * d.order as f64),
            short(d.tau)
        )?;
        outln!(
            "observer poles (the design's at bandwidth {} rad/s): {}",
            num4(d.bandwidth),
            control::format_poles(&d.observer)
        )?;
        return observer_gains(a, d, &names).map(|()| names);
    }
    outln!(
        "design: bandwidth {} rad/s, tau {} s; controller poles (with integral action): {}",
        num4(d.bandwidth),
        short(d.tau),
        control::format_poles(&d.closed_loop)
    )?;
    outln!("observer poles: {}", control::format_poles(&d.observer))?;
    outln!(
        "gains: u = u* - K (x_hat - x*) - k_i * integral({y} - setpoint); K: {}; k_i {:.6e}",
        gains(&names, &d.k),
        d.k_i
    )?;
    observer_gains(a, d, &names)?;
    Ok(names)
}

/// `name value` pairs of a gain vector over the state's names.
fn gains(names: &[String], g: &[f64]) -> String {
    names
        .iter()
        .zip(g)
        .map(|(n, v)| format!("{n} {v:.6e}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The observer's gains, the end of the design's lines, and the design's notes.
fn observer_gains(a: &ControlArgs, d: &control::Design, names: &[String]) -> Result<()> {
    let y = &d.output;
    outln!(
        "observer gains L (on {y} - {y}_hat, {}): {}",
        match a.observer {
            ObserverArg::Linearised => "placed on the linearisation",
            ObserverArg::Chain => "chain of integrators",
        },
        gains(names, &d.l)
    )?;
    outln!("")?;
    for n in &d.notes {
        eprintln!("note: {n}");
    }
    Ok(())
}

/// The design with the observer asked for (the chain observer's poles and sampled loop checked
/// as the linearised one's are).
fn designed(
    model: &Model,
    o: &DesignOptions,
    observer: ObserverArg,
) -> ctsid::Result<control::Design> {
    let d = control::design(model, o)?;
    match observer {
        ObserverArg::Linearised => Ok(d),
        ObserverArg::Chain => control::with_chain_observer(d),
    }
}

/// Why a noise-free loop around its own model strays from the design and does not settle, as
/// the error to give: a faster sampling that is checked to work, a longer run that settles, or
/// another bandwidth.
fn diagnose_stray(
    a: &ControlArgs,
    (model, o, d): (&Model, &DesignOptions, &control::Design),
    plant: &control::Plant,
    scenario: &Scenario,
    m: &control::StepMetrics,
) -> Error {
    // Suggest only a sampling period (or a bandwidth) that is checked to work: the design of
    // `o2` run noise-free as the failing one (for `duration`, else its default), settled and
    // following its design; with its settling time.
    let follows = |o2: &DesignOptions, duration: Option<f64>| -> Option<(control::Design, f64)> {
        let d2 = designed(model, o2, a.observer).ok()?;
        let run = Scenario {
            duration: duration.unwrap_or_else(|| control::default_duration(&d2)),
            ..scenario.clone()
        };
        let m2 = control::run(&d2, plant, &run)
            .and_then(|tr| control::metrics(&tr, &d2, a.from))
            .ok()?;
        (!m2.settling_time.is_nan() && m2.design_deviation <= DESIGN_STRAY)
            .then_some((d2, m2.settling_time))
    };
    let works = |t: f64| -> bool {
        let mut o2 = o.clone();
        o2.tau = t;
        follows(&o2, Some(scenario.duration)).is_some()
    };
    let stray = |advice: String| {
        Error::param(
            "tau",
            format!(
                "around its own model the loop sampled every {} s does not settle within {} s ({:.1} % off the designed response): {advice}",
                short(d.tau),
                num4(scenario.duration),
                m.design_deviation,
            ),
        )
    };
    if let Some(t) = (1..=6)
        .map(|h| d.tau / f64::powi(2.0, h))
        .find(|&t| works(t))
    {
        return stray(format!("sample faster (--tau {t:.3e} works)"));
    }
    // Sampling faster does not help. A nonlinear model can follow its linear design loosely
    // and still settle, only later than the run (sized for the design) lasts: that asks
    // for a longer --duration, not another bandwidth. Tried up to 16 times the run.
    let longer = (1..=4)
        .map(|k| scenario.duration * f64::powi(2.0, k))
        .find_map(|dur| {
            let long = Scenario {
                duration: dur,
                ..scenario.clone()
            };
            let m2 = control::run(d, plant, &long)
                .and_then(|tr| control::metrics(&tr, d, a.from))
                .ok()?;
            (!m2.settling_time.is_nan()).then_some((dur, m2.settling_time))
        });
    if let Some((dur, settle)) = longer {
        return Error::param(
            "duration",
            format!(
                "around its own model the loop has not settled within the {} s run ({:.1} % off the linear design's response): it settles in {} s; give --duration {} or more",
                num4(scenario.duration),
                m.design_deviation,
                num4(settle),
                num4(dur)
            ),
        );
    }
    // Nor does a longer run: another bandwidth, one checked to work where one is found (a
    // Coulomb friction makes a slow loop stick and slip: EMPS's default 0.235 rad/s strays,
    // 5 rad/s follows its design within 3 %).
    let tried = [4.0, 16.0, 64.0, 0.25, 1.0 / 16.0]
        .into_iter()
        .find_map(|f| {
            let mut o2 = o.clone();
            o2.bandwidth = Some(d.bandwidth * f);
            follows(&o2, a.duration)
        });
    let advice = match tried {
        Some((d2, settle)) => format!(
            "--bandwidth {} follows its design and settles in {} s",
            num4(d2.bandwidth),
            num4(settle)
        ),
        None => {
            "neither sampling up to 64 times faster nor a bandwidth 1/16 to 64 times this one helps"
                .to_string()
        }
    };
    Error::param(
        "bandwidth",
        format!(
            "around its own model the loop at bandwidth {} rad/s, sampled every {} s, does not settle within {} s ({:.1} % off the designed response): {advice}",
            num4(d.bandwidth),
            short(d.tau),
            num4(scenario.duration),
            m.design_deviation,
        ),
    )
}

/// Largest difference from the designed response, in % of the step, of a loop around its own
/// model that still counts as following its design (working loops measure under 1 %; the
/// sampled sixth-order loops the design cannot hold 11-23 %).
const DESIGN_STRAY: f64 = 5.0;

/// The loop's trace: time, reference (and the designed response of a step), the output and its
/// measurement under the output's name, the estimates, the input under its name.
fn write_trace(
    path: &std::path::Path,
    tr: &control::Trace,
    (names, input): (&[String], &str),
    designed: Option<&[f64]>,
) -> Result<()> {
    let io = |e: std::io::Error| Error::file(path.display().to_string(), e);
    let mut file = ctsid::util::AtomicFile::create(path)?;
    // Through the CSV writer: a state named with a comma or a quote (`a,b`) is quoted, not
    // split into two header fields over one column of values.
    let mut w = csv::Writer::from_writer(&mut file);
    let bad = |e: csv::Error| io(std::io::Error::other(e.to_string()));
    let y = &names[0];
    let mut header: Vec<String> = vec!["t".into(), "reference".into()];
    if designed.is_some() {
        header.push("designed".into());
    }
    header.extend([y.clone(), format!("{y}_measured")]);
    header.extend(names.iter().map(|n| format!("{n}_hat")));
    header.push(input.to_string());
    w.write_record(distinct(header)).map_err(bad)?;
    for i in 0..tr.t.len() {
        let mut row = vec![tr.t[i].to_string(), tr.reference[i].to_string()];
        if let Some(dr) = designed {
            row.push(dr.get(i).map_or(String::new(), |v| format!("{v:e}")));
        }
        row.extend([format!("{:e}", tr.y[i]), format!("{:e}", tr.y_measured[i])]);
        row.extend(tr.estimate.iter().map(|e| format!("{:e}", e[i])));
        row.push(format!("{:e}", tr.u[i]));
        w.write_record(&row).map_err(bad)?;
    }
    w.flush().map_err(io)?;
    drop(w);
    file.commit()
}

/// The header with every repeated name made distinct (`t`, ..., `t_2`): a model whose output or
/// input is named `t`, `reference` or `designed`, or an input named `y_measured` or `y_hat`
/// beside the output `y`, gave a trace with two columns of one name, which CSV readers join or
/// rename silently.
fn distinct(header: Vec<String>) -> Vec<String> {
    let mut out: Vec<String> = Vec::with_capacity(header.len());
    for name in &header {
        let mut candidate = name.clone();
        let mut k = 2;
        // A new name may not take one that comes later in the header either.
        while out.contains(&candidate) || (candidate != *name && header.contains(&candidate)) {
            candidate = format!("{name}_{k}");
            k += 1;
        }
        out.push(candidate);
    }
    out
}

fn write_plots(
    dir: &std::path::Path,
    d: &control::Design,
    tr: &control::Trace,
    from: f64,
) -> Result<()> {
    use ctsid::report::{svg, write_file};
    let step = control::step_plot(
        d,
        tr,
        from,
        &format!("{}: step {from} -> {} under feedback", d.output, d.setpoint),
        &d.output,
        "output",
    )?;
    write_file(dir, "step.svg", &step)?;
    let input = svg::line_plot(
        &format!("{}: input under feedback", d.input),
        "t (s)",
        &d.input,
        &[svg::Series {
            label: "input",
            x: &tr.t,
            y: &tr.u,
            color: "red",
            band: None,
            dashed: false,
        }],
    );
    write_file(dir, "input.svg", &input)
}

/// The tracking run the flags ask for (`None`: the classic setpoint step under the pole
/// placement, with its design checks).
fn tracking_settings(a: &ControlArgs, d: &control::Design) -> Result<Option<control::Tracking>> {
    let law = match a.law {
        LawArg::Placement => {
            if a.sigma.is_some() {
                return Err(Error::param(
                    "sigma",
                    "is a setting of --law profile; the placement law takes --bandwidth",
                ));
            }
            control::Law::PolePlacement
        }
        LawArg::Profile => control::Law::Profile(control::ProfileLaw {
            sigma: a.sigma.unwrap_or(d.bandwidth),
        }),
    };
    let reference = match a.reference.as_deref() {
        None => control::Reference::constant(a.setpoint),
        Some("steps") => {
            control::Reference::steps_and_ramps(a.from, a.setpoint, a.duration.unwrap_or(5.0))?
        }
        Some(path) => control::Reference::read_csv(std::path::Path::new(path))?,
    };
    let tk = control::Tracking {
        reference,
        law,
        block: a.block,
    };
    tk.check()?;
    let classic = a.reference.is_none() && a.law == LawArg::Placement && a.block == 1;
    Ok((!classic).then_some(tk))
}

/// Runs and reports a tracking loop (a reference, the profile law or blocking).
fn run_tracking(
    a: &ControlArgs,
    d: &control::Design,
    plant: &control::Plant,
    scenario: &Scenario,
    tk: &control::Tracking,
    names: &[String],
) -> Result<()> {
    let tr = control::track(d, plant, scenario, tk)?;
    let m = control::tracking_metrics(&tr.t, &tr.y, &tr.u, &tk.reference, scenario.u_limits);
    let law = match tk.law {
        control::Law::PolePlacement => "pole placement".to_string(),
        control::Law::Profile(p) => format!("exponential profile (sigma {} 1/s)", num4(p.sigma)),
    };
    let plant_name = a
        .plant
        .as_ref()
        .map_or("the model itself".to_string(), |p| p.display().to_string());
    let reference = match a.reference.as_deref() {
        None => format!("step {} -> {}", short(a.from), short(a.setpoint)),
        Some("steps") => "the built-in steps and ramps".to_string(),
        Some(p) => p.to_string(),
    };
    outln!(
        "{reference} around {plant_name}, law: {law}, input decided every {} sample(s), {} s, noise sd {}:",
        tk.block,
        num4(scenario.duration),
        short(a.noise)
    )?;
    outln!(
        "{}",
        control::tracking::describe(&m, tr.t.len(), tr.decision_seconds)
    )?;
    // A loop that rings through the reference, or lives at its limits, passed with its figures
    // only (EMPS at the default bandwidth: overshoot 96 % and +-6500 N; 4131 of 5001 samples at
    // a limit): said in words.
    let samples = tr.t.len().max(1);
    // A reference without steps has no overshoot or settling (NaN): nothing to say of them.
    let has_steps = !m.overshoot.is_nan();
    if has_steps && (m.overshoot > 50.0 || m.settling_time.is_nan()) {
        eprintln!(
            "note: the loop does not settle on the reference's steps (overshoot {} %): this design does not suit the reference; try another --bandwidth, --law or --observer",
            num4(m.overshoot)
        );
    }
    if m.saturated * 2 > samples {
        eprintln!(
            "note: the input is at a limit in {} of {samples} samples: the loop is mostly open; a lower --bandwidth or wider limits",
            m.saturated
        );
    }
    if let Some(path) = &a.output {
        write_trace(path, &tr, (names, &d.input), None)?;
        super::written(format!("wrote {}", path.display()));
    }
    if let Some(dir) = &a.report {
        let title = format!("{}: {reference}, {law}", d.output);
        let svg = control::tracking::tracking_plot(&tr, &title, &d.output, &d.input);
        ctsid::report::write_file(dir, "tracking.svg", &svg)?;
        let text = format!(
            "# {title}\n\n{}\n\n![tracking](tracking.svg)\n",
            control::tracking::describe(&m, tr.t.len(), tr.decision_seconds)
        );
        ctsid::report::write_file(dir, "report.md", &text)?;
        super::written(format!("plots written to {}", dir.display()));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::distinct;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_trace_header_never_repeats_a_name() {
        // An output named `t`, an input named `reference`, a state `t_2` further on.
        let h = distinct(names(&[
            "t",
            "reference",
            "t",
            "t_measured",
            "t_2",
            "reference",
        ]));
        assert_eq!(
            h,
            names(&["t", "reference", "t_3", "t_measured", "t_2", "reference_2"])
        );
        let plain = names(&[
            "t",
            "reference",
            "designed",
            "y",
            "y_measured",
            "y_hat",
            "u",
        ]);
        assert_eq!(distinct(plain.clone()), plain);
    }
}
