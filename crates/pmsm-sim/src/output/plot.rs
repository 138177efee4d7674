//! The run's plot: an SVG with speed and its estimate, the angle error, and the dq currents
//! over time.
//!
//! [`PlotSink`] keeps every `stride`-th sample (at most about [`MAX_POINTS`] per curve) while
//! the run goes, and every change of the controller's state (at the period it happens), and
//! [`PlotSink::write_svg`] draws a band and four panels:
//!
//! 0. the **drive state** along the time axis: one coloured bar per stretch of a state
//!    ([`STATE_COLORS`]: align, I/f, hand-over, closed loop, HFI, fault, ...), named inside
//!    when it is wide enough; above it the key: a swatch and the state's name in words for
//!    each state the run went through;
//! 1. mechanical speed: true, estimated (the simulator's EKF and the controller's own, when
//!    it has one), the scenario's reference and the controller's own (slewed; `foc`: the I/f
//!    ramp speed in open loop), rpm;
//! 2. angle error `wrap(th_hat - th)` of the observer(s), electrical degrees; the axis is
//!    zoomed on the converged part (`|e| < 5 deg`), so the start-up excursion is clipped;
//! 3. dq currents in the true rotor frame and the controller's references, A;
//! 4. the motor's `psi_f` and `Rs`: the plant's (they drift with temperature, module
//!    [`faults`](crate::plant::fault_injection)) and the observers' tracked ones, % of the plant's values at
//!    the start.
//!
//! Each panel's legend lists the curves drawn on it and only those, in words ("speed
//! reference", "EKF angle error (simulator, f64)", "d-axis current", ...): a curve with no
//! finite point (no seed filter, no controller's observer) gets no line and no entry, and a
//! panel without curves no legend box. No text of the plot is a colour code or an
//! identifier.
//!
//! SVG only: plotters' SVG backend writes text as `<text>` elements and needs no font files,
//! so the plot works on a headless machine without system fonts.

use std::path::Path;

use plotters::prelude::*;

use crate::SimError;
use crate::output::SampleSink;
use crate::output::record::Sample;

/// Largest number of points kept per curve.
pub const MAX_POINTS: usize = 4000;

/// Colour and label of each drive state in the band (by the telemetry's state name), and of
/// each step of the identification sequence (`pmsm-sim identify`, foc's `IdentifyStep`
/// names); any other name is drawn grey, named in words (underscores as spaces).
pub const STATE_COLORS: [(&str, &str, RGBColor); 16] = [
    ("idle", "idle", RGBColor(190, 190, 190)),
    ("align", "align", RGBColor(255, 140, 0)),
    ("open_loop", "I/f", RGBColor(255, 215, 0)),
    ("handover", "hand-over", RGBColor(100, 149, 237)),
    ("closed_loop", "closed loop", RGBColor(46, 139, 87)),
    ("hfi", "HFI", RGBColor(148, 0, 211)),
    ("fault", "fault", RGBColor(220, 20, 60)),
    ("sensored", "sensored", RGBColor(0, 128, 128)),
    ("offsets", "current offsets", RGBColor(160, 160, 160)),
    ("probe", "probe", RGBColor(210, 180, 140)),
    ("resistance", "resistance", RGBColor(30, 144, 255)),
    ("inductance_d", "d-axis inductance", RGBColor(0, 0, 205)),
    ("inductance_q", "q-axis inductance", RGBColor(138, 43, 226)),
    ("spin", "spin", RGBColor(46, 139, 87)),
    ("inertia", "inertia", RGBColor(107, 142, 35)),
    ("done", "done", RGBColor(112, 128, 144)),
];

/// Label (in words) and colour of the state named `name` in the band: from
/// [`STATE_COLORS`], else grey with the name's underscores written as spaces.
pub fn state_style(name: &str) -> (String, RGBColor) {
    STATE_COLORS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map_or_else(
            || (name.replace('_', " "), RGBColor(120, 120, 120)),
            |(_, label, c)| ((*label).to_string(), *c),
        )
}

