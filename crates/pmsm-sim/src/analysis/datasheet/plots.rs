//! The datasheet's figures: x-y charts drawn with plotters' SVG backend into a string (text
//! as SVG `<text>`, no font files; the same backend as the run's plot, `output::plot`).

use plotters::prelude::*;

/// One curve or point set of a figure.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend entry.
    pub name: String,
    /// Colour.
    pub color: RGBColor,
    /// `(x, y)` points; non-finite ones are left out.
    pub points: Vec<(f64, f64)>,
    /// Joined by a line (else markers only).
    pub line: bool,
}

/// A figure: its file name (markdown twin), title, axes and series.
#[derive(Clone, Debug)]
pub struct Figure {
    /// File name next to `datasheet.md` (`fig1-angle-error.svg`).
    pub file: String,
    /// Title above the chart.
    pub title: String,
    /// x-axis caption.
    pub x_label: String,
    /// y-axis caption.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Names of the integer x positions (a category axis), if any.
    pub x_categories: Vec<String>,
    /// Horizontal reference lines `(y, caption)`.
    pub h_lines: Vec<(f64, String)>,
}

/// Colours of successive series (colour-blind-safe palette, Okabe-Ito).
pub const PALETTE: [RGBColor; 7] = [
    RGBColor(0, 114, 178),
    RGBColor(230, 159, 0),
    RGBColor(0, 158, 115),
    RGBColor(204, 121, 167),
    RGBColor(86, 180, 233),
    RGBColor(213, 94, 0),
    RGBColor(0, 0, 0),
];
/// Good outcome.
pub const GOOD: RGBColor = RGBColor(0, 158, 115);
/// Bad outcome.
pub const BAD: RGBColor = RGBColor(213, 94, 0);

/// Width and height of every figure, px.
pub const SIZE: (u32, u32) = (820, 440);

/// The range of `v` padded by 5 % (a unit span around a single value; `0..1` for none).
fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = v
        .filter(|x| x.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), x| {
            (l.min(x), h.max(x))
        });
    if !lo.is_finite() {
        return (0.0, 1.0);
    }
    let span = hi - lo;
    if span <= 1e-12 * lo.abs().max(1.0) {
        return (lo - 0.5, hi + 0.5);
    }
    (lo - 0.05 * span, hi + 0.05 * span)
}

/// The figure as SVG text.
pub fn svg(fig: &Figure) -> Result<String, String> {
    let mut out = String::new();
    draw(fig, &mut out).map_err(|e| format!("cannot draw {}: {e}", fig.file))?;
    Ok(out)
}

fn draw(fig: &Figure, out: &mut String) -> Result<(), Box<dyn std::error::Error>> {
    let finite = |p: &&(f64, f64)| p.0.is_finite() && p.1.is_finite();
    let all = || {
        fig.series
            .iter()
            .flat_map(|s| s.points.iter().filter(finite))
    };
    let (x0, x1) = if fig.x_categories.is_empty() {
        range(all().map(|p| p.0))
    } else {
        (-0.5, fig.x_categories.len() as f64 - 0.5)
    };
    let (y0, y1) = range(all().map(|p| p.1).chain(fig.h_lines.iter().map(|h| h.0)));
    let root = SVGBackend::with_string(out, SIZE).into_drawing_area();
    root.fill(&WHITE)?;
    let mut chart = ChartBuilder::on(&root)
        .caption(&fig.title, ("sans-serif", 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(64)
        .build_cartesian_2d(x0..x1, y0..y1)?;
    let cats = &fig.x_categories;
    let fmt_x = |x: &f64| {
        if cats.is_empty() {
            format!("{x}")
        } else {
            let k = x.round();
            if (x - k).abs() < 1e-6 && k >= 0.0 && (k as usize) < cats.len() {
                cats[k as usize].clone()
            } else {
                String::new()
            }
        }
    };
    let mut mesh = chart.configure_mesh();
    mesh.x_desc(fig.x_label.as_str())
        .y_desc(fig.y_label.as_str())
        .x_label_formatter(&fmt_x)
        .label_style(("sans-serif", 14));
    if !cats.is_empty() {
        mesh.x_labels(cats.len() * 2 + 1);
    }
    mesh.draw()?;
    for (y, caption) in &fig.h_lines {
        let grey = RGBColor(120, 120, 120);
        chart.draw_series(LineSeries::new([(x0, *y), (x1, *y)], grey.stroke_width(1)))?;
        chart.draw_series(std::iter::once(Text::new(
            caption.clone(),
            (x0 + 0.01 * (x1 - x0), *y),
            ("sans-serif", 13).into_font().color(&grey),
        )))?;
    }
    for s in &fig.series {
        let pts: Vec<(f64, f64)> = s.points.iter().filter(finite).copied().collect();
        let c = s.color;
        if s.line {
            chart
                .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))?
                .label(s.name.as_str())
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], c.stroke_width(2)));
            chart.draw_series(pts.iter().map(|&p| Circle::new(p, 3, c.filled())))?;
        } else {
            chart
                .draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled())))?
                .label(s.name.as_str())
                .legend(move |(x, y)| Circle::new((x + 9, y), 4, c.filled()));
        }
    }
    if fig.series.iter().any(|s| !s.name.is_empty()) {
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .label_font(("sans-serif", 13))
            .position(SeriesLabelPosition::UpperRight)
            .draw()?;
    }
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_figure_is_svg_with_its_title_and_legend() {
        let fig = Figure {
            file: "f.svg".into(),
            title: "the title".into(),
            x_label: "x".into(),
            y_label: "y".into(),
            series: vec![
                Series {
                    name: "line one".into(),
                    color: PALETTE[0],
                    points: vec![(0.0, 1.0), (1.0, f64::NAN), (2.0, 3.0)],
                    line: true,
                },
                Series {
                    name: "dots".into(),
                    color: BAD,
                    points: vec![(1.0, 2.0)],
                    line: false,
                },
            ],
            x_categories: vec![],
            h_lines: vec![(2.5, "limit".into())],
        };
        let s = svg(&fig).unwrap();
        assert!(s.starts_with("<svg"), "{}", &s[..40]);
        for want in ["the title", "line one", "dots", "limit", "<circle"] {
            assert!(s.contains(want), "{want}");
        }
        assert!(!s.contains("NaN"));
    }
}
