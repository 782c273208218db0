//! Which engine runs a regression: `--engine cpu|gpu|auto`, decided before anything is built.
//!
//! The decision is a value ([`Decision`]: an engine kind and the one-line reason the CLI prints),
//! computed by a pure function from the request, the problem size and the adapters present, so
//! it is testable without a GPU and does not depend on how the engines are constructed.
//!
//! Rules:
//! * `cpu`: always the CPU engine.
//! * `gpu`: the best Vulkan adapter, a CPU (software) one such as lavapipe included; no adapter
//!   is an error ([`Error::NoGpu`]), never a silent fall-back.
//! * `auto`: a real GPU (never a `DeviceType::Cpu` adapter: lavapipe is many times slower than
//!   the CPU engine) when the problem is large enough to pay for the fixed costs of the GPU
//!   (device start, shader compilation, upload, and ~0.1 ms of submit/read-back per sweep);
//!   otherwise the CPU engine, with the reason.

use std::fmt;
use std::str::FromStr;

use crate::error::{Error, Result};

/// The kind of a Vulkan adapter, as the selection sees it (wgpu's device types).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DeviceType {
    DiscreteGpu,
    IntegratedGpu,
    VirtualGpu,
    Other,
    /// A software driver such as lavapipe.
    Cpu,
}

/// One Vulkan adapter as seen by the selection logic.
#[derive(Debug, Clone)]
pub struct AdapterSummary {
    pub name: String,
    pub device_type: DeviceType,
    pub driver: String,
}

/// What the user asked for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum EngineChoice {
    #[default]
    Auto,
    Cpu,
    Gpu,
}

impl FromStr for EngineChoice {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s.to_ascii_lowercase().as_str() {
            "auto" => Ok(EngineChoice::Auto),
            "cpu" => Ok(EngineChoice::Cpu),
            "gpu" => Ok(EngineChoice::Gpu),
            other => Err(Error::param(
                "engine",
                format!("'{other}'; expected cpu, gpu or auto"),
            )),
        }
    }
}

impl fmt::Display for EngineChoice {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            EngineChoice::Auto => "auto",
            EngineChoice::Cpu => "cpu",
            EngineChoice::Gpu => "gpu",
        })
    }
}

/// The engine that will run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EngineKind {
    Cpu,
    Gpu,
}

/// An engine and why it was chosen (one line, printed by the CLI).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Decision {
    pub kind: EngineKind,
    pub reason: String,
}

/// Sample-candidate pairs per sweep below which `auto` keeps the CPU engine. At 5e7 pairs a CPU
/// sweep takes ~10-20 ms on two cores, while the GPU's fixed costs (start-up, compilation and
/// upload of ~0.1-0.5 s spread over a path of ~200 sweeps, plus per-sweep round trips) are of
/// the same order: below it the GPU cannot win by much, above it the GPU wins by orders of
/// magnitude.
pub const AUTO_MIN_PAIRS: u64 = 50_000_000;

/// Decides which engine runs a problem of `n_samples x n_candidates`, given the adapters present
/// (best first, as [`probe`] returns them). Pure. Errs ([`Error::NoGpu`]) only where `gpu` is asked
/// for and `adapters` is empty.
///
/// ```
/// use ctsid::engine::select::{decide, probe, EngineChoice, EngineKind};
/// // With no adapter, auto keeps the CPU engine and a GPU asked for is a clear error.
/// let auto = decide(EngineChoice::Auto, 25_000, 12_376, &[])?;
/// assert_eq!(auto.kind, EngineKind::Cpu);
/// assert!(decide(EngineChoice::Gpu, 25_000, 12_376, &[]).is_err());
/// // On this machine: whatever `probe` finds.
/// println!("{}", decide(EngineChoice::Auto, 25_000, 12_376, &probe())?.reason);
/// # Ok::<(), ctsid::Error>(())
/// ```
pub fn decide(
    choice: EngineChoice,
    n_samples: usize,
    n_candidates: usize,
    adapters: &[AdapterSummary],
) -> Result<Decision> {
    let pairs = n_samples as u64 * n_candidates as u64;
    let real = adapters.iter().find(|a| a.device_type != DeviceType::Cpu);
    match choice {
        EngineChoice::Cpu => Ok(Decision { kind: EngineKind::Cpu, reason: "cpu engine: requested with --engine cpu".into() }),
        EngineChoice::Gpu => match real.or(adapters.first()) {
            Some(a) => Ok(Decision {
                kind: EngineKind::Gpu,
                reason: format!("gpu engine on {} ({:?}): requested with --engine gpu", a.name, a.device_type),
            }),
            None if cfg!(not(feature = "gpu")) => Err(Error::NoGpu("--engine gpu was requested but this build has no GPU engine (built without the 'gpu' feature); use --engine cpu or auto".into())),
            None => Err(Error::NoGpu("--engine gpu was requested but no Vulkan adapter was found; use --engine cpu or auto".into())),
        },
        EngineChoice::Auto => {
            let Some(a) = real else {
                let why = match adapters.first() {
                    Some(c) => format!("only a software Vulkan adapter ({}) was found, slower than the CPU engine", c.name),
                    None => "no GPU adapter was found".to_string(),
                };
                return Ok(Decision { kind: EngineKind::Cpu, reason: format!("cpu engine: {why}") });
            };
            if pairs < AUTO_MIN_PAIRS {
                Ok(Decision {
                    kind: EngineKind::Cpu,
                    reason: format!(
                        "cpu engine: {n_samples} samples x {n_candidates} candidates ({pairs} pairs per sweep) is below the {AUTO_MIN_PAIRS} pairs that pay for the GPU ({})",
                        a.name
                    ),
                })
            } else {
                Ok(Decision {
                    kind: EngineKind::Gpu,
                    reason: format!("gpu engine on {} ({:?}): {pairs} pairs per sweep", a.name, a.device_type),
                })
            }
        }
    }
}