/// One kept sample.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Point {
    t: f64,
    speed_rpm: f64,
    est_rpm: f64,
    ref_rpm: f64,
    err_deg: f64,
    seed_err_deg: Option<f64>,
    ctl_est_rpm: Option<f64>,
    ctl_err_deg: Option<f64>,
    ctl_ref_rpm: Option<f64>,
    i_dq: [f64; 2],
    i_dq_ref: [f64; 2],
    /// `psi_f`: plant, simulator's EKF, controller's observer; `Rs` likewise.
    psi: [f64; 3],
    rs: [f64; 3],
}

/// Collects a decimated trace for the plot (module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PlotSink {
    stride: usize,
    /// Samples to skip before the next kept one (a countdown: no division per period).
    skip: usize,
    pole_pairs: f64,
    points: Vec<Point>,
    /// Every change of the controller's state: time and the new state's name.
    states: Vec<(f64, &'static str)>,
    /// Time of the last sample, s.
    t_last: f64,
}

impl PlotSink {
    /// A sink for a run of `periods` periods of a motor with `pole_pairs`.
    pub fn new(periods: usize, pole_pairs: u32) -> Self {
        let stride = periods.div_ceil(MAX_POINTS).max(1);
        Self {
            stride,
            skip: 0,
            pole_pairs: f64::from(pole_pairs),
            points: Vec::with_capacity(periods / stride + 1),
            states: Vec::new(),
            t_last: 0.0,
        }
    }

    /// Number of points kept.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether no point was kept.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// Draws the SVG at `path` with `title` on top.
    pub fn write_svg(&self, path: &Path, title: &str) -> Result<(), SimError> {
        // Drawn under a temporary name, renamed when complete (crate::output::file).
        crate::output::file::write_whole(path, |tmp| {
            self.draw(tmp, title)
                .map_err(|e| format!("cannot draw the plot: {e}"))
        })
    }

