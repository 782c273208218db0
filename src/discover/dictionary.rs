//! The dictionary of named effects: each candidate is a family identifier (the JSON output uses
//! them), a readable formula and its parsed [`Expr`].
//!
//! Scales inside formulas (the `eps` of `tanh(v/eps)`, a dead-zone width, a preload position) come
//! from the training data so that the dictionary means the same thing in any units; they are
//! written into the formula as numbers, so the formula is exactly what is evaluated.
//! `v` is the highest derivative of the output below the model's order (`y_d1` for a second-order
//! mechanical model, `y` itself for a first-order one).

use crate::error::{Error, Result};
use crate::model::Expr;

/// One named candidate.
#[derive(Debug, Clone)]
pub struct Effect {
    pub family: String,
    pub formula: String,
    pub expr: Expr,
}

/// Scales measured on the training runs, per variable of `z` (state names then inputs).
#[derive(Debug, Clone)]
pub struct Scales {
    /// Standard deviation of each variable.
    pub sd: Vec<f64>,
    /// Median of each variable.
    pub median: Vec<f64>,
    /// 99th percentile of |x| for each variable.
    pub p99: Vec<f64>,
}

/// Four significant digits, no trailing zeros.
pub fn num(x: f64) -> String {
    if x == 0.0 {
        return "0".into();
    }
    let mag = x.abs().log10().floor() as i32;
    if !(-3..=5).contains(&mag) {
        return format!("{x:.3e}");
    }
    let dec = (3 - mag).max(0) as usize;
    let s = format!("{x:.dec$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// User effects need a name each, and a name once (checked before any data are read by the CLI,
/// and again by [`build`]). Refuses an empty name and a name given twice.
pub fn check_user_names(user: &[(String, String)]) -> Result<()> {
    let names: Vec<&str> = user.iter().map(|(n, _)| n.trim()).collect();
    if let Some(i) = names.iter().position(|n| n.is_empty()) {
        return Err(Error::param(
            "effect",
            format!("'={}' has no name; write NAME=EXPRESSION", user[i].1),
        ));
    }
    if let Some((_, j)) = crate::util::first_repeat(&names) {
        return Err(Error::param(
            "effect",
            format!("'{}' is given twice", names[j]),
        ));
    }
    Ok(())
}

/// The named families (friction, drag, stiffness, trigonometric, outflow, input nonlinearities)
/// for an output of order `order` over `vars`, as (family, formula), scales from `scales`.
fn named_effects(vars: &[String], order: usize, scales: &Scales) -> Vec<(String, String)> {
    let y = &vars[0];
    let vi = order - 1;
    let v = &vars[vi];
    let inputs: Vec<usize> = (order..vars.len()).collect();
    let mut list: Vec<(String, String)> = Vec::new();
    let mut add = |f: &str, e: String| list.push((f.to_string(), e));
    // Coulomb friction on a velocity w of spread sd: a step, and a tanh at 5 % of the spread.
    let coulomb = |w: &str, sd: f64| {
        [
            format!("sign({w})"),
            format!("tanh({w}/{})", num(sd * 0.05)),
        ]
    };
    for f in coulomb(v, scales.sd[vi]) {
        add("coulomb_friction", f);
    }
    add(
        "stribeck",
        format!("sign({v})*exp(-({v}/{})^2)", num(scales.sd[vi] * 0.3)),
    );
    if order >= 3 {
        // A mechanism behind an actuator pole (a motor's current, a drive's filter): its
        // friction acts on the velocity y_d1, which the pole's balance carries into the
        // order-3 equation (y_d3 = ... + a f(y, y_d1) for y_d2 = f + K x, x_d1 = -a x + b u).
        for f in coulomb(&vars[1], scales.sd[1]) {
            add("coulomb_friction", f);
        }
    }
    add("quadratic_drag", format!("abs({v})*{v}"));
    add("cubic_damping", format!("{v}^3"));
    add("cubic_stiffness", format!("{y}^3"));
    add("asymmetric_stiffness", format!("abs({y})*{y}"));
    add("asymmetric_stiffness", format!("{y}^2"));
    let y0 = scales.median[0];
    add(
        "preload",
        if y0.abs() < 1e-12 {
            format!("sign({y})")
        } else {
            format!("sign({y} - {})", num(y0))
        },
    );
    add("trigonometric", format!("sin({y})"));
    add("trigonometric", format!("cos({y})"));
    add("trigonometric", format!("cos({y})^2"));
    add("offset", "1".into());
    add("sqrt_outflow", format!("sqrt(abs({y}))*sign({y})"));
    if order >= 2 {
        // Torricelli outflow seen one derivative up (a tank's level y in a second-order
        // model): d/dt sqrt(y) = y' / (2 sqrt(y)); the floor keeps an empty tank finite.
        let floor = num(0.01 * scales.sd[0]);
        add(
            "sqrt_outflow",
            format!("{}/sqrt(abs({y}) + {floor})", vars[1]),
        );
    }
    for &c in &inputs {
        let u = &vars[c];
        let s = num(0.7 * scales.p99[c]);
        add("input_saturation", format!("{s}*sat({u}/{s}) - {u}"));
        let d = num(0.1 * scales.p99[c]);
        add("input_dead_zone", format!("{d}*sat({u}/{d})"));
        add("input_relay", format!("sign({u})"));
    }
    list
}

/// The monomials of degree 1 to 3 over `vars` that are not among `nominal_monomials`, as
/// ("polynomial", formula).
fn polynomial_effects(
    vars: &[String],
    nominal_monomials: &[Vec<(usize, u32)>],
) -> Vec<(String, String)> {
    let mut list: Vec<(String, String)> = Vec::new();
    let mut add = |f: &str, e: String| list.push((f.to_string(), e));
    let nv = vars.len();
    let mut monos: Vec<Vec<u32>> = Vec::new();
    for deg in 1..=3u32 {
        let mut e = vec![0u32; nv];
        fn rec(k: usize, left: u32, e: &mut Vec<u32>, out: &mut Vec<Vec<u32>>) {
            if k + 1 == e.len() {
                e[k] = left;
                out.push(e.clone());
                return;
            }
            for a in (0..=left).rev() {
                e[k] = a;
                rec(k + 1, left - a, e, out);
            }
            e[k] = 0;
        }
        rec(0, deg, &mut e, &mut monos);
    }
    for m in monos {
        let ex: Vec<(usize, u32)> = m
            .iter()
            .enumerate()
            .filter(|(_, &e)| e > 0)
            .map(|(i, &e)| (i, e))
            .collect();
        if nominal_monomials.contains(&ex) {
            continue;
        }
        let txt = ex
            .iter()
            .map(|&(i, e)| {
                if e == 1 {
                    vars[i].clone()
                } else {
                    format!("{}^{e}", vars[i])
                }
            })
            .collect::<Vec<_>>()
            .join("*");
        add("polynomial", txt);
    }
    list
}

/// Builds the dictionary for an output of order `order` over `vars` (the `order` state names
/// first, then the inputs), leaving out monomials already in the nominal model
/// (`nominal_monomials`, as exponent lists over `vars`). Refuses user effects that
/// [`check_user_names`] refuses, one named like a built-in family, one whose expression does not
/// parse over `vars`, and one already in the dictionary (or a term of the nominal model), also
/// as a constant multiple of a monomial there. Panics
/// when `order` is 0 or above `vars.len()`, or when `scales.sd` has fewer than `order` entries,
/// `scales.median` none, or `scales.p99` fewer than `vars.len()` (with inputs in `vars`).
pub fn build(
    vars: &[String],
    order: usize,
    scales: &Scales,
    nominal_monomials: &[Vec<(usize, u32)>],
    user: &[(String, String)],
) -> Result<Vec<Effect>> {
    let mut list = named_effects(vars, order, scales);
    list.extend(polynomial_effects(vars, nominal_monomials));
    let built_in = list.len();
    check_user_names(user)?;
    for (name, e) in user {
        let name = name.trim();
        if list[..built_in].iter().any(|(f, _)| f == name) {
            return Err(Error::param(
                "effect",
                format!("'{name}' is the name of a built-in effect; choose another"),
            ));
        }
        list.push((name.to_string(), e.clone()));
    }
    let mut out: Vec<Effect> = Vec::new();
    for (k, (family, formula)) in list.into_iter().enumerate() {
        let expr = Expr::parse(&formula, vars)?;
        // Drop exact duplicates (a polynomial that a named family already covers keeps the name)
        // and nominal monomials written as a family formula; a user's effect is named instead,
        // also as a constant multiple (`2*y^3` was kept and then vanished from the output).
        let mono = if k >= built_in {
            expr.monomial_up_to_scale()
        } else {
            expr.monomial()
        };
        let twin = match mono {
            Some(m) if nominal_monomials.contains(&m) => Some("a term of the nominal model".into()),
            Some(m) => out
                .iter()
                .find(|o: &&Effect| o.expr.monomial().as_ref() == Some(&m))
                .map(|o| format!("{} {}", o.family, o.formula)),
            None => None,
        }
        .or_else(|| {
            out.iter()
                .find(|o| o.formula == formula)
                .map(|o| format!("{} {}", o.family, o.formula))
        });
        if let Some(twin) = twin {
            if k >= built_in {
                return Err(Error::param(
                    "effect",
                    format!("'{family}' ({formula}) is already in the dictionary as {twin}; leave it out"),
                ));
            }
            continue;
        }
        out.push(Effect {
            family,
            formula,
            expr,
        });
    }
    Ok(out)
}
