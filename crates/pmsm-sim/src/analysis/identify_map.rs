//! The flux-map step of `pmsm-sim identify --flux-map`: foc's [`IdentifyWithMap`] (the
//! identification, then stop, re-align and the standstill flux-map probe) in place of the
//! plain [`Identifier`], and its report: the measured `psi_d`, `psi_q` on the grid, the
//! plant's true flux at the same currents when the plant saturates (`[motor.saturation]` or
//! `[motor.flux_map]`; the linear model's `psi_f + L i` otherwise), the largest errors and an
//! SVG of the curves.
//!
//! Errors are `|psi_measured - psi_true| / |psi_true|` (the stator flux magnitude at the
//! node), `%`, over the nodes with `|i| <= I_r` (`I_r` the identification's test current:
//! half the current limit, the rated current of the saturated reference scenarios) and over
//! the whole grid.

use std::path::Path;

use foc::identify::{FluxMapStep, IdentifyWithMap};
use foc::{Identifier, IdentifyConfig, IdentifyOutput, TickInput};
use plotters::prelude::*;
use serde::Serialize;

use crate::SimError;
use crate::plant::MotorModel;

/// Largest rotor angle the probe followed (electrical rad) below which the table carries no
/// warning: the probe's rotor-frame tracking was verified to 0.24 rad on the interior PM motor.
pub const ROTOR_TURNED_RAD: f64 = 0.5;

/// The identifier `identify` ticks: the plain sequence or the one with the flux-map step.
#[allow(clippy::large_enum_variant)]
pub(super) enum Runner {
    Plain(Identifier),
    Map(IdentifyWithMap),
}

impl Runner {
    /// The plain sequence, or (with `flux_map_a`) the one with the flux-map step up to that
    /// current.
    pub(super) fn new(cfg: &IdentifyConfig, flux_map_a: Option<f64>) -> Result<Self, String> {
        match flux_map_a {
            None => Identifier::new(cfg)
                .map(Runner::Plain)
                .map_err(|e| e.to_string()),
            Some(i) => IdentifyWithMap::new(cfg, &FluxMapStep::new(i as f32))
                .map(Runner::Map)
                .map_err(|e| e.to_string()),
        }
    }

    pub(super) fn identifier(&self) -> &Identifier {
        match self {
            Runner::Plain(id) => id,
            Runner::Map(m) => m.identifier(),
        }
    }

    pub(super) fn tick(&mut self, input: &TickInput) -> IdentifyOutput {
        match self {
            Runner::Plain(id) => id.tick(input),
            Runner::Map(m) => m.tick(input),
        }
    }

    pub(super) fn is_done(&self) -> bool {
        match self {
            Runner::Plain(id) => id.is_done(),
            Runner::Map(m) => m.is_done(),
        }
    }

    pub(super) fn ticks(&self) -> u32 {
        match self {
            Runner::Plain(id) => id.ticks(),
            Runner::Map(m) => m.ticks(),
        }
    }

    pub(super) fn max_duration_s(&self) -> f32 {
        match self {
            Runner::Plain(id) => id.max_duration_s(),
            Runner::Map(m) => m.max_duration_s(),
        }
    }

    /// The name of the part in progress (the step's name for the plain sequence).
    pub(super) fn part_name(&self) -> &'static str {
        match self {
            Runner::Plain(id) => id.step().name(),
            Runner::Map(m) => m.part().name(),
        }
    }

    /// The flux-map step's report (`None` for the plain sequence): `i_rated` bounds the
    /// rated-range error.
    pub(super) fn map_report(
        &self,
        motor: &MotorModel,
        i_rated: f64,
        ts: f64,
    ) -> Option<FluxMapReport> {
        let Runner::Map(m) = self else { return None };
        let [stop, realign, probe] = m.map_ticks().map(|n| f64::from(n) * ts);
        let mut r = FluxMapReport {
            ok: false,
            error: None,
            i_max_a: 0.0,
            i_rated_a: i_rated,
            i_d_a: Vec::new(),
            i_q_a: Vec::new(),
            psi_d_wb: Vec::new(),
            psi_q_wb: Vec::new(),
            true_psi_d_wb: Vec::new(),
            true_psi_q_wb: Vec::new(),
            max_error_rated_pct: None,
            max_error_grid_pct: None,
            max_error_rated_map_pct: None,
            max_error_grid_map_pct: None,
            stop_s: stop,
            realign_s: realign,
            probe_s: probe,
            rotor_angle_max_rad: 0.0,
        };
        match m.flux_map() {
            None => r.error = Some("the identification failed before the flux-map step".into()),
            Some(Err(e)) => r.error = Some(e.to_string()),
            Some(Ok(s)) => {
                r.ok = true;
                r.i_d_a = s.i_d[..s.n_d].iter().map(|&x| f64::from(x)).collect();
                r.i_q_a = s.i_q[..s.n_q].iter().map(|&x| f64::from(x)).collect();
                r.i_max_a = r.i_q_a.last().copied().unwrap_or(0.0);
                r.rotor_angle_max_rad = f64::from(s.rotor_angle_max_rad);
                let rows = |p: &[[f32; foc::identify::saturation::SAT_MAX_Q]]| {
                    p[..s.n_d]
                        .iter()
                        .map(|row| row[..s.n_q].iter().map(|&x| f64::from(x)).collect())
                        .collect::<Vec<Vec<f64>>>()
                };
                r.psi_d_wb = rows(&s.psi_d);
                r.psi_q_wb = rows(&s.psi_q);
                r.fill_truth(motor);
            }
        }
        Some(r)
    }
}

