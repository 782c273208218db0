//! SVG figures for reports: panels stacked one above the other, each a few series against a
//! shared x (time, lag, a state), with optional shaded bands, drawn as lines or as stems.
//!
//! What a reader needs from a plot decides the layout: the legend sits in a column right of the
//! plot area, so it never covers the data; dashed series are dashed in the legend too; a panel
//! can show a window of x (a zoom on a long record, where the full view would pack 100,000
//! samples into 800 pixels and hide one trace under the other); and a series longer than the
//! panel's pixel width is reduced to each pixel column's first, lowest, highest and last sample,
//! the envelope a screen shows anyway, so a 100,000-sample record makes a file of a few hundred
//! kilobytes rather than megabytes.
//!
//! Hand-written because reports need only this and a plotting crate would double the build
//! time; the output opens in any browser (`rsvg-convert -o f.png f.svg` makes a PNG).

use std::fmt::Write;
use std::ops::Range;

/// One line on a plot.
#[derive(Clone, Copy)]
pub struct Series<'a> {
    pub label: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub color: &'a str,
    /// Optional band (lower, upper) drawn under the line.
    pub band: Option<(&'a [f64], &'a [f64])>,
    pub dashed: bool,
}

/// How a panel draws its series.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Style {
    /// Connected lines (time series).
    Lines,
    /// A stem from zero to each point (correlations against lag); series with a band are
    /// drawn as lines (the band's edge).
    Stems,
}

/// One panel of a [`figure`].
pub struct Panel<'a> {
    pub title: String,
    pub xlabel: String,
    pub ylabel: String,
    pub series: Vec<Series<'a>>,
    pub style: Style,
    /// Height in pixels, title and axis labels included.
    pub height: f64,
    /// Only this window of x is drawn (a zoom); `None`: all of it.
    pub x_range: Option<(f64, f64)>,
    /// The y window covers the bulk of the values (see [`Panel::bulk_y`]), not every one.
    pub bulk_y: bool,
}

impl<'a> Panel<'a> {
    /// A panel of lines, 320 pixels high, over all x.
    pub fn lines(title: &str, xlabel: &str, ylabel: &str, series: Vec<Series<'a>>) -> Panel<'a> {
        Panel {
            title: title.into(),
            xlabel: xlabel.into(),
            ylabel: ylabel.into(),
            series,
            style: Style::Lines,
            height: 320.0,
            x_range: None,
            bulk_y: false,
        }
    }

    /// A panel of stems (correlations), 240 pixels high.
    pub fn stems(title: &str, xlabel: &str, ylabel: &str, series: Vec<Series<'a>>) -> Panel<'a> {
        Panel {
            style: Style::Stems,
            height: 240.0,
            ..Panel::lines(title, xlabel, ylabel, series)
        }
    }

    /// The same panel with another height.
    pub fn height(self, height: f64) -> Panel<'a> {
        Panel { height, ..self }
    }

    /// The same panel with its y window set by the bulk of the values: the 1st to 99th
    /// percentile, widened by half that span each side; values beyond are drawn at the edge.
    /// For signals with an isolated spike (a third derivative at a run's start is 1000 times
    /// its typical size) that would otherwise flatten everything else to a line.
    pub fn bulk_y(self) -> Panel<'a> {
        Panel {
            bulk_y: true,
            ..self
        }
    }

    /// The same panel showing x in `[lo, hi]` only.
    pub fn zoom(self, lo: f64, hi: f64) -> Panel<'a> {
        Panel {
            x_range: Some((lo, hi)),
            ..self
        }
    }
}

const WIDTH: f64 = 960.0;
const LEFT: f64 = 80.0;
/// The legend column right of the plot area.
const LEGEND: f64 = 200.0;
const TITLE_H: f64 = 36.0;
/// Per panel: its title above, tick labels and the x label below the plot area.
const PANEL_TOP: f64 = 22.0;
const PANEL_BOTTOM: f64 = 44.0;

/// Renders one panel as an SVG document (the common case). Panics as [`figure`] does.
pub fn line_plot(title: &str, xlabel: &str, ylabel: &str, series: &[Series]) -> String {
    let panel = Panel::lines("", xlabel, ylabel, series.to_vec()).height(384.0);
    figure(title, &[panel])
}

