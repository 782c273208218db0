//! `ctsid benchmark NAME [--data DIR] [--out DIR]`: the one workflow of [`ctsid::benchmark`]
//! (a linear nominal by identify, discover in rounds with a second look on simulation error at
//! what its gates refuse, then the undetermined terms dropped) on a
//! public benchmark record, scored by the benchmark's protocol beside the published rows.
//! `--out` writes `NAME.model.json`,
//! `NAME.csv` (benchmark, metric, ours, linear, pnarx, best), the test run as `NAME_test.csv`
//! (so that `ctsid simulate` checks the printed RMS) and `NAME_test.svg`.

use clap::Args;
use ctsid::benchmark::{self, Benchmark, Outcome};
use ctsid::util::num4;
use ctsid::{Error, Result};
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct BenchmarkArgs {
    /// silverbox, emps, tanks or unbalanced-disk.
    pub name: String,
    /// The folder holding the records (`silverbox/`, `emps/`, `cascaded_tanks/`,
    /// `unbalanced_disk/`).
    #[arg(long, default_value = "../shared/data")]
    pub data: PathBuf,
    /// Write the final model, the scores and the test plot into this folder.
    #[arg(long)]
    pub out: Option<PathBuf>,
}

pub fn run(a: BenchmarkArgs) -> Result<()> {
    if let Some(d) = &a.out {
        super::check_output_dir(d)?;
    }
    let b = benchmark::load(&a.name, &a.data.to_string_lossy())?;
    if let Some(d) = &a.out {
        check_output_files(d, b.name)?;
    }
    outln!("# {} ({})\n", b.title, b.name)?;
    outln!("protocol: {}.\n", b.protocol)?;
    let o = benchmark::run(&b)?;
    outln!(
        "nominal (identify, degree 1, {:.1} s): {}",
        o.identify_seconds,
        o.nominal.outputs[0].to_text()
    )?;
    for (k, r) in o.rounds.iter().enumerate() {
        outln!(
            "discover round {}: {}{}{}; validation NRMSE {:.4} -> {:.4} ({:.1} s)",
            k + 1,
            r.verdict,
            if r.verdict == "added" && !r.kept {
                ", not kept: the validation error did not fall"
            } else {
                ""
            },
            if r.effects.is_empty() {
                String::new()
            } else {
                format!(" ({})", r.effects.join(", "))
            },
            r.validation_before,
            r.validation_after,
            r.seconds
        )?;
        if let Some(why) = &r.closest {
            outln!("  {why}")?;
        }
        for t in &r.tried {
            outln!(
                "  second look on simulation error: {}: validation NRMSE {:.4} -> {:.4}, {:.1} standard errors from zero: {}",
                t.effect,
                t.validation_before,
                t.validation_after,
                t.t_ratio,
                if t.kept { "added" } else { "refused" }
            )?;
        }
    }
    for r in &o.removals {
        outln!(
            "simplify: term {} of {} ({:.2} standard errors from zero): {} (validation NRMSE from fitted initial states {:.4}, without it {:.4})",
            r.term,
            r.equation,
            r.t_ratio,
            if r.dropped { "dropped" } else { "kept" },
            r.gate_before,
            r.gate_after
        )?;
    }
    let dropped = o.removals.iter().filter(|r| r.dropped).count();
    if o.removals.is_empty() {
        outln!(
            "simplify: every term is at least 1.96 standard errors from zero ({:.1} s)",
            o.prune_seconds
        )?;
    } else {
        outln!("simplify: {dropped} dropped ({:.1} s)", o.prune_seconds)?;
    }
    let eq = &o.model.outputs[0];
    let limits = eq
        .limits
        .text()
        .map_or(String::new(), |l| format!(", {} held {l}", eq.name));
    outln!("final model: {}{limits}\n", eq.to_text())?;
    outln!("{}", table(&b, &o))?;
    outln!("time {:.1} s", o.seconds)?;
    if let Some(dir) = &a.out {
        write_outputs(dir, &b, &o)?;
        let d = dir.display();
        outln!(
            "wrote {d}/{n}.model.json, {n}.csv, {n}_test.csv, {n}_test.svg; the first row again: ctsid simulate {d}/{n}.model.json {d}/{n}_test.csv --time-column t_s --init-window {i} --score-from {i}",
            n = b.name,
            i = b.init
        )?;
    }
    Ok(())
}

