//! `ctsid demo etc|mimo`: the built-in demonstrations.

use clap::{Args, Subcommand};
use ctsid::demo::{etc, mimo};
use ctsid::regression::EngineChoice;
use ctsid::Result;
use std::path::PathBuf;

#[derive(Args, Debug)]
pub struct DemoArgs {
    #[command(subcommand)]
    pub which: Which,
}

#[derive(Subcommand, Debug)]
pub enum Which {
    /// The source paper's electronic-throttle experiment, judged against the truth.
    Etc(EtcArgs),
    /// A MIMO plant of the paper's size (dim z = 11) at d = 2, 4, 6.
    Mimo(MimoArgs),
}

#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq)]
pub enum Preset {
    Paper,
    Physical,
}

#[derive(Args, Debug)]
pub struct EtcArgs {
    /// Atmospheric pressure in the aerodynamic term, Pa (0: the linear throttle of the paper's results).
    #[arg(long, default_value_t = 0.0)]
    pub patm: f64,
    /// `physical`: excitation scaled so the angle stays within [0, pi/2], Patm = 101325 Pa.
    #[arg(long, value_enum, default_value_t = Preset::Paper)]
    pub preset: Preset,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Noise level eta (the paper's definition), e.g. 0.03.
    #[arg(long, default_value_t = 0.03)]
    pub noise: f64,
    #[arg(long, default_value_t = 3)]
    pub degree: usize,
    #[arg(long, default_value = "auto")]
    pub engine: EngineChoice,
    /// Write the tables (Markdown, CSV) and plots (SVG) here.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress lines (they are shown only when standard error is a terminal anyway).
    #[arg(long)]
    pub quiet: bool,
}

#[derive(Args, Debug)]
pub struct MimoArgs {
    #[arg(long, value_delimiter = ',', default_values_t = vec![2usize, 4, 6])]
    pub degrees: Vec<usize>,
    /// Candidate orders of every output, chosen by the order search; one value fixes them.
    #[arg(long, value_delimiter = ',', default_values_t = vec![1usize, 2, 3, 4])]
    pub orders: Vec<usize>,
    /// Engines to time, e.g. `cpu,gpu`.
    #[arg(long, value_delimiter = ',', default_value = "cpu")]
    pub engines: Vec<EngineChoice>,
    #[arg(long, default_value_t = 0.0)]
    pub noise: f64,
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Structure search, as `identify --method`.
    #[arg(long, value_enum, default_value_t = super::regress::MethodArg::ForwardOls)]
    pub method: super::regress::MethodArg,
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// No progress lines (they are shown only when standard error is a terminal anyway).
    #[arg(long)]
    pub quiet: bool,
}

pub fn run(a: DemoArgs) -> Result<()> {
    match a.which {
        Which::Etc(e) => {
            if let Some(d) = &e.out {
                super::check_output_dir(d)?;
            }
            let o = etc::EtcOptions {
                patm: e.patm,
                physical: e.preset == Preset::Physical,
                seed: e.seed,
                noise: e.noise,
                degree: e.degree,
                engine: e.engine,
                out: e.out,
                progress: super::show_progress(e.quiet),
                ..Default::default()
            };
            out!("{}", etc::run(&o)?)?;
        }
        Which::Mimo(m) => {
            if let Some(d) = &m.out {
                super::check_output_dir(d)?;
            }
            let o = mimo::MimoOptions {
                degrees: m.degrees,
                orders: m.orders,
                engines: m.engines,
                noise: m.noise,
                seed: m.seed,
                method: Some(m.method.into()),
                out: m.out,
                progress: super::show_progress(m.quiet),
                ..Default::default()
            };
            out!("{}", mimo::run(&o)?)?;
        }
    }
    Ok(())
}