/// Flux values on the grid, `[d][q]`, Wb.
pub type Nodes = Vec<Vec<f64>>;

/// The flux-map step's outcome (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FluxMapReport {
    /// Whether the map was measured.
    pub ok: bool,
    /// Why not, if not.
    pub error: Option<String>,
    /// The grid's largest current, A.
    pub i_max_a: f64,
    /// The current bounding the rated-range error, A.
    pub i_rated_a: f64,
    /// d levels, A.
    pub i_d_a: Vec<f64>,
    /// q levels, A.
    pub i_q_a: Vec<f64>,
    /// Measured `psi_d[d][q]`, Wb.
    pub psi_d_wb: Vec<Vec<f64>>,
    /// Measured `psi_q[d][q]`, Wb.
    pub psi_q_wb: Vec<Vec<f64>>,
    /// The plant's `psi_d` at the nodes, Wb.
    pub true_psi_d_wb: Vec<Vec<f64>>,
    /// The plant's `psi_q` at the nodes, Wb.
    pub true_psi_q_wb: Vec<Vec<f64>>,
    /// Largest `(psi_d, psi_q)` error over the nodes with `|i| <= i_rated_a`, % of `|psi|`.
    pub max_error_rated_pct: Option<(f64, f64)>,
    /// The same over the whole grid.
    pub max_error_grid_pct: Option<(f64, f64)>,
    /// Largest `(psi_d, psi_q)` error of the map as it is used ([`symmetric_nodes`]
    /// (Self::symmetric_nodes): each node averaged with its mirror in `i_q`) over the nodes
    /// with `|i| <= i_rated_a`, % of `|psi|`; `None` on a grid not symmetric in `i_q`.
    pub max_error_rated_map_pct: Option<(f64, f64)>,
    /// The same over the whole grid.
    pub max_error_grid_map_pct: Option<(f64, f64)>,
    /// Time of the stop, s.
    pub stop_s: f64,
    /// Time of the re-alignment, s.
    pub realign_s: f64,
    /// Time of the probe, s.
    pub probe_s: f64,
    /// Largest rotor angle the probe followed, electrical rad.
    pub rotor_angle_max_rad: f64,
}

impl FluxMapReport {
    /// The flux-map step's time, s.
    pub fn time_s(&self) -> f64 {
        self.stop_s + self.realign_s + self.probe_s
    }

    /// The measured nodes made symmetric as a motor's map is, `psi_d` even and `psi_q` odd in
    /// `i_q`: each node averaged with its mirror `(i_d, -i_q)` (`psi_q` with its sign turned).
    /// The errors that do not follow the current's sign (the current sensors' offsets, the
    /// part of the dead-time voltage that does not) cancel, and the map gives equal and
    /// opposite torques at `+-i_q`, as foc's map tables require. `None` when the grid is not
    /// symmetric in `i_q` (within 1e-3 of its largest `|i_q|`) or nothing was measured.
    pub fn symmetric_nodes(&self) -> Option<(Nodes, Nodes)> {
        let nq = self.i_q_a.len();
        let tol = 1e-3 * self.i_q_a.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let symmetric = (0..nq).all(|k| (self.i_q_a[k] + self.i_q_a[nq - 1 - k]).abs() <= tol);
        if !self.ok || nq == 0 || !symmetric {
            return None;
        }
        let mirror = |rows: &Nodes, sign: f64| -> Nodes {
            rows.iter()
                .map(|r| {
                    (0..nq)
                        .map(|k| 0.5 * (r[k] + sign * r[nq - 1 - k]))
                        .collect()
                })
                .collect()
        };
        Some((mirror(&self.psi_d_wb, 1.0), mirror(&self.psi_q_wb, -1.0)))
    }