/// Renders panels stacked top to bottom under a figure title as an SVG document. Panics when a
/// series' `y`, or a bound of its band, is shorter than its `x`.
pub fn figure(title: &str, panels: &[Panel]) -> String {
    let h = TITLE_H + panels.iter().map(|p| p.height).sum::<f64>();
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{h}" font-family="sans-serif" font-size="12"><rect width="100%" height="100%" fill="white"/><text x="{}" y="24" font-size="15" text-anchor="middle">{}</text>"#,
        (LEFT + WIDTH - LEGEND) / 2.0,
        esc(title)
    );
    let mut top = TITLE_H;
    for p in panels {
        draw_panel(&mut s, p, top);
        top += p.height;
    }
    s.push_str("</svg>\n");
    s
}

/// A panel's plot area in pixels and the data window it maps.
struct Frame {
    left: f64,
    top: f64,
    width: f64,
    height: f64,
    x: (f64, f64),
    y: (f64, f64),
}

impl Frame {
    fn px(&self, x: f64) -> f64 {
        self.left + (x - self.x.0) / (self.x.1 - self.x.0) * self.width
    }
    fn py(&self, y: f64) -> f64 {
        let y = y.clamp(self.y.0, self.y.1);
        self.top + (self.y.1 - y) / (self.y.1 - self.y.0) * self.height
    }
    fn shows(&self, x: f64) -> bool {
        x >= self.x.0 && x <= self.x.1
    }
}

fn draw_panel(s: &mut String, p: &Panel, top: f64) {
    let mut f = Frame {
        left: LEFT,
        top: top + PANEL_TOP,
        width: WIDTH - LEFT - LEGEND,
        height: (p.height - PANEL_TOP - PANEL_BOTTOM).max(20.0),
        x: x_window(p),
        y: (0.0, 1.0),
    };
    f.y = y_window(p, &f);
    draw_axes(s, p, &f);
    for ser in &p.series {
        if let Some(band) = ser.band {
            draw_band(s, &f, ser, band);
        }
    }
    for ser in &p.series {
        // On a stem panel a series with a band is the band's edge (a confidence bound).
        match p.style {
            Style::Stems if ser.band.is_none() => draw_stems(s, &f, ser),
            _ => draw_line(s, &f, ser),
        }
    }
    draw_legend(s, &f, &p.series);
}

/// The x window: the zoom if set, else every finite x of the series.
fn x_window(p: &Panel) -> (f64, f64) {
    let (lo, hi) = p
        .x_range
        .unwrap_or_else(|| finite_range(p.series.iter().flat_map(|s| s.x.iter().copied())));
    if hi > lo {
        (lo, hi)
    } else {
        widened(lo)
    }
}

/// A window around a single value `v`: wide enough to be a window at v's magnitude (at 1.7e18,
/// nanosecond time stamps, v +- 0.5 is v itself), (0, 1) for a non-finite v.
fn widened(v: f64) -> (f64, f64) {
    let pad = 0.5f64.max(v.abs() * 1e-9);
    if v.is_finite() && v + pad > v - pad {
        (v - pad, v + pad)
    } else {
        (0.0, 1.0)
    }
}

/// The y window: every finite y (and band) whose x is shown, with 5 % margins; stems always
/// include zero.
fn y_window(p: &Panel, f: &Frame) -> (f64, f64) {
    let shown = |s: &Series| -> Vec<f64> {
        let mut v = Vec::new();
        for (i, &x) in s.x.iter().enumerate() {
            if f.shows(x) {
                v.push(s.y[i]);
                if let Some((lo, hi)) = s.band {
                    v.extend([lo[i], hi[i]]);
                }
            }
        }
        v
    };
    let (mut lo, mut hi) = if p.bulk_y {
        bulk_range(
            p.series
                .iter()
                .flat_map(shown)
                .filter(|v| v.is_finite())
                .collect(),
        )
    } else {
        finite_range(p.series.iter().flat_map(shown))
    };
    if p.style == Style::Stems {
        lo = lo.min(0.0);
        hi = hi.max(0.0);
    }
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    if hi - lo < 1e-300 {
        return widened(lo);
    }
    let pad = 0.05 * (hi - lo);
    (lo - pad, hi + pad)
}