/// The scores beside the published rows, markdown.
fn table(b: &Benchmark, o: &Outcome) -> String {
    let mut s = format!(
        "| metric ({}) | ours | our linear nominal | linear | polynomial NARX | best published |\n|---|---|---|---|---|---|\n",
        b.unit
    );
    for sc in &o.scores {
        let p = &sc.metric.published;
        s += &format!(
            "| {} | {} | {} | {} | {} | {} ({}) |\n",
            sc.metric.name,
            num4(sc.ours),
            num4(sc.nominal),
            p.linear,
            published(p.pnarx, "-"),
            p.best,
            p.best_by
        );
    }
    s
}

/// A published figure, or `none` where the benchmark has none.
fn published(x: Option<f64>, none: &str) -> String {
    x.map_or_else(|| none.to_string(), |x| x.to_string())
}

/// The files `--out` gets, checked before the work (a pipe, a folder or a link to a record in
/// their place failed only after the whole run: 15 s for EMPS, a minute for the disk).
fn check_output_files(dir: &std::path::Path, name: &str) -> Result<()> {
    if !dir.is_dir() {
        return Ok(());
    }
    for file in output_names(name) {
        let path = dir.join(file);
        let target = ctsid::util::output_target(&path)?;
        if ctsid::util::Outputs::was_read(&target) {
            return Err(Error::Io {
                path: path.display().to_string(),
                message: "is a record this benchmark reads; writing it would destroy it, so write elsewhere".into(),
            });
        }
    }
    Ok(())
}

/// The files `--out` gets: the model, the scores, the test run and its plot.
fn output_names(name: &str) -> [String; 4] {
    [
        format!("{name}.model.json"),
        format!("{name}.csv"),
        format!("{name}_test.csv"),
        format!("{name}_test.svg"),
    ]
}

fn write_outputs(dir: &std::path::Path, b: &Benchmark, o: &Outcome) -> Result<()> {
    use ctsid::report::{svg, write_file};
    ctsid::util::Outputs::create_folder(dir)
        .map_err(|e| Error::file(dir.display().to_string(), e))?;
    let [model_name, scores_name, test_name, plot_name] = output_names(b.name);
    let model_path = dir.join(model_name);
    // Written through the path itself: a folder whose name is not UTF-8 went through a lossy
    // string and the model landed elsewhere.
    o.model.write(&model_path)?;
    let mut csv = String::from("benchmark,metric,ours,linear,pnarx,best\n");
    for sc in &o.scores {
        let p = &sc.metric.published;
        csv += &format!(
            "{},{} ({}),{},{},{},{}\n",
            b.name,
            sc.metric.name,
            b.unit,
            sc.ours,
            p.linear,
            published(p.pnarx, ""),
            p.best
        );
    }
    write_file(dir, &scores_name, &csv)?;
    // The test run as its own record, so that `ctsid simulate` can check the printed RMS.
    let mut test = format!("t_s,{},{}\n", b.output, b.input);
    let run = &b.records.runs[b.split.test[0]];
    let (yi, ui) = (
        b.records.channel_index(&b.output)?,
        b.records.channel_index(&b.input)?,
    );
    for k in 0..run.len() {
        test += &format!(
            "{},{:e},{:e}\n",
            k as f64 * b.records.tau,
            run.channels[yi][k],
            run.channels[ui][k]
        );
    }
    write_file(dir, &test_name, &test)?;
    let series = |label, y, color| svg::Series {
        label,
        x: &o.test_t,
        y,
        color,
        band: None,
        dashed: false,
    };
    let error: Vec<f64> = o
        .test_simulated
        .iter()
        .zip(&o.test_measured)
        .map(|(s, m)| s - m)
        .collect();
    let panels = [
        svg::Panel::lines(
            "test run: free run from the input",
            "t (s)",
            &b.output,
            vec![
                series("measured", &o.test_measured, "black"),
                series("simulated", &o.test_simulated, "#d62728"),
            ],
        ),
        svg::Panel::lines(
            "simulated minus measured",
            "t (s)",
            &b.output,
            vec![series("error", &error, "#1f77b4")],
        )
        .height(200.0),
    ];
    let title = format!("{}: test run, final model", b.title);
    write_file(dir, &plot_name, &svg::figure(&title, &panels))
}