    /// Largest `(psi_d, psi_q)` errors of the nodes `pd`, `pq` against the plant's, % of
    /// `|psi|`: within the rated current and over the grid.
    fn largest_errors(&self, pd: &Nodes, pq: &Nodes) -> ((f64, f64), (f64, f64)) {
        let (mut rated, mut grid) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
        for (d, &id) in self.i_d_a.iter().enumerate() {
            for (q, &iq) in self.i_q_a.iter().enumerate() {
                let (td, tq) = (self.true_psi_d_wb[d][q], self.true_psi_q_wb[d][q]);
                let m = td.hypot(tq);
                let e = (
                    100.0 * (pd[d][q] - td).abs() / m,
                    100.0 * (pq[d][q] - tq).abs() / m,
                );
                grid = (grid.0.max(e.0), grid.1.max(e.1));
                if id.hypot(iq) <= self.i_rated_a * 1.0001 {
                    rated = (rated.0.max(e.0), rated.1.max(e.1));
                }
            }
        }
        (rated, grid)
    }

    fn fill_truth(&mut self, motor: &MotorModel) {
        let mag = motor.magnetics();
        let truth = |id: f64, iq: f64| match &mag {
            Some(s) => s.flux(
                (id, iq),
                (motor.psi_f_wb + motor.ld_h * id, motor.lq_h * iq),
            ),
            None => Some((motor.psi_f_wb + motor.ld_h * id, motor.lq_h * iq)),
        };
        for &id in &self.i_d_a {
            let (mut rd, mut rq) = (Vec::new(), Vec::new());
            for &iq in &self.i_q_a {
                let (td, tq) = truth(id, iq).unwrap_or((f64::NAN, f64::NAN));
                rd.push(td);
                rq.push(tq);
            }
            self.true_psi_d_wb.push(rd);
            self.true_psi_q_wb.push(rq);
        }
        let (rated, grid) = self.largest_errors(&self.psi_d_wb, &self.psi_q_wb);
        self.max_error_rated_pct = Some(rated);
        self.max_error_grid_pct = Some(grid);
        if let Some((pd, pq)) = self.symmetric_nodes() {
            let (rated, grid) = self.largest_errors(&pd, &pq);
            self.max_error_rated_map_pct = Some(rated);
            self.max_error_grid_map_pct = Some(grid);
        }
    }