/// The 1st to 99th percentile of `v`, widened by half their distance each side (never beyond
/// the values' own range).
fn bulk_range(mut v: Vec<f64>) -> (f64, f64) {
    if v.is_empty() {
        return (f64::INFINITY, f64::NEG_INFINITY);
    }
    v.sort_unstable_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    let (lo, hi) = (at(0.01), at(0.99));
    let pad = 0.5 * (hi - lo);
    ((lo - pad).max(v[0]), (hi + pad).min(v[v.len() - 1]))
}

fn finite_range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        })
}

fn draw_axes(s: &mut String, p: &Panel, f: &Frame) {
    let bottom = f.top + f.height;
    let right = f.left + f.width;
    for t in nice_ticks(f.x.0, f.x.1, 8) {
        let _ = write!(
            s,
            r##"<line x1="{0:.1}" x2="{0:.1}" y1="{1:.1}" y2="{2:.1}" stroke="#ddd"/><text x="{0:.1}" y="{3:.1}" text-anchor="middle">{4}</text>"##,
            f.px(t),
            f.top,
            bottom,
            bottom + 15.0,
            fmt_tick(t)
        );
    }
    for t in nice_ticks(f.y.0, f.y.1, 5) {
        let _ = write!(
            s,
            r##"<line x1="{0:.1}" x2="{1:.1}" y1="{2:.1}" y2="{2:.1}" stroke="#ddd"/><text x="{3:.1}" y="{4:.1}" text-anchor="end">{5}</text>"##,
            f.left,
            right,
            f.py(t),
            f.left - 6.0,
            f.py(t) + 4.0,
            fmt_tick(t)
        );
    }
    let _ = write!(
        s,
        r#"<rect x="{}" y="{}" width="{}" height="{}" fill="none" stroke="black"/><text x="{}" y="{}" font-weight="bold">{}</text><text x="{}" y="{}" text-anchor="middle">{}</text><text transform="translate(16,{}) rotate(-90)" text-anchor="middle">{}</text>"#,
        f.left,
        f.top,
        f.width,
        f.height,
        f.left,
        f.top - 7.0,
        esc(&p.title),
        f.left + f.width / 2.0,
        bottom + 32.0,
        esc(&p.xlabel),
        f.top + f.height / 2.0,
        esc(&p.ylabel)
    );
}

/// Consecutive indices of the shown samples that fall in the same pixel column; every sample is
/// its own bucket when there are few (at most two per pixel).
fn buckets(f: &Frame, x: &[f64]) -> Vec<Range<usize>> {
    let shown: Vec<usize> = (0..x.len()).filter(|&i| f.shows(x[i])).collect();
    if shown.len() <= 2 * f.width as usize {
        return shown.into_iter().map(|i| i..i + 1).collect();
    }
    let mut out: Vec<Range<usize>> = Vec::new();
    let mut col = f64::NAN;
    for i in shown {
        let c = f.px(x[i]).floor();
        match out.last_mut() {
            Some(r) if c == col && r.end == i => r.end = i + 1,
            _ => out.push(i..i + 1),
        }
        col = c;
    }
    out
}

/// The points to draw for one bucket, in index order: first, lowest, highest, last (each
/// once); `None` when the bucket holds a non-finite value (the line breaks there).
fn bucket_points(y: &[f64], r: Range<usize>) -> Option<Vec<usize>> {
    if y[r.clone()].iter().any(|v| !v.is_finite()) {
        return None;
    }
    let (mut lo, mut hi) = (r.start, r.start);
    for i in r.clone() {
        if y[i] < y[lo] {
            lo = i;
        }
        if y[i] > y[hi] {
            hi = i;
        }
    }
    let mut idx = vec![r.start, lo, hi, r.end - 1];
    idx.sort_unstable();
    idx.dedup();
    Some(idx)
}

fn draw_line(s: &mut String, f: &Frame, ser: &Series) {
    let mut d = String::new();
    let mut pen = false;
    for b in buckets(f, ser.x) {
        let Some(points) = bucket_points(ser.y, b) else {
            pen = false;
            continue;
        };
        for i in points {
            let cmd = if pen { "L" } else { "M" };
            let _ = write!(d, "{cmd}{:.1},{:.1} ", f.px(ser.x[i]), f.py(ser.y[i]));
            pen = true;
        }
    }
    let _ = write!(
        s,
        r#"<path d="{d}" fill="none" stroke="{}" stroke-width="1.2"{}/>"#,
        ser.color,
        dash(ser.dashed)
    );
}