/// The adapters of this machine, best first (none in a build without the `gpu` feature).
pub fn probe() -> Vec<AdapterSummary> {
    #[cfg(feature = "gpu")]
    {
        crate::engine::gpu::probe_adapters()
    }
    #[cfg(not(feature = "gpu"))]
    {
        Vec::new()
    }
}

/// [`decide`] with the adapters of this machine. Errs ([`Error::NoGpu`]) only where `gpu` is asked
/// for and this machine has no adapter (or the build no `gpu` feature).
pub fn choose(choice: EngineChoice, n_samples: usize, n_candidates: usize) -> Result<Decision> {
    let adapters = if choice == EngineChoice::Cpu {
        Vec::new()
    } else {
        probe()
    };
    decide(choice, n_samples, n_candidates, &adapters)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ad(name: &str, t: DeviceType) -> AdapterSummary {
        AdapterSummary {
            name: name.into(),
            device_type: t,
            driver: String::new(),
        }
    }

    #[test]
    fn parses_choices() {
        assert_eq!("AUTO".parse::<EngineChoice>().unwrap(), EngineChoice::Auto);
        assert_eq!("gpu".parse::<EngineChoice>().unwrap(), EngineChoice::Gpu);
        assert!("cuda"
            .parse::<EngineChoice>()
            .unwrap_err()
            .to_string()
            .contains("cpu, gpu or auto"));
    }

    #[test]
    fn auto_never_picks_a_software_adapter() {
        let lvp = [ad("llvmpipe", DeviceType::Cpu)];
        let d = decide(EngineChoice::Auto, 25_000, 497_420, &lvp).unwrap();
        assert_eq!(d.kind, EngineKind::Cpu);
        assert!(
            d.reason.contains("software") && d.reason.contains("llvmpipe"),
            "{}",
            d.reason
        );
        let d = decide(EngineChoice::Auto, 25_000, 497_420, &[]).unwrap();
        assert_eq!(d.kind, EngineKind::Cpu);
        assert!(d.reason.contains("no GPU adapter"), "{}", d.reason);
    }

    #[test]
    fn auto_uses_a_real_gpu_only_for_large_problems() {
        let h100 = [
            ad("NVIDIA H100", DeviceType::DiscreteGpu),
            ad("llvmpipe", DeviceType::Cpu),
        ];
        let big = decide(EngineChoice::Auto, 25_000, 12_376, &h100).unwrap();
        assert_eq!(big.kind, EngineKind::Gpu);
        assert!(big.reason.contains("H100"));
        let small = decide(EngineChoice::Auto, 1_000, 78, &h100).unwrap();
        assert_eq!(small.kind, EngineKind::Cpu);
        assert!(small.reason.contains("below"), "{}", small.reason);
    }

    #[test]
    fn gpu_takes_any_adapter_or_fails_clearly() {
        let lvp = [ad("llvmpipe", DeviceType::Cpu)];
        assert_eq!(
            decide(EngineChoice::Gpu, 10, 10, &lvp).unwrap().kind,
            EngineKind::Gpu
        );
        let e = decide(EngineChoice::Gpu, 10, 10, &[]).unwrap_err();
        assert!(matches!(e, Error::NoGpu(_)));
        assert!(e.to_string().contains("--engine cpu"));
        assert_eq!(
            decide(EngineChoice::Cpu, 1 << 20, 1 << 20, &lvp)
                .unwrap()
                .kind,
            EngineKind::Cpu
        );
    }
}