    /// The map as a markdown table (`psi_d / psi_q` in mWb, rows `i_d`, columns `i_q`;
    /// the plant's values below in brackets) and the errors.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        if let Some(e) = &self.error {
            let _ = writeln!(s, "flux map FAILED: {e}");
            return s;
        }
        let _ = writeln!(
            s,
            "flux map: stop {:.3} s, re-align {:.3} s, probe {:.3} s (step {:.3} s); rotor \
             followed up to {:.3} rad (electrical)",
            self.stop_s,
            self.realign_s,
            self.probe_s,
            self.time_s(),
            self.rotor_angle_max_rad
        );
        if self.rotor_angle_max_rad > ROTOR_TURNED_RAD {
            let _ = writeln!(
                s,
                "WARNING: the rotor turned more than {ROTOR_TURNED_RAD} rad during the probe \
                 (light rotor against the q pulses' torque): the map is not valid"
            );
        }
        let _ = writeln!(
            s,
            "psi_d / psi_q (mWb), rows i_d, columns i_q; the plant's in brackets\n"
        );
        let _ = write!(s, "| i_d \\ i_q (A) |");
        for iq in &self.i_q_a {
            let _ = write!(s, " {iq:.2} |");
        }
        let _ = write!(s, "\n|---|");
        for _ in &self.i_q_a {
            let _ = write!(s, "---|");
        }
        let _ = writeln!(s);
        for (d, id) in self.i_d_a.iter().enumerate() {
            let _ = write!(s, "| {id:.2} |");
            for q in 0..self.i_q_a.len() {
                let _ = write!(
                    s,
                    " {:.2} / {:.2} ({:.2} / {:.2}) |",
                    1e3 * self.psi_d_wb[d][q],
                    1e3 * self.psi_q_wb[d][q],
                    1e3 * self.true_psi_d_wb[d][q],
                    1e3 * self.true_psi_q_wb[d][q]
                );
            }
            let _ = writeln!(s);
        }
        if let (Some(r), Some(g)) = (self.max_error_rated_pct, self.max_error_grid_pct) {
            let _ = writeln!(
                s,
                "\nlargest error (% of |psi|): psi_d {:.2}, psi_q {:.2} within {:.2} A; \
                 psi_d {:.2}, psi_q {:.2} over the grid (+-{:.2} A)",
                r.0, r.1, self.i_rated_a, g.0, g.1, self.i_max_a
            );
        }
        if let (Some(r), Some(g)) = (self.max_error_rated_map_pct, self.max_error_grid_map_pct) {
            let _ = writeln!(
                s,
                "the map as used (each node averaged with its mirror in i_q): psi_d {:.2}, \
                 psi_q {:.2} within {:.2} A; psi_d {:.2}, psi_q {:.2} over the grid",
                r.0, r.1, self.i_rated_a, g.0, g.1
            );
        }
        s
    }

    /// Draws `psi_d(i_d)` (one curve per `i_q`) and `psi_q(i_q)` (one per `i_d`), measured
    /// (solid, marked) and the plant's (dashed), to `path`.
    pub fn write_svg(&self, path: &Path, title: &str) -> Result<(), SimError> {
        crate::output::file::write_whole(path, |tmp| {
            self.draw(tmp, title)
                .map_err(|e| format!("cannot draw the plot: {e}"))
        })
    }

    fn draw(&self, path: &Path, title: &str) -> Result<(), Box<dyn std::error::Error>> {
        let root = SVGBackend::new(path, (1200, 560)).into_drawing_area();
        root.fill(&WHITE)?;
        let (head, body) = root.split_vertically(34);
        head.draw(&Text::new(title, (10, 8), ("sans-serif", 18)))?;
        let (left, right) = body.split_horizontally(600);
        let nd = self.i_d_a.len();
        let nq = self.i_q_a.len();
        // psi_d against i_d, a curve per i_q level; psi_q against i_q, a curve per i_d.
        let d_curves: Vec<Curve> = (0..nq)
            .map(|q| {
                let m = (0..nd).map(|d| (self.i_d_a[d], 1e3 * self.psi_d_wb[d][q]));
                let t = (0..nd).map(|d| (self.i_d_a[d], 1e3 * self.true_psi_d_wb[d][q]));
                (self.i_q_a[q], m.collect(), t.collect())
            })
            .collect();
        let q_curves: Vec<Curve> = (0..nd)
            .map(|d| {
                let m = (0..nq).map(|q| (self.i_q_a[q], 1e3 * self.psi_q_wb[d][q]));
                let t = (0..nq).map(|q| (self.i_q_a[q], 1e3 * self.true_psi_q_wb[d][q]));
                (self.i_d_a[d], m.collect(), t.collect())
            })
            .collect();
        panel(
            &left,
            "psi_d(i_d), a curve per i_q",
            "i_d (A)",
            "psi_d (mWb)",
            "i_q",
            &d_curves,
        )?;
        panel(
            &right,
            "psi_q(i_q), a curve per i_d",
            "i_q (A)",
            "psi_q (mWb)",
            "i_d",
            &q_curves,
        )?;
        root.present()?;
        Ok(())
    }
}

/// A curve's level, its measured and its true points.
type Curve = (f64, Vec<(f64, f64)>, Vec<(f64, f64)>);
type Curves = [Curve];

fn panel(
    area: &DrawingArea<SVGBackend<'_>, plotters::coord::Shift>,
    caption: &str,
    x_desc: &str,
    y_desc: &str,
    param: &str,
    curves: &Curves,
) -> Result<(), Box<dyn std::error::Error>> {
    let all = || curves.iter().flat_map(|c| c.1.iter().chain(c.2.iter()));
    let fin = |v: f64| v.is_finite();
    let (x0, x1) = all()
        .map(|p| p.0)
        .filter(|v| fin(*v))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let (y0, y1) = all()
        .map(|p| p.1)
        .filter(|v| fin(*v))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    let pad = ((y1 - y0) * 0.05).max(1e-3);
    let mut c = ChartBuilder::on(area)
        .caption(caption, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(34)
        .y_label_area_size(60)
        .build_cartesian_2d(x0..x1, (y0 - pad)..(y1 + pad))?;
    c.configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .light_line_style(WHITE.mix(0.0))
        .draw()?;
    for (k, (level, meas, truth)) in curves.iter().enumerate() {
        let color = Palette99::pick(k).to_rgba();
        let st = ShapeStyle::from(color).stroke_width(2);
        c.draw_series(LineSeries::new(meas.iter().copied(), st))?
            .label(format!("{param} = {level:.2} A"))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], st));
        c.draw_series(meas.iter().map(|&p| Circle::new(p, 3, color.filled())))?;
        let thin = ShapeStyle::from(color.mix(0.6)).stroke_width(1);
        c.draw_series(DashedLineSeries::new(
            truth.iter().copied().filter(|p| fin(p.1)),
            6,
            4,
            thin,
        ))?;
    }
    c.configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}
