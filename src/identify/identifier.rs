//! The one-line entry point to identification: a builder over [`Settings`], checked once when
//! it fits. See the crate documentation for a complete example.

use super::{identify, Identification, Orders, Settings, Split};
use crate::engine::select::EngineChoice;
use crate::error::Result;
use crate::records::RecordSet;

/// Identifies `y_i^(n_i) = P_i(y, ..., u)` from measured runs.
///
/// Name the outputs and inputs (the record set's channel names), the largest monomial degree,
/// and optionally a fixed order, named terms and the engine; [`Identifier::fit`] checks the
/// settings and runs the whole pipeline (derivatives, sparse regression per candidate order,
/// order choice on free-run simulation of the held-out runs, refinement, test simulation).
///
/// ```no_run
/// use ctsid::{Identifier, RecordSet, Split};
/// let records = RecordSet::read_csv("emps.csv", &["q_m", "force_N"], Some("run"), 1e-3)?;
/// let split = Split::from_lists(&records, "0-3", Some("4-5"), "6")?;
/// let fit = Identifier::new()
///     .outputs(["q_m"])
///     .inputs(["force_N"])
///     .degree(1)
///     .order(2)
///     .term("sign(q_m_d1)")
///     .fit(&records, &split)?;
/// println!("{}", fit.model);
/// # Ok::<(), ctsid::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct Identifier {
    settings: Settings,
    order: Option<usize>,
}

impl Default for Identifier {
    fn default() -> Self {
        Identifier::new()
    }
}

impl Identifier {
    /// No outputs or inputs yet, degree 3, orders 1 to 4 searched, the default engine.
    pub fn new() -> Identifier {
        Identifier {
            settings: Settings::new(Vec::new(), Vec::new(), 3),
            order: None,
        }
    }

    /// The output channels, by name.
    pub fn outputs<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.settings.outputs = names.into_iter().map(Into::into).collect();
        self
    }

    /// The input channels, by name (none for an autonomous system).
    pub fn inputs<S: Into<String>>(mut self, names: impl IntoIterator<Item = S>) -> Self {
        self.settings.inputs = names.into_iter().map(Into::into).collect();
        self
    }

    /// The largest monomial degree of the candidate terms (1..=12). Checked by [`Identifier::fit`].
    pub fn degree(mut self, d: usize) -> Self {
        self.settings.degree = d;
        self
    }

    /// One fixed order for every output instead of the search. Checked by [`Identifier::fit`]
    /// (1..=[`super::MAX_ORDER`]).
    pub fn order(mut self, n: usize) -> Self {
        self.order = Some(n);
        self
    }

    /// The candidate orders searched for every output (default 1 to 4). Checked by
    /// [`Identifier::fit`]: not empty, each in 1..=[`super::MAX_ORDER`], none twice.
    pub fn orders(mut self, candidates: impl IntoIterator<Item = usize>) -> Self {
        self.order = None;
        self.settings.orders = Orders::Search(candidates.into_iter().collect());
        self
    }

    /// A named term beside the monomials, in the model file's expression language
    /// (`sign(q_m_d1)`, `abs(y_d1)*y_d1`); may be given several times. Checked by
    /// [`Identifier::fit`]: it must parse, not be given twice, have no part that is never
    /// finite, not be a monomial already among the candidates, and be finite on the data.
    pub fn term(mut self, expression: impl Into<String>) -> Self {
        self.settings.terms.push(expression.into());
        self
    }

    /// How the sampled inputs are read between samples when the model is simulated (default:
    /// [`Interpolation::Linear`](crate::model::Interpolation)); written into the model.
    pub fn input_interpolation(mut self, i: crate::model::Interpolation) -> Self {
        self.settings.input_interpolation = i;
        self
    }

    /// Whether an output the training runs hold at its extreme value is modelled with a hard
    /// limit there (default: yes; [`Settings::limits`](super::Settings::limits)).
    pub fn limits(mut self, on: bool) -> Self {
        self.settings.limits = on;
        self
    }

    /// Which engine runs the sparse regression's sweeps (default: automatic).
    pub fn engine(mut self, engine: EngineChoice) -> Self {
        self.settings.engine = engine;
        self
    }

    /// A function or closure called with each progress line of the long stages (default:
    /// silent); it may be called from the fitting threads ([`crate::identify::Progress`]).
    pub fn progress(mut self, f: impl Fn(&str) + Send + Sync + 'static) -> Self {
        self.settings.progress = Some(crate::identify::Progress::new(f));
        self
    }

    /// Every other setting, for what the builder does not name.
    pub fn settings_mut(&mut self) -> &mut Settings {
        &mut self.settings
    }

    /// The settings as they will run.
    pub fn settings(&self) -> Settings {
        let mut s = self.settings.clone();
        if let Some(n) = self.order {
            s.orders = Orders::Fixed(vec![n; s.outputs.len()]);
        }
        s
    }

    /// Checks the settings against the record set and identifies. Training, validation and
    /// test runs come from `split` (see [`Split::from_lists`]). Refuses what [`identify`] refuses,
    /// settings that [`Settings::validate`] refuses among it.
    ///
    /// ```
    /// use ctsid::records::{RecordSet, Run};
    /// use ctsid::{Identifier, Split};
    /// // Six runs of y' = -2 y + 3 u under different sines, integrated finely.
    /// let run = |r: usize| {
    ///     let (mut y, mut ys, mut us) = (0.0, Vec::new(), Vec::new());
    ///     for k in 0..400 {
    ///         let u = |t: f64| (t * (1.0 + 0.4 * r as f64)).sin() + 0.3 * r as f64;
    ///         ys.push(y);
    ///         us.push(u(k as f64 * 0.01));
    ///         for j in 0..50 {
    ///             y += 2e-4 * (-2.0 * y + 3.0 * u(k as f64 * 0.01 + j as f64 * 2e-4));
    ///         }
    ///     }
    ///     Run::new(r.to_string(), vec![ys, us])
    /// };
    /// let records = RecordSet::new(0.01, vec!["y".into(), "u".into()], (0..6).map(run).collect())?;
    /// let split = Split::from_lists(&records, "0-3", Some("4"), "5")?;
    /// let fit = Identifier::new().outputs(["y"]).inputs(["u"]).degree(1).fit(&records, &split)?;
    /// let eq = &fit.model.outputs[0];
    /// assert_eq!(eq.order, 1, "{}", fit.model);
    /// let coef = |v: &str| eq.terms.iter().find(|t| t.exponents.get(v) == Some(&1)).map(|t| t.coefficient);
    /// assert!((coef("y").unwrap() + 2.0).abs() < 0.02 && (coef("u").unwrap() - 3.0).abs() < 0.03, "{}", fit.model);
    /// # Ok::<(), ctsid::Error>(())
    /// ```
    pub fn fit(&self, records: &RecordSet, split: &Split) -> Result<Identification> {
        let s = self.settings();
        s.validate()?;
        identify(records, split, &s)
    }
}
