//! The run's plot: an SVG with speed and its estimate, the angle error, and the dq currents
//! over time.
//!
//! [`PlotSink`] keeps every `stride`-th sample (at most about [`MAX_POINTS`] per curve) while
//! the run goes, and every change of the controller's state (at the period it happens), and
//! [`PlotSink::write_svg`] draws a band and four panels:
//!
//! 0. the **drive state** along the time axis: one coloured bar per stretch of a state
//!    ([`STATE_COLORS`]: align, I/f, hand-over, closed loop, HFI, fault, ...), named inside
//!    when it is wide enough, the key in the band's caption;
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
//! SVG only: plotters' SVG backend writes text as `<text>` elements and needs no font files,
//! so the plot works on a headless machine without system fonts.

use std::path::Path;

use plotters::prelude::*;

use crate::SimError;
use crate::output::SampleSink;
use crate::output::record::Sample;

/// Largest number of points kept per curve.
pub const MAX_POINTS: usize = 4000;

/// Colour and label of each drive state in the band (by the telemetry's state name; any
/// other name is drawn grey with its own name).
pub const STATE_COLORS: [(&str, &str, RGBColor); 8] = [
    ("idle", "idle", RGBColor(190, 190, 190)),
    ("align", "align", RGBColor(255, 140, 0)),
    ("open_loop", "I/f", RGBColor(255, 215, 0)),
    ("handover", "hand-over", RGBColor(100, 149, 237)),
    ("closed_loop", "closed loop", RGBColor(46, 139, 87)),
    ("hfi", "HFI", RGBColor(148, 0, 211)),
    ("fault", "fault", RGBColor(220, 20, 60)),
    ("sensored", "sensored", RGBColor(0, 128, 128)),
];

/// Colour and label of the state named `name` in the band.
pub fn state_style(name: &str) -> (&str, RGBColor) {
    STATE_COLORS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map_or((name, RGBColor(120, 120, 120)), |(_, label, c)| {
            (*label, *c)
        })
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

        // Band: the drive state.
        self.draw_states(&band, t0..t1)?;

        // Panel 1: speed.
        let (lo, hi) = range(pts.iter().flat_map(|p| [p.speed_rpm, p.est_rpm, p.ref_rpm]));
        let mut c = chart(&panels[0], "speed", t0..t1, lo..hi, "rpm (mech.)")?;
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.ref_rpm)),
            &BLACK.mix(0.5),
            "reference",
        )?;
        if pts.iter().any(|p| p.ctl_ref_rpm.is_some()) {
            line(
                &mut c,
                pts.iter().filter_map(|p| p.ctl_ref_rpm.map(|w| (p.t, w))),
                &MAGENTA.mix(0.6),
                "controller's own reference",
            )?;
        }
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.speed_rpm)),
            &BLUE,
            "true",
        )?;
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.est_rpm)),
            &RED,
            "EKF f64 (sim) estimate",
        )?;
        if pts.iter().any(|p| p.ctl_est_rpm.is_some()) {
            line(
                &mut c,
                pts.iter().filter_map(|p| p.ctl_est_rpm.map(|w| (p.t, w))),
                &CYAN.mix(0.9),
                "controller's EKF (f32) estimate",
            )?;
        }
        legend(&mut c)?;

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
            "angle error wrap(th_hat - th) (start-up excursion clipped)",
            t0..t1,
            -lim..lim,
            "deg el.",
        )?;
        if pts.iter().any(|p| p.seed_err_deg.is_some()) {
            line(
                &mut c,
                pts.iter()
                    .filter_map(|p| p.seed_err_deg.map(|e| (p.t, e.clamp(-lim, lim)))),
                &GREEN.mix(0.8),
                "seed filter",
            )?;
        }
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.err_deg.clamp(-lim, lim))),
            &RED,
            "EKF f64 (sim)",
        )?;
        if pts.iter().any(|p| p.ctl_err_deg.is_some()) {
            line(
                &mut c,
                pts.iter()
                    .filter_map(|p| p.ctl_err_deg.map(|e| (p.t, e.clamp(-lim, lim)))),
                &CYAN.mix(0.9),
                "controller's EKF (f32)",
            )?;
        }
        legend(&mut c)?;

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
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.i_dq_ref[1])),
            &BLACK.mix(0.5),
            "i_q ref",
        )?;
        line(&mut c, pts.iter().map(|p| (p.t, p.i_dq[1])), &BLUE, "i_q")?;
        line(
            &mut c,
            pts.iter().map(|p| (p.t, p.i_dq[0])),
            &MAGENTA,
            "i_d",
        )?;
        legend(&mut c)?;

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
            (0, true, BLACK, "psi_f plant"),
            (1, true, BLUE, "psi_f sim EKF"),
            (2, true, GREEN, "psi_f controller"),
            (0, false, RGBColor(128, 0, 0), "Rs plant"),
            (1, false, RED, "Rs sim EKF"),
            (2, false, MAGENTA, "Rs controller"),
        ];
        for (i, is_psi, color, label) in series {
            line(
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
        legend(&mut c)?;
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
        let key: Vec<String> = seen
            .iter()
            .map(|n| {
                let (label, RGBColor(r, g, b)) = state_style(n);
                format!("{label} #{r:02x}{g:02x}{b:02x}")
            })
            .collect();
        let caption = format!("drive state: {}", key.join(", "));
        let span = x.end - x.start;
        let mut c = ChartBuilder::on(area)
            .caption(caption, ("sans-serif", 16))
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
                        label.to_string(),
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
    let pad = ((hi - lo) * 0.05).max(1e-3);
    (lo - pad, hi + pad)
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
) -> Result<(), Box<dyn std::error::Error>> {
    let st: ShapeStyle = (*style).into();
    c.draw_series(LineSeries::new(points.filter(|p| p.1.is_finite()), st))?
        .label(label)
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], st));
    Ok(())
}

fn legend<'a, 'b: 'a>(c: &mut Chart<'a, 'b>) -> Result<(), Box<dyn std::error::Error>> {
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
        assert!(svg.contains(
            "drive state: align #ff8c00, I/f #ffd700, hand-over #6495ed, closed loop #2e8b57, fault #dc143c"
        ));
        // The band's rectangles, in time order, are the first ones after the background.
        let fills: Vec<&str> = svg
            .lines()
            .filter(|l| l.starts_with("<rect"))
            .filter_map(|l| l.split("fill=\"").nth(1)?.split('"').next())
            .skip(1)
            .take(5)
            .collect();
        assert_eq!(
            fills,
            ["#FF8C00", "#FFD700", "#6495ED", "#2E8B57", "#DC143C"]
        );
        let xs: Vec<f64> = svg
            .lines()
            .filter(|l| l.starts_with("<rect"))
            .skip(1)
            .take(5)
            .filter_map(|l| l.split("x=\"").nth(1)?.split('"').next()?.parse().ok())
            .collect();
        assert!(xs.windows(2).all(|w| w[0] < w[1]), "{xs:?}");
        // Names inside the stretches of at least 5 % of the run (all but the 20 ms hand-over).
        for name in ["align", "I/f", "closed loop", "fault"] {
            assert!(svg.contains(&format!(">\n{name}\n</text>")), "{name}");
        }
        assert!(!svg.contains(">\nhand-over\n</text>"));
    }
}