    fn draw(&self, path: &Path, title: &str) -> Result<(), Box<dyn std::error::Error>> {
        let pts = &self.points;
        let root = SVGBackend::new(path, (1200, 1380)).into_drawing_area();
        root.fill(&WHITE)?;
        let (top, rest) = root.split_vertically(40);
        top.titled(title, ("sans-serif", 22))?;
        let (band, rest) = rest.split_vertically(80);
        let panels = rest.split_evenly((4, 1));
        let (t0, t1) = match (pts.first(), pts.last()) {
            (Some(a), Some(b)) if b.t > a.t => (a.t, b.t),
            (Some(a), _) => (a.t, a.t + 1e-3),
            _ => (0.0, 1e-3),
        };

        // Legend entries drawn since the last legend (none: no legend box).
        let mut drawn = 0usize;

        // Band: the drive state.
        self.draw_states(&band, t0..t1)?;

        // Panel 1: speed.
        let (lo, hi) = range(pts.iter().flat_map(|p| [p.speed_rpm, p.est_rpm, p.ref_rpm]));
        let mut c = chart(&panels[0], "speed", t0..t1, lo..hi, "rpm (mech.)")?;
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.ref_rpm)),
            &BLACK.mix(0.5),
            "speed reference",
        )?;
        if pts.iter().any(|p| p.ctl_ref_rpm.is_some()) {
            drawn += line(
                &mut c,
                pts.iter().filter_map(|p| p.ctl_ref_rpm.map(|w| (p.t, w))),
                &MAGENTA.mix(0.6),
                "controller's speed reference (slewed)",
            )?;
        }
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.speed_rpm)),
            &BLUE,
            "true speed",
        )?;
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.est_rpm)),
            &RED,
            "EKF speed estimate (simulator, f64)",
        )?;
        if pts.iter().any(|p| p.ctl_est_rpm.is_some()) {
            drawn += line(
                &mut c,
                pts.iter().filter_map(|p| p.ctl_est_rpm.map(|w| (p.t, w))),
                &CYAN.mix(0.9),
                "controller's EKF speed estimate (f32)",
            )?;
        }
        legend(&mut c, &mut drawn)?;

        // Panel 2: angle error, zoomed on the converged part.
        let conv = |e: f64| e.abs() < 5.0;
        let zoom = pts
            .iter()
            .flat_map(|p| [Some(p.err_deg), p.seed_err_deg, p.ctl_err_deg])
            .flatten()
            .filter(|e| conv(*e))
            .fold(0.0f64, |m, e| m.max(e.abs()));
        let lim = (zoom * 1.15).clamp(0.2, 5.0);
        let mut c = chart(
            &panels[1],
            "angle error: estimated minus true angle, wrapped (start-up excursion clipped)",
            t0..t1,
            -lim..lim,
            "deg el.",
        )?;
        if pts.iter().any(|p| p.seed_err_deg.is_some()) {
            drawn += line(
                &mut c,
                pts.iter()
                    .filter_map(|p| p.seed_err_deg.map(|e| (p.t, e.clamp(-lim, lim)))),
                &GREEN.mix(0.8),
                "seed EKF angle error",
            )?;
        }
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.err_deg.clamp(-lim, lim))),
            &RED,
            "EKF angle error (simulator, f64)",
        )?;
        if pts.iter().any(|p| p.ctl_err_deg.is_some()) {
            drawn += line(
                &mut c,
                pts.iter()
                    .filter_map(|p| p.ctl_err_deg.map(|e| (p.t, e.clamp(-lim, lim)))),
                &CYAN.mix(0.9),
                "controller's EKF angle error (f32)",
            )?;
        }
        legend(&mut c, &mut drawn)?;

        // Panel 3: dq currents.
        let (lo, hi) = range(
            pts.iter()
                .flat_map(|p| [p.i_dq[0], p.i_dq[1], p.i_dq_ref[0], p.i_dq_ref[1]]),
        );
        let mut c = chart(
            &panels[2],
            "dq currents (true rotor frame)",
            t0..t1,
            lo..hi,
            "A",
        )?;
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.i_dq_ref[1])),
            &BLACK.mix(0.5),
            "q-axis current reference",
        )?;
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.i_dq[1])),
            &BLUE,
            "q-axis current",
        )?;
        drawn += line(
            &mut c,
            pts.iter().map(|p| (p.t, p.i_dq[0])),
            &MAGENTA,
            "d-axis current",
        )?;
        legend(&mut c, &mut drawn)?;

        // Panel 4: the motor's parameters, % of the plant's at the start.
        let (psi0, rs0) = pts.first().map_or((1.0, 1.0), |p| (p.psi[0], p.rs[0]));
        let pct = |v: f64, v0: f64| 100.0 * v / v0;
        let (lo, hi) = range(pts.iter().flat_map(|p| {
            [
                pct(p.psi[0], psi0),
                pct(p.psi[1], psi0),
                pct(p.psi[2], psi0),
                pct(p.rs[0], rs0),
                pct(p.rs[1], rs0),
                pct(p.rs[2], rs0),
            ]
        }));
        let (lo, hi) = (lo.min(95.0), hi.max(105.0));
        let mut c = chart(
            &panels[3],
            "motor parameters: plant vs tracked (% of the plant's at the start)",
            t0..t1,
            lo..hi,
            "%",
        )?;
        let series: [(usize, bool, RGBColor, &str); 6] = [
            (0, true, BLACK, "magnet flux, plant"),
            (1, true, BLUE, "magnet flux, EKF estimate"),
            (2, true, GREEN, "magnet flux, controller's estimate"),
            (0, false, RGBColor(128, 0, 0), "stator resistance, plant"),
            (1, false, RED, "stator resistance, EKF estimate"),
            (
                2,
                false,
                MAGENTA,
                "stator resistance, controller's estimate",
            ),
        ];
        for (i, is_psi, color, label) in series {
            drawn += line(
                &mut c,
                pts.iter().map(|p| {
                    let v = if is_psi {
                        pct(p.psi[i], psi0)
                    } else {
                        pct(p.rs[i], rs0)
                    };
                    (p.t, v)
                }),
                &color,
                label,
            )?;
        }
        legend(&mut c, &mut drawn)?;
        root.present()?;
        Ok(())
    }
}