fn draw_stems(s: &mut String, f: &Frame, ser: &Series) {
    let zero = f.py(0.0);
    for (i, &x) in ser.x.iter().enumerate() {
        let y = ser.y[i];
        if !f.shows(x) || !y.is_finite() {
            continue;
        }
        let _ = write!(
            s,
            r#"<line x1="{0:.1}" x2="{0:.1}" y1="{1:.1}" y2="{2:.1}" stroke="{3}" stroke-width="1.5"/><circle cx="{0:.1}" cy="{2:.1}" r="2.5" fill="{3}"/>"#,
            f.px(x),
            zero,
            f.py(y),
            ser.color
        );
    }
}

/// A shaded band: per pixel column, the highest upper and lowest lower bound.
fn draw_band(s: &mut String, f: &Frame, ser: &Series, (lo, hi): (&[f64], &[f64])) {
    let edge = |v: &[f64], pick: fn(f64, f64) -> f64, r: &Range<usize>| {
        let x = 0.5 * (ser.x[r.start] + ser.x[r.end - 1]);
        let y = v[r.clone()].iter().copied().fold(v[r.start], pick);
        (f.px(x), f.py(y))
    };
    let bs: Vec<Range<usize>> = buckets(f, ser.x)
        .into_iter()
        .filter(|r| (r.clone()).all(|i| lo[i].is_finite() && hi[i].is_finite()))
        .collect();
    if bs.is_empty() {
        return;
    }
    let mut d = String::new();
    for (k, r) in bs.iter().enumerate() {
        let (x, y) = edge(hi, f64::max, r);
        let _ = write!(d, "{}{x:.1},{y:.1} ", if k == 0 { "M" } else { "L" });
    }
    for r in bs.iter().rev() {
        let (x, y) = edge(lo, f64::min, r);
        let _ = write!(d, "L{x:.1},{y:.1} ");
    }
    let _ = write!(
        s,
        r#"<path d="{d}Z" fill="{}" fill-opacity="0.2" stroke="none"/>"#,
        ser.color
    );
}

/// The legend, in the column right of the plot area; each entry drawn as its series is.
fn draw_legend(s: &mut String, f: &Frame, series: &[Series]) {
    let x = f.left + f.width + 12.0;
    for (k, ser) in series.iter().enumerate() {
        let y = f.top + 10.0 + 18.0 * k as f64;
        if ser.band.is_some() {
            let _ = write!(
                s,
                r#"<rect x="{x}" y="{}" width="26" height="10" fill="{}" fill-opacity="0.2"/>"#,
                y - 5.0,
                ser.color
            );
        }
        let _ = write!(
            s,
            r#"<line x1="{x}" x2="{}" y1="{y}" y2="{y}" stroke="{}" stroke-width="2"{}/><text x="{}" y="{}">{}</text>"#,
            x + 26.0,
            ser.color,
            dash(ser.dashed),
            x + 32.0,
            y + 4.0,
            esc(ser.label)
        );
    }
}

fn dash(dashed: bool) -> &'static str {
    if dashed {
        r#" stroke-dasharray="6,4""#
    } else {
        ""
    }
}

fn nice_ticks(lo: f64, hi: f64, n: usize) -> Vec<f64> {
    let span = (hi - lo).max(1e-300);
    let raw = span / n as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| span / s <= n as f64)
        .unwrap_or(10.0 * mag);
    // Ticks as k * step: adding step to a value far larger than it (time stamps in ns) would
    // not move it, and the loop would not end.
    let first = (lo / step).ceil();
    let mut out = Vec::new();
    for k in 0..=4 * n {
        let t = (first + k as f64) * step;
        if t.is_nan() || t > hi + 1e-9 * step {
            break;
        }
        if out.last() == Some(&t) {
            break;
        }
        out.push(if t.abs() < 1e-12 * step { 0.0 } else { t });
    }
    out
}

