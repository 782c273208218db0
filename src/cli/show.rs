//! `ctsid show MODEL`: a model file as equations, then each term with its coefficient, standard
//! error, interval and origin, as far as the file has them.

use clap::Args;
use ctsid::model::{derivative_name, Model, Origin};
use ctsid::regression::format_coefficient;
use ctsid::Result;

#[derive(Args, Debug)]
pub struct ShowArgs {
    /// Model file (ctsid-model/2 JSON, or /1)
    pub model: String,
}

pub fn run(a: ShowArgs) -> Result<()> {
    let model = Model::read(&a.model)?;
    outln!("{model}")?;
    let tau = model
        .tau
        .map_or("not recorded".into(), |t| format!("{t} s"));
    outln!(
        "\ninputs: {} (read between samples: {}); identified at tau = {tau}",
        model.inputs.join(", "),
        model.input_interpolation.name()
    )?;
    if !model.sign_smoothing.is_empty() {
        // The widths change every simulation of sign(.) and its kin: shown, not only stored.
        let widths: Vec<String> = model
            .sign_smoothing
            .iter()
            .map(|(v, w)| format!("{v} {}", ctsid::util::short(*w)))
            .collect();
        outln!("sign smoothing widths: {}", widths.join(", "))?;
    }
    for o in &model.outputs {
        // A limit changes every simulation as much as a term does.
        if let Some(l) = o.limits.text() {
            outln!(
                "limits: {} {l} (held there while pushed beyond: an overflow, an end stop)",
                o.name
            )?;
        }
    }
    let mut unknown = false;
    let (mut no_interval, mut weak) = (false, 0usize);
    for o in &model.outputs {
        outln!(
            "\n{} (order {}):",
            derivative_name(&o.name, o.order),
            o.order
        )?;
        outln!("| term | coefficient | std. error | rel. | 95 % interval | origin |")?;
        outln!("|---|---|---|---|---|---|")?;
        for t in &o.terms {
            let name = if t.is_monomial() && t.exponents.is_empty() {
                "1".to_string()
            } else {
                t.monomial()
            };
            let (se, rel) = match t.std_error {
                Some(s) => (format_coefficient(s), relative_error(s, t.coefficient)),
                None => {
                    unknown = true;
                    ("-".into(), "-".into())
                }
            };
            no_interval |= t.interval.is_none();
            weak += usize::from(
                t.std_error
                    .is_some_and(|s| s.abs() > 0.5 * t.coefficient.abs()),
            );
            let interval = t.interval.map_or("-".into(), |[lo, hi]| {
                format!("[{}, {}]", format_coefficient(lo), format_coefficient(hi))
            });
            let origin = match &t.origin {
                Some(Origin::Identified) => "identified".to_string(),
                Some(Origin::Nominal) => "nominal".to_string(),
                Some(Origin::Effect(f)) => format!("effect: {f}"),
                None => "-".to_string(),
            };
            outln!(
                "| {name} | {} | {se} | {rel} | {interval} | {origin} |",
                format_coefficient(t.coefficient)
            )?;
        }
    }
    if unknown {
        outln!("\n'-': no standard error was estimated for that term (identify writes one for every term it fits; discover for the effects it adds; a hand-written or older file may have none).")?;
    }
    // The empty interval column and standard errors larger than the coefficients were shown
    // without a word (an engineer could not tell an unestimated interval from a missing one).
    if no_interval {
        outln!("\n95 % interval '-': intervals are discover's bootstrap over runs, for the effects it adds, where the coefficient is the weak-form estimate they belong to (a coefficient refined on simulation error has its std. error; the bootstrap interval of its weak-form estimate is in the file's discovery section); for the other terms coefficient +- 2 std. errors is the spread the measurement noise alone would give (an error of the model's structure or of its input interpolation adds a bias it does not cover).")?;
    }
    if weak > 0 {
        outln!("\n{weak} term(s) with a standard error above half the coefficient (rel. > 50 %): the data determine them poorly; a model with fewer terms (a lower degree) may simulate as well.")?;
    }
    Ok(())
}

/// A standard error relative to its coefficient in percent (one decimal; scientific notation from
/// 1e6 %, not hundreds of digits); `-` where the ratio means nothing (a zero coefficient) or is
/// not finite.
fn relative_error(se: f64, coefficient: f64) -> String {
    let r = 100.0 * se / coefficient.abs();
    if coefficient == 0.0 || !r.is_finite() {
        "-".into()
    } else if r < 1e6 {
        format!("{r:.1} %")
    } else {
        format!("{} %", ctsid::util::num4(r))
    }
}

#[cfg(test)]
mod tests {
    use super::relative_error;

    #[test]
    fn relative_errors_are_short_and_finite() {
        assert_eq!(relative_error(0.5, 0.0), "-");
        assert_eq!(relative_error(1e300, -2.0), "5.0000e301 %");
        assert_eq!(relative_error(0.1, 2.0), "5.0 %");
        assert_eq!(relative_error(f64::INFINITY, 2.0), "-");
    }
}