impl PlotSink {
    /// The stretches of each state: `(start, end, state)`, s.
    pub fn state_segments(&self) -> Vec<(f64, f64, &'static str)> {
        let mut out = Vec::with_capacity(self.states.len());
        for (i, &(t, name)) in self.states.iter().enumerate() {
            let end = self.states.get(i + 1).map_or(self.t_last, |x| x.0);
            out.push((t, end, name));
        }
        out
    }

    /// The drive-state band (module docs) on `area` over the time range `x`.
    fn draw_states(
        &self,
        area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
        x: core::ops::Range<f64>,
    ) -> Result<(), Box<dyn std::error::Error>> {
        let segments = self.state_segments();
        let mut seen: Vec<&str> = vec![];
        for (_, _, name) in &segments {
            if !seen.contains(name) {
                seen.push(name);
            }
        }
        // The key, in words: "drive state:", then a swatch and the name of each state seen.
        let (key, area) = area.split_vertically(26);
        let font: TextStyle = ("sans-serif", 15).into();
        let mut px = 68;
        key.draw(&Text::new("drive state:", (px, 6), font.clone()))?;
        px += key.estimate_text_size("drive state:", &font)?.0 as i32 + 14;
        for n in &seen {
            let (label, color) = state_style(n);
            key.draw(&Rectangle::new([(px, 6), (px + 14, 20)], color.filled()))?;
            key.draw(&Text::new(label.clone(), (px + 19, 6), font.clone()))?;
            px += key.estimate_text_size(&label, &font)?.0 as i32 + 36;
        }
        let span = x.end - x.start;
        let mut c = ChartBuilder::on(&area)
            .margin(8)
            .x_label_area_size(0)
            .y_label_area_size(60)
            .build_cartesian_2d(x.clone(), 0.0..1.0)?;
        c.configure_mesh()
            .disable_mesh()
            .disable_x_axis()
            .y_labels(0)
            .draw()?;
        c.draw_series(segments.iter().map(|&(a, b, name)| {
            let (_, color) = state_style(name);
            Rectangle::new([(a.max(x.start), 0.0), (b.min(x.end), 1.0)], color.filled())
        }))?;
        // Names inside the stretches wide enough for them (5 % of the run).
        c.draw_series(
            segments
                .iter()
                .filter(|(a, b, _)| b - a >= 0.05 * span)
                .map(|&(a, _, name)| {
                    let (label, _) = state_style(name);
                    Text::new(
                        label,
                        (a.max(x.start) + 0.005 * span, 0.7),
                        ("sans-serif", 13),
                    )
                }),
        )?;
        Ok(())
    }
}

type Chart<'a, 'b> = ChartContext<
    'a,
    SVGBackend<'b>,
    Cartesian2d<plotters::coord::types::RangedCoordf64, plotters::coord::types::RangedCoordf64>,
>;

/// A finite `(lo, hi)` around the values with a 5 % margin.
fn range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    if !(lo.is_finite() && hi.is_finite()) {
        return (-1.0, 1.0);
    }
    // Half-spans: `hi - lo` itself may overflow near f64::MAX.
    let pad = (hi * 0.05 - lo * 0.05).max(1e-3);
    let (a, b) = (lo - pad, hi + pad);
    if a.is_finite() && b.is_finite() {
        (a, b)
    } else {
        (lo, hi.max(lo + 1e-3))
    }
}

fn chart<'a, 'b>(
    area: &'a DrawingArea<SVGBackend<'b>, plotters::coord::Shift>,
    caption: &str,
    x: core::ops::Range<f64>,
    y: core::ops::Range<f64>,
    y_desc: &str,
) -> Result<Chart<'a, 'b>, Box<dyn std::error::Error>> {
    let mut c = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(8)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(x, y)?;
    c.configure_mesh()
        .x_desc("t (s)")
        .y_desc(y_desc)
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    Ok(c)
}

