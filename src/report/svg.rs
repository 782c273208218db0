//! Minimal SVG line plots for reports: a few series against time, optional shaded bands, axes
//! with tick labels. Hand-written because reports need only this and a plotting crate would
//! double the build time; the output opens in any browser.

use std::fmt::Write;

/// One line on a plot.
pub struct Series<'a> {
    pub label: &'a str,
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub color: &'a str,
    /// Optional band (lower, upper) drawn under the line.
    pub band: Option<(&'a [f64], &'a [f64])>,
    pub dashed: bool,
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

/// Renders a plot as an SVG document.
pub fn line_plot(title: &str, xlabel: &str, ylabel: &str, series: &[Series]) -> String {
    let (w, h) = (900.0, 420.0);
    let (ml, mr, mt, mb) = (80.0, 20.0, 40.0, 55.0);
    let finite = |v: &&f64| v.is_finite();
    let xs = series.iter().flat_map(|s| s.x.iter()).filter(finite);
    let (x0, x1) = xs.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
        (a.min(v), b.max(v))
    });
    let ys = series
        .iter()
        .flat_map(|s| {
            s.y.iter().chain(
                s.band
                    .map(|b| b.0.iter().chain(b.1.iter()))
                    .into_iter()
                    .flatten(),
            )
        })
        .filter(finite);
    let (mut y0, mut y1) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
        (a.min(v), b.max(v))
    });
    if !(y0.is_finite() && y1.is_finite()) {
        y0 = -1.0;
        y1 = 1.0;
    }
    if y1 - y0 < 1e-300 {
        y0 -= 1.0;
        y1 += 1.0;
    }
    let pad = 0.05 * (y1 - y0);
    let (y0, y1) = (y0 - pad, y1 + pad);
    let (x0, x1) = if x1 > x0 { (x0, x1) } else { (0.0, 1.0) };
    let px = |x: f64| ml + (x - x0) / (x1 - x0) * (w - ml - mr);
    let py = |y: f64| mt + (y1 - y) / (y1 - y0) * (h - mt - mb);
    let mut s = String::new();
    let _ = write!(
        s,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" font-family="sans-serif" font-size="12">"#
    );
    let _ = write!(
        s,
        r#"<rect width="100%" height="100%" fill="white"/><text x="{}" y="22" font-size="15" text-anchor="middle">{}</text>"#,
        w / 2.0,
        esc(title)
    );
    for t in nice_ticks(x0, x1, 8) {
        let _ = write!(
            s,
            r##"<line x1="{0}" x2="{0}" y1="{1}" y2="{2}" stroke="#ddd"/><text x="{0}" y="{3}" text-anchor="middle">{4}</text>"##,
            px(t),
            mt,
            h - mb,
            h - mb + 16.0,
            fmt_tick(t)
        );
    }
    for t in nice_ticks(y0, y1, 6) {
        let _ = write!(
            s,
            r##"<line x1="{0}" x2="{1}" y1="{2}" y2="{2}" stroke="#ddd"/><text x="{3}" y="{4}" text-anchor="end">{5}</text>"##,
            ml,
            w - mr,
            py(t),
            ml - 6.0,
            py(t) + 4.0,
            fmt_tick(t)
        );
    }
    let _ = write!(
        s,
        r#"<rect x="{ml}" y="{mt}" width="{}" height="{}" fill="none" stroke="black"/>"#,
        w - ml - mr,
        h - mt - mb
    );
    let _ = write!(
        s,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        (ml + w - mr) / 2.0,
        h - 12.0,
        esc(xlabel)
    );
    let _ = write!(
        s,
        r#"<text transform="translate(18,{}) rotate(-90)" text-anchor="middle">{}</text>"#,
        (mt + h - mb) / 2.0,
        esc(ylabel)
    );
    for ser in series {
        if let Some((lo, hi)) = ser.band {
            let mut d = String::new();
            for (i, &x) in ser.x.iter().enumerate() {
                let _ = write!(
                    d,
                    "{}{:.1},{:.1} ",
                    if i == 0 { "M" } else { "L" },
                    px(x),
                    py(hi[i].clamp(y0, y1))
                );
            }
            for (i, &x) in ser.x.iter().enumerate().rev() {
                let _ = write!(d, "L{:.1},{:.1} ", px(x), py(lo[i].clamp(y0, y1)));
            }
            let _ = write!(
                s,
                r#"<path d="{d}Z" fill="{}" fill-opacity="0.2" stroke="none"/>"#,
                ser.color
            );
        }
        let mut d = String::new();
        let mut pen = false;
        for (i, &x) in ser.x.iter().enumerate() {
            let y = ser.y[i];
            if !y.is_finite() {
                pen = false;
                continue;
            }
            let _ = write!(
                d,
                "{}{:.1},{:.1} ",
                if pen { "L" } else { "M" },
                px(x),
                py(y.clamp(y0, y1))
            );
            pen = true;
        }
        let dash = if ser.dashed {
            r#" stroke-dasharray="6,4""#
        } else {
            ""
        };
        let _ = write!(
            s,
            r#"<path d="{d}" fill="none" stroke="{}" stroke-width="1.3"{dash}/>"#,
            ser.color
        );
    }
    for (k, ser) in series.iter().enumerate() {
        let y = mt + 14.0 + 16.0 * k as f64;
        let _ = write!(
            s,
            r#"<line x1="{}" x2="{}" y1="{y}" y2="{y}" stroke="{}" stroke-width="2"/><text x="{}" y="{}">{}</text>"#,
            w - mr - 190.0,
            w - mr - 165.0,
            ser.color,
            w - mr - 160.0,
            y + 4.0,
            esc(ser.label)
        );
    }
    s.push_str("</svg>\n");
    s
}

fn esc(t: &str) -> String {
    t.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn renders_lines_bands_and_labels() {
        let x = [0.0, 1.0, 2.0];
        let y = [1.0, f64::NAN, 3.0];
        let svg = line_plot(
            "t<1",
            "time (s)",
            "y",
            &[Series {
                label: "a&b",
                x: &x,
                y: &y,
                color: "red",
                band: Some((&[0.0, 0.0, 2.0], &[2.0, 2.0, 4.0])),
                dashed: true,
            }],
        );
        assert!(svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"));
        assert!(svg.contains("t&lt;1") && svg.contains("a&amp;b") && svg.contains("fill-opacity"));
        assert_eq!(
            nice_ticks(0.0, 10.0, 5),
            vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]
        );
    }
}