fn fmt_tick(v: f64) -> String {
    let a = v.abs();
    if a != 0.0 && !(1e-3..1e5).contains(&a) {
        format!("{v:.1e}")
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Text as XML character data: `& < >` escaped, and control characters (which XML 1.0 does not
/// allow at all: a run id with `\x01` made the figure unreadable) shown as U+FFFD.
fn esc(t: &str) -> String {
    let mut out = String::with_capacity(t.len());
    for c in t.chars() {
        match c {
            '\t' | '\n' | '\r' => out.push(c),
            c if (c as u32) < 0x20 || c == '\u{FFFE}' || c == '\u{FFFF}' => out.push('\u{FFFD}'),
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            c => out.push(c),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_from_the_data_is_well_formed_xml() {
        assert_eq!(esc("a\u{1}b & <c>"), "a\u{FFFD}b &amp; &lt;c&gt;");
        assert_eq!(esc("tab\tok"), "tab\tok");
    }

    fn series<'a>(x: &'a [f64], y: &'a [f64], dashed: bool) -> Series<'a> {
        Series {
            label: "a&b",
            x,
            y,
            color: "red",
            band: None,
            dashed,
        }
    }

    #[test]
    fn renders_lines_bands_and_labels() {
        let x = [0.0, 1.0, 2.0];
        let y = [1.0, f64::NAN, 3.0];
        let mut s = series(&x, &y, true);
        s.band = Some((&[0.0, 0.0, 2.0], &[2.0, 2.0, 4.0]));
        let svg = line_plot("t<1", "time (s)", "y", &[s]);
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("t&lt;1") && svg.contains("a&amp;b") && svg.contains("fill-opacity"));
        // The dashed series and its legend entry are both dashed.
        assert_eq!(svg.matches("stroke-dasharray").count(), 2);
        assert_eq!(
            nice_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
    }

    #[test]
    fn the_legend_is_right_of_the_data() {
        let x = [0.0, 1.0];
        let svg = line_plot("", "t", "y", &[series(&x, &x, false)]);
        let legend_x: f64 = svg
            .split("<line x1=\"")
            .last()
            .and_then(|r| r.split('"').next())
            .and_then(|v| v.parse().ok())
            .unwrap();
        assert!(legend_x > WIDTH - LEGEND, "legend at x = {legend_x}");
    }

    #[test]
    fn long_series_keep_their_envelope_in_few_points() {
        let n = 100_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        // A spike of one sample must survive the reduction.
        let y: Vec<f64> = (0..n)
            .map(|i| if i == 54_321 { 9.0 } else { (i % 7) as f64 })
            .collect();
        let svg = line_plot("", "t", "y", &[series(&x, &y, false)]);
        assert!(svg.len() < 100_000, "{} bytes", svg.len());
        // y = 9 plots at the top of the y window (9 + 5 % margin).
        let f = Frame {
            left: LEFT,
            top: TITLE_H + PANEL_TOP,
            width: WIDTH - LEFT - LEGEND,
            height: 384.0 - PANEL_TOP - PANEL_BOTTOM,
            x: (0.0, n as f64 - 1.0),
            y: (-0.45, 9.45),
        };
        assert!(svg.contains(&format!(",{:.1} ", f.py(9.0))));
    }

    #[test]
    fn a_bulk_window_ignores_an_isolated_spike() {
        let x: Vec<f64> = (0..1000).map(|i| i as f64).collect();
        let mut y: Vec<f64> = x.iter().map(|v| (v * 0.05).sin()).collect();
        y[0] = 2e6;
        let panel = Panel::lines("", "t", "y", vec![series(&x, &y, false)]).bulk_y();
        let f = Frame {
            left: 0.0,
            top: 0.0,
            width: 800.0,
            height: 100.0,
            x: (0.0, 999.0),
            y: (0.0, 1.0),
        };
        let (lo, hi) = y_window(&panel, &f);
        assert!(lo > -3.0 && hi < 3.0, "{lo}..{hi}");
        let (_, hi) = y_window(
            &Panel {
                bulk_y: false,
                ..panel
            },
            &f,
        );
        assert!(hi > 1e6);
    }

    #[test]
    fn a_zoom_draws_only_its_window_and_stems_start_at_zero() {
        let x: Vec<f64> = (0..100).map(|i| i as f64).collect();
        let y: Vec<f64> = x.iter().map(|v| v * v).collect();
        let zoomed = figure(
            "",
            &[Panel::lines("", "t", "y", vec![series(&x, &y, false)]).zoom(10.0, 20.0)],
        );
        let path = zoomed.split("<path d=\"").nth(1).unwrap();
        assert_eq!(path.matches('L').count(), 10, "11 samples in [10, 20]");
        let stems = figure(
            "",
            &[Panel::stems(
                "",
                "lag",
                "r",
                vec![series(&x[..3], &[0.5, -0.5, 1.0], false)],
            )],
        );
        assert_eq!(stems.matches("<circle").count(), 3);
    }
}