fn line<S: Into<ShapeStyle> + Copy + 'static>(
    c: &mut Chart<'_, '_>,
    points: impl Iterator<Item = (f64, f64)>,
    style: &S,
    label: &str,
) -> Result<usize, Box<dyn std::error::Error>> {
    let st: ShapeStyle = (*style).into();
    // Points far outside the axes are drawn at a span beyond them (clipped by the chart):
    // plotters turns a coordinate into an i32 pixel, which a value beyond about 2^31 times
    // the axis's span would overflow.
    let (xr, yr) = (c.x_range(), c.y_range());
    let near = |v: f64, r: &core::ops::Range<f64>| {
        let span = r.end * 0.5 - r.start * 0.5;
        v.max(r.start - span).min(r.end + span)
    };
    let finite: Vec<(f64, f64)> = points
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .map(|(x, y)| (near(x, &xr), near(y, &yr)))
        .collect();
    if finite.is_empty() {
        // Nothing to draw: no line, no legend entry.
        return Ok(0);
    }
    c.draw_series(LineSeries::new(finite, st))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], st));
    Ok(1)
}

/// The legend of the curves drawn since the last one (`drawn` of them; none: no box).
fn legend<'a, 'b: 'a>(
    c: &mut Chart<'a, 'b>,
    drawn: &mut usize,
) -> Result<(), Box<dyn std::error::Error>> {
    if std::mem::take(drawn) == 0 {
        return Ok(());
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

impl SampleSink for PlotSink {
    #[inline]
    fn record(&mut self, s: &Sample) -> Result<(), String> {
        let state = s.control.telemetry.state;
        if self.states.last().is_none_or(|x| x.1 != state) {
            self.states.push((s.t_s, state));
        }
        self.t_last = s.t_s;
        if self.skip > 0 {
            self.skip -= 1;
        } else {
            self.skip = self.stride - 1;
            let tel = &s.control.telemetry;
            self.points.push(Point {
                t: s.t_s,
                speed_rpm: s.truth.speed_rpm,
                est_rpm: s.observer.omega_e_rad_s / self.pole_pairs
                    * crate::scenario::RPM_PER_RAD_S,
                ref_rpm: s.control.speed_ref_rpm,
                err_deg: s.observer.angle_error_deg,
                seed_err_deg: s.seed_filter.map(|f| f.angle_error_deg),
                ctl_est_rpm: s
                    .controller_observer
                    .map(|o| o.omega_e_rad_s / self.pole_pairs * crate::scenario::RPM_PER_RAD_S),
                ctl_err_deg: s.controller_observer.map(|o| o.angle_error_deg),
                ctl_ref_rpm: tel.speed_ref_rpm,
                i_dq: s.truth.i_dq_a,
                i_dq_ref: tel.i_dq_ref_a,
                psi: [
                    s.truth.psi_f_wb,
                    s.observer.psi_f_wb,
                    s.controller_observer.map_or(f64::NAN, |o| o.psi_f_wb),
                ],
                rs: [
                    s.truth.rs_ohm,
                    s.observer.rs_ohm,
                    s.controller_observer.map_or(f64::NAN, |o| o.rs_ohm),
                ],
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The band: one filled rectangle per stretch of a state, in its colour, left to right,
    /// the key in the caption and the names of the wide stretches inside.
    #[test]
    fn svg_has_the_drive_state_band() {
        let plan = [
            (0.0, "align"),
            (0.1, "open_loop"),
            (0.3, "handover"),
            (0.32, "closed_loop"),
            (0.8, "fault"),
        ];
        let mut sink = PlotSink::new(1000, 4);
        for k in 0..1000 {
            let t = k as f64 * 1e-3;
            let state = plan
                .iter()
                .rev()
                .find(|(t0, _)| t >= *t0)
                .map_or("idle", |x| x.1);
            let mut s = Sample {
                t_s: t,
                ..Sample::default()
            };
            s.control.telemetry.state = state;
            s.truth.psi_f_wb = 0.175;
            s.truth.rs_ohm = 2.875;
            sink.record(&s).unwrap_or_else(|e| panic!("{e}"));
        }
        let segs = sink.state_segments();
        assert_eq!(segs.len(), 5);
        assert_eq!(segs[1], (0.1, 0.3, "open_loop"));
        assert_eq!(segs[4].1, 0.999);

        let path = std::env::temp_dir().join(format!("pmsm-sim-band-{}.svg", std::process::id()));
        sink.write_svg(&path, "band")
            .unwrap_or_else(|e| panic!("{e}"));
        let svg = std::fs::read_to_string(&path).unwrap_or_default();
        let _ = std::fs::remove_file(&path);
        // The key in words: a swatch and a name per state, in order of appearance.
        let texts = visible_texts(&svg);
        let key: Vec<&str> = texts
            .iter()
            .skip_while(|t| *t != "drive state:")
            .skip(1)
            .take(5)
            .map(String::as_str)
            .collect();
        assert_eq!(key, ["align", "I/f", "hand-over", "closed loop", "fault"]);
        let colours = ["#FF8C00", "#FFD700", "#6495ED", "#2E8B57", "#DC143C"];
        // After the background: the key's five swatches, then the band's rectangles in time
        // order, in the same colours.
        let rects: Vec<&str> = svg.lines().filter(|l| l.starts_with("<rect")).collect();
        let fill = |l: &&str| {
            l.split("fill=\"")
                .nth(1)?
                .split('"')
                .next()
                .map(str::to_string)
        };
        let x =
            |l: &&str| -> Option<f64> { l.split("x=\"").nth(1)?.split('"').next()?.parse().ok() };
        let swatches: Vec<String> = rects.iter().skip(1).take(5).filter_map(fill).collect();
        assert_eq!(swatches, colours);
        let fills: Vec<String> = rects.iter().skip(6).take(5).filter_map(fill).collect();
        assert_eq!(fills, colours);
        let xs: Vec<f64> = rects.iter().skip(6).take(5).filter_map(x).collect();
        assert!(xs.windows(2).all(|w| w[0] < w[1]), "{xs:?}");
        // Names inside the stretches of at least 5 % of the run (all but the 20 ms hand-over).
        for name in ["align", "I/f", "closed loop", "fault"] {
            assert!(svg.contains(&format!(">\n{name}\n</text>")), "{name}");
        }
        // The hand-over's name is in the key only.
        assert_eq!(texts.iter().filter(|t| *t == "hand-over").count(), 1);
        assert!(no_hex_colour(&texts), "{texts:?}");
    }

    /// The contents of the SVG's `<text>` elements (what a reader sees), unescaped.
    fn visible_texts(svg: &str) -> Vec<String> {
        svg.split("<text")
            .skip(1)
            .filter_map(|t| {
                let body = t.split_once('>')?.1.split("</text>").next()?;
                Some(
                    body.trim()
                        .replace("&apos;", "'")
                        .replace("&quot;", "\"")
                        .replace("&lt;", "<")
                        .replace("&gt;", ">")
                        .replace("&amp;", "&"),
                )
            })
            .collect()
    }

    /// No text looks like a hex colour code (`#` and six hex digits).
    fn no_hex_colour(texts: &[String]) -> bool {
        texts.iter().all(|t| {
            !t.as_bytes()
                .windows(7)
                .any(|w| w[0] == b'#' && w[1..].iter().all(u8::is_ascii_hexdigit))
        })
    }

    /// Every label a curve can have, with whether a run with the seed filter and a controller
    /// observer (`all`) and one without them draws it.
    const LABELS: [(&str, bool); 17] = [
        ("speed reference", true),
        ("controller's speed reference (slewed)", false),
        ("true speed", true),
        ("EKF speed estimate (simulator, f64)", true),
        ("controller's EKF speed estimate (f32)", false),
        ("seed EKF angle error", false),
        ("EKF angle error (simulator, f64)", true),
        ("controller's EKF angle error (f32)", false),
        ("q-axis current reference", true),
        ("q-axis current", true),
        ("d-axis current", true),
        ("magnet flux, plant", true),
        ("magnet flux, EKF estimate", true),
        ("magnet flux, controller's estimate", false),
        ("stator resistance, plant", true),
        ("stator resistance, EKF estimate", true),
        ("stator resistance, controller's estimate", false),
    ];

    fn drawn(all: bool, state: &'static str) -> String {
        let mut sink = PlotSink::new(200, 4);
        for k in 0..200 {
            let mut s = Sample {
                k,
                t_s: k as f64 * 1e-3,
                ..Sample::default()
            };
            s.control.telemetry.state = state;
            s.truth.psi_f_wb = 0.175;
            s.truth.rs_ohm = 2.875;
            s.observer.psi_f_wb = 0.17;
            s.observer.rs_ohm = 2.9;
            s.observer.angle_error_deg = 0.1 * (k as f64 * 0.1).sin();
            if all {
                let mut o = s.observer;
                o.angle_error_deg *= 2.0;
                s.seed_filter = Some(o);
                s.controller_observer = Some(o);
                s.control.telemetry.speed_ref_rpm = Some(100.0);
            }
            sink.record(&s).unwrap_or_else(|e| panic!("{e}"));
        }
        let path =
            std::env::temp_dir().join(format!("pmsm-sim-legend-{all}-{}.svg", std::process::id()));
        sink.write_svg(&path, "legend")
            .unwrap_or_else(|e| panic!("{e}"));
        let svg = std::fs::read_to_string(&path).unwrap_or_default();
        let _ = std::fs::remove_file(&path);
        svg
    }

    /// The legends list the curves drawn and only those, in words: a run without the seed
    /// filter and the controller's observer has no entries for them (nor an empty curve);
    /// every entry is one drawn curve (one polyline for the curve, one for its legend
    /// sample); no text is a colour code; a state without a label of its own is named in
    /// words.
    #[test]
    fn legend_lists_the_drawn_curves_in_words() {
        for all in [false, true] {
            let svg = drawn(all, if all { "closed_loop" } else { "over_current" });
            let texts = visible_texts(&svg);
            let mut entries = 0;
            for (label, always) in LABELS {
                let n = texts.iter().filter(|t| *t == label).count();
                let expected = usize::from(all || always);
                assert_eq!(n, expected, "{label} (all: {all})");
                entries += n;
            }
            assert_eq!(entries, if all { 17 } else { 11 });
            // Polylines: (stroke and opacity, points). A legend sample is a 20 px horizontal
            // stroke; each has a curve of its style with more points.
            let lines: Vec<(String, Vec<(f64, f64)>)> = svg
                .lines()
                .filter(|l| l.starts_with("<polyline"))
                .filter_map(|l| {
                    let attr = |k: &str| l.split(&format!("{k}=\"")).nth(1)?.split('"').next();
                    let style = format!("{} {}", attr("stroke")?, attr("opacity")?);
                    let pts = attr("points")?
                        .split_whitespace()
                        .filter_map(|p| {
                            let (x, y) = p.split_once(',')?;
                            Some((x.parse().ok()?, y.parse().ok()?))
                        })
                        .collect();
                    Some((style, pts))
                })
                .collect();
            let samples: Vec<&String> = lines
                .iter()
                .filter(|(_, p)| p.len() == 2 && p[0].1 == p[1].1 && p[1].0 - p[0].0 == 20.0)
                .map(|(st, _)| st)
                .collect();
            assert_eq!(samples.len(), entries, "all: {all}");
            for st in samples {
                assert!(
                    lines.iter().any(|(s, p)| s == st && p.len() > 2),
                    "no curve drawn for the legend entry styled {st}"
                );
            }
            assert!(no_hex_colour(&texts), "{texts:?}");
            assert!(!texts.iter().any(|t| t.contains('_')), "{texts:?}");
            let state = if all { "closed loop" } else { "over current" };
            assert!(texts.iter().any(|t| t == state), "{texts:?}");
        }
    }
}
