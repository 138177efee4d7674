//! The datasheet as markdown (`datasheet.md`, figures as SVG files next to it) and as one
//! self-contained HTML page (the same text, the figures inline, no external resource).
//!
//! Both come from one list of [`Block`]s per section, so they say the same thing.

use super::angle::SETTLE_S;
use super::plots::{BAD, Figure, GOOD, PALETTE, Series, svg};
use super::sections::IDENTIFIED;
use super::start::{
    HFI_END_S, POLARITY_TOLERANCE_DEG, STARTUP_END_S, STARTUP_SPEED_FRAC, wilson95_pct,
};
use super::{Datasheet, SECTION_TITLES, m4f, page};

/// A piece of a section.
#[derive(Clone, Debug)]
pub enum Block {
    /// A paragraph; `` `code` `` spans allowed.
    Para(String),
    /// A table: header and rows (cells may hold `` `code` ``).
    Table(Vec<String>, Vec<Vec<String>>),
    /// A command line.
    Code(String),
    /// A figure.
    Figure(Figure),
}

/// One section: its title and blocks.
#[derive(Clone, Debug)]
pub struct Section {
    /// Heading.
    pub title: &'static str,
    /// Content.
    pub blocks: Vec<Block>,
}

/// The rendered datasheet.
#[derive(Clone, Debug)]
pub struct Rendered {
    /// `datasheet.md`.
    pub markdown: String,
    /// `datasheet.html`.
    pub html: String,
    /// `(file name, SVG text)` of each figure.
    pub figures: Vec<(String, String)>,
}

/// The command that rebuilds this datasheet.
pub fn command(d: &Datasheet) -> String {
    format!(
        "pmsm-sim datasheet --motor {} --seed {}{} --out DIR",
        d.motor.name(),
        d.seed,
        if d.quick { " --quick" } else { "" }
    )
}

fn f(x: f64, digits: usize) -> String {
    if x.is_finite() {
        format!("{x:.digits$}")
    } else {
        "-".into()
    }
}

/// `k of n` with Wilson's 95 % interval of the rate.
fn rate(k: usize, n: usize) -> String {
    let (lo, hi) = wilson95_pct(k, n);
    format!("{k} of {n}; 95 % interval {lo:.1}-{hi:.1} %")
}

fn yes(b: bool) -> String {
    if b { "yes" } else { "no" }.into()
}

/// The sections of `d`.
pub fn sections(d: &Datasheet) -> Vec<Section> {
    vec![
        angle(d),
        low_speed(d),
        startup(d),
        hfi(d),
        identify(d),
        monte_carlo(d),
        m4f_section(d),
    ]
}

fn angle(d: &Datasheet) -> Section {
    let g = &d.angle;
    let mut blocks = vec![Block::Para(format!(
        "Method: one closed-loop run per cell of {} speeds x {} loads (foc sensorless from standstill, \
         the low-speed table's run with the load set to the cell's level, the reference ramped to the \
         test speed by 1.5 s, {SETTLE_S} s of settling); the RMS of `wrap(theta_hat - theta)` of foc's \
         observer over a {} s window, noise seed {} (the preset's). A cell where the loop did not stay \
         closed is marked lost and left out of the figure.",
        g.speeds_pct.len(),
        g.loads_pct.len(),
        g.window_s,
        g.seed
    ))];
    let series = g
        .loads_pct
        .iter()
        .enumerate()
        .map(|(k, &l)| Series {
            name: format!("{l} % rated torque"),
            color: PALETTE[k % PALETTE.len()],
            // x: the speed's place in the list (the low speeds would crowd a linear axis).
            points: g
                .at_load(l)
                .enumerate()
                .filter(|(_, c)| c.held)
                .map(|(k, c)| (k as f64, c.angle_error_rms_deg))
                .collect(),
            line: true,
        })
        .collect();
    blocks.push(Block::Figure(Figure {
        file: "fig1-angle-error.svg".into(),
        title: format!("{}: angle error of foc's observer", d.motor.name()),
        x_label: "speed, % of rated (the speeds tested, evenly spaced)".into(),
        y_label: "RMS angle error, deg el.".into(),
        series,
        x_categories: g.speeds_pct.iter().map(|s| s.to_string()).collect(),
        h_lines: vec![],
    }));
    let mut header = vec!["load \\ speed (% rated)".to_string()];
    header.extend(g.speeds_pct.iter().map(|s| format!("{s}")));
    let rows = g
        .loads_pct
        .iter()
        .map(|&l| {
            let mut row = vec![format!("{l} %")];
            row.extend(g.at_load(l).map(|c| {
                if c.held {
                    f(c.angle_error_rms_deg, 2)
                } else {
                    format!("lost ({:.0} % closed)", c.closed_loop_pct)
                }
            }));
            row
        })
        .collect();
    blocks.push(Block::Table(header, rows));
    let result = match g.worst_held() {
        Some(w) => format!(
            "Result: RMS angle error (deg el.) per cell above; the largest where the loop held is {} deg \
             at {} % speed and {} % torque, from 10 % of rated speed up at most {} deg; {} of {} cells \
             lost the loop. (The simulator's f64 EKF, riding along on the same samples, is in \
             `datasheet.json`, `ekf_angle_error_rms_deg`.)",
            f(w.angle_error_rms_deg, 2),
            w.speed_pct,
            w.load_pct,
            f(
                g.cells
                    .iter()
                    .filter(|c| c.held && c.speed_pct >= 10.0)
                    .fold(f64::NAN, |m, c| m.max(c.angle_error_rms_deg)),
                2
            ),
            g.cells.iter().filter(|c| !c.held).count(),
            g.cells.len()
        ),
        None => "Result: the loop held in no cell.".into(),
    };
    blocks.push(Block::Para(result));
    blocks.push(Block::Code(command(d)));
    Section {
        title: SECTION_TITLES[0],
        blocks,
    }
}

fn low_speed(d: &Datasheet) -> Section {
    let r = &d.low_speed;
    let hold = d.sizes.low_speed_hold_s;
    let mut blocks = vec![Block::Para(format!(
        "Method: the low-speed table's run (`pmsm-sim low-speed`) at {} % of rated speed: foc sensorless \
         started at 20 % of rated speed, the rated torque as an active load from 0.8 s, the reference \
         down to the test speed by 1.5 s, held {hold} s; a speed passes with closed loop in every period \
         of the hold, no fault and the mean speed within 25 % of the test speed. The lowest speed is the \
         lowest down to which every listed speed passes. Deterministic (the preset's noise seed).",
        r.runs
            .iter()
            .map(|x| x.speed_pct.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    ))];
    let ratio = |x: &crate::analysis::low_speed::LowSpeedRun| x.mean_speed_rpm / x.speed_rpm;
    blocks.push(Block::Figure(Figure {
        file: "fig2-low-speed.svg".into(),
        title: format!("{}: held at low speed under rated torque", d.motor.name()),
        x_label: "test speed, % of rated".into(),
        y_label: "mean speed / test speed".into(),
        series: vec![
            Series {
                name: "passed".into(),
                color: GOOD,
                points: r
                    .runs
                    .iter()
                    .filter(|x| x.pass)
                    .map(|x| (x.speed_pct, ratio(x)))
                    .collect(),
                line: false,
            },
            Series {
                name: "failed".into(),
                color: BAD,
                points: r
                    .runs
                    .iter()
                    .filter(|x| !x.pass)
                    .map(|x| (x.speed_pct, ratio(x).clamp(-1.0, 3.0)))
                    .collect(),
                line: false,
            },
        ],
        x_categories: vec![],
        h_lines: vec![(0.75, "-25 %".into()), (1.25, "+25 %".into())],
    }));
    let rows = r
        .runs
        .iter()
        .map(|x| {
            vec![
                format!("{}", x.speed_pct),
                f(x.speed_rpm, 1),
                yes(x.pass),
                f(x.closed_loop_pct, 1),
                f(x.mean_speed_rpm, 2),
                f(x.current_ratio, 3),
                f(x.angle_error_rms_deg, 2),
                x.fault.clone().unwrap_or_else(|| "none".into()),
            ]
        })
        .collect();
    blocks.push(Block::Table(
        [
            "speed (% rated)",
            "(rpm)",
            "pass",
            "closed loop (% hold)",
            "mean speed (rpm)",
            "RMS current / rated-torque current",
            "angle error RMS (deg)",
            "fault",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    ));
    blocks.push(Block::Para(match &r.lowest {
        Some(l) => format!(
            "Result: lowest closed-loop speed at rated torque **{} % of rated ({:.1} rpm)**{}, drawing {:.3} x \
             the rated-torque current ({:.2} A).",
            l.speed_pct,
            l.speed_rpm,
            if r.runs.last().is_some_and(|x| x.speed_pct == l.speed_pct) {
                " (the lowest speed tried: the limit may lie lower)"
            } else {
                ""
            },
            l.current_ratio,
            r.rated_torque_current_a
        ),
        None => "Result: no listed speed held rated torque in closed loop.".into(),
    }));
    blocks.push(Block::Code(format!(
        "pmsm-sim low-speed --motor {} --hold {hold}",
        d.motor.name()
    )));
    Section {
        title: SECTION_TITLES[1],
        blocks,
    }
}

fn startup(d: &Datasheet) -> Section {
    let s = &d.startup;
    let mut blocks = vec![Block::Para(format!(
        "Method: {} sensorless start-ups (foc's start-up defaults) from rest at a rotor angle drawn \
         uniformly in [-180, 180) deg el., each with a noise seed of its own (both drawn from seed {}); \
         no load but the preset's friction, the reference 0 -> {} % of rated speed over 0.5 s, runs of \
         {STARTUP_END_S} s. Success: no fault, the loop closed and never left, the final speed within 25 % \
         of the reference. Backward speed: the largest negative speed before the hand-over.",
        s.runs.len(),
        d.seed,
        100.0 * STARTUP_SPEED_FRAC
    ))];
    let pts = |ok: bool| {
        s.runs
            .iter()
            .filter(|r| r.success == ok)
            .map(|r| (r.theta0_deg, r.backward_pct))
            .collect()
    };
    blocks.push(Block::Figure(Figure {
        file: "fig3-startup.svg".into(),
        title: format!("{}: start-up from random rotor angles", d.motor.name()),
        x_label: "initial rotor angle, deg el.".into(),
        y_label: "largest backward speed, % of rated".into(),
        series: vec![
            Series {
                name: "success".into(),
                color: GOOD,
                points: pts(true),
                line: false,
            },
            Series {
                name: "failure".into(),
                color: BAD,
                points: pts(false),
                line: false,
            },
        ],
        x_categories: vec![],
        h_lines: vec![],
    }));
    let failures: Vec<String> = s
        .runs
        .iter()
        .filter_map(|r| {
            r.failure
                .as_ref()
                .map(|why| format!("{:.1} deg, seed {}: {why}", r.theta0_deg, r.seed))
        })
        .take(5)
        .collect();
    let worst = s.worst_backward();
    blocks.push(Block::Para(format!(
        "Result: success **{:.1} %** ({}); worst backward speed **{} % of rated** (from {} deg el.); \
         latest closing of the loop {} s.{}",
        s.success_pct(),
        rate(s.runs.iter().filter(|r| r.success).count(), s.runs.len()),
        worst.map_or("-".into(), |w| f(w.backward_pct, 2)),
        worst.map_or("-".into(), |w| f(w.theta0_deg, 1)),
        s.latest_closed_loop_s().map_or("-".into(), |t| f(t, 3)),
        if failures.is_empty() {
            String::new()
        } else {
            format!(" Failures (first 5): {}.", failures.join("; "))
        }
    )));
    blocks.push(Block::Code(command(d)));
    Section {
        title: SECTION_TITLES[2],
        blocks,
    }
}

fn hfi(d: &Datasheet) -> Section {
    let Some(h) = &d.hfi else {
        return Section {
            title: SECTION_TITLES[3],
            blocks: vec![Block::Para(format!(
                "Not applicable: {} is a surface motor (Ld = Lq), which has no saliency for HFI to \
                 track; its start is the sensorless start of section 3. The section is measured on the \
                 interior motors (`--motor industrial_ipm`, `--motor traction_ipm`).",
                d.motor.name()
            ))],
        };
    };
    let mut blocks = vec![Block::Para(format!(
        "Method: {} standstill starts with HFI on (foc's defaults for the preset's sensor noise), the \
         rotor at a uniform random angle, a noise seed per run (drawn from seed {}), {HFI_END_S} s each, \
         the plant with d-axis saturation (Ld 20 % lower at the current limit). Right: the control angle \
         within {POLARITY_TOLERANCE_DEG} deg el. of the rotor from 20 ms after HFI tracks to the end.",
        h.runs.len(),
        d.seed
    ))];
    let pts = |ok: bool| {
        h.runs
            .iter()
            .filter(|r| r.right == ok)
            .map(|r| (r.theta0_deg, r.max_error_deg.min(200.0)))
            .collect()
    };
    blocks.push(Block::Figure(Figure {
        file: "fig4-hfi-polarity.svg".into(),
        title: format!("{}: HFI polarity from random rotor angles", d.motor.name()),
        x_label: "initial rotor angle, deg el.".into(),
        y_label: "largest angle error after the decision, deg el.".into(),
        series: vec![
            Series {
                name: "right".into(),
                color: GOOD,
                points: pts(true),
                line: false,
            },
            Series {
                name: "wrong".into(),
                color: BAD,
                points: pts(false),
                line: false,
            },
        ],
        x_categories: vec![],
        h_lines: vec![(POLARITY_TOLERANCE_DEG, "tolerance".into())],
    }));
    let worst = h
        .runs
        .iter()
        .map(|r| r.max_error_deg)
        .fold(
            0.0_f64,
            |m, x| if x.is_nan() { f64::INFINITY } else { m.max(x) },
        );
    blocks.push(Block::Para(format!(
        "Result: polarity right in **{:.1} %** of starts ({}); largest angle error after the \
         decision {} deg el.; first guess flipped in {} starts.",
        h.right_pct(),
        rate(h.runs.iter().filter(|r| r.right).count(), h.runs.len()),
        f(worst, 2),
        h.runs.iter().filter(|r| r.flipped).count()
    )));
    blocks.push(Block::Code(command(d)));
    Section {
        title: SECTION_TITLES[3],
        blocks,
    }
}

fn identify(d: &Datasheet) -> Section {
    let s = &d.identify;
    let mut blocks = vec![Block::Para(format!(
        "Method: the self-commissioning sequence (`pmsm-sim identify`: standstill tests, then a short \
         spin) on the preset `{}`, once per noise seed {}..={}; the error of each identified parameter \
         against the plant's, %, and the sequence's simulated time.",
        s.preset,
        d.seed + 1,
        d.seed + s.runs.len() as u64
    ))];
    let names: Vec<String> = IDENTIFIED.iter().map(|(n, _)| n.to_string()).collect();
    let series = vec![Series {
        name: format!("one point per seed ({})", s.runs.len()),
        color: PALETTE[0],
        points: s
            .runs
            .iter()
            .flat_map(|r| {
                IDENTIFIED.iter().enumerate().filter_map(|(i, (_, get))| {
                    r.errors_pct.as_ref().and_then(get).map(|e| (i as f64, e))
                })
            })
            .collect(),
        line: false,
    }];
    blocks.push(Block::Figure(Figure {
        file: "fig5-identification.svg".into(),
        title: format!("{}: identification error per parameter", d.motor.name()),
        x_label: "parameter".into(),
        y_label: "error, %".into(),
        series,
        x_categories: names,
        h_lines: vec![(0.0, String::new())],
    }));
    let rows = s
        .summary()
        .into_iter()
        .map(|(name, st)| match st {
            Some((mean, max)) => vec![name.to_string(), f(mean, 2), f(max, 2)],
            None => vec![name.to_string(), "not identified".into(), "-".into()],
        })
        .collect();
    blocks.push(Block::Table(
        ["parameter", "mean abs. error (%)", "largest abs. error (%)"]
            .map(String::from)
            .to_vec(),
        rows,
    ));
    let failed: Vec<String> = s
        .runs
        .iter()
        .filter(|r| !r.ok)
        .map(|r| {
            format!(
                "seed {}: {}",
                r.seed,
                r.error.as_deref().unwrap_or("failed")
            )
        })
        .collect();
    blocks.push(Block::Para(format!(
        "Result: {} of {} sequences finished ({:.0} %); the longest took **{} s** (simulated).{}",
        s.runs.iter().filter(|r| r.ok).count(),
        s.runs.len(),
        s.ok_pct(),
        f(s.longest_s(), 2),
        if failed.is_empty() {
            String::new()
        } else {
            format!(" Failed: {}.", failed.join("; "))
        }
    )));
    blocks.push(Block::Code(format!(
        "pmsm-sim identify {} --seed {}",
        s.preset,
        d.seed + 1
    )));
    Section {
        title: SECTION_TITLES[4],
        blocks,
    }
}

fn monte_carlo(d: &Datasheet) -> Section {
    let m = &d.monte_carlo;
    let mut blocks = vec![Block::Para(format!(
        "Method: {} runs of the preset `{}`'s own job (a sweep plan, seed {}), each with the drive's model \
         off the plant's by uniform draws: Rs +-30 %, Ld and Lq +-20 % each, psi_f +-10 % (what foc and \
         the observers are told), the inverter's dead time 0-2 us (foc told it, as in the presets) and the \
         current sensors' noise x0.5-x3. A run lost the lock when it left closed loop, tripped, stopped \
         early or could not run. The plan is written as `montecarlo-plan.toml`; `pmsm-sim sweep` runs \
         the same runs.",
        m.runs.len(),
        m.preset,
        m.seed
    ))];
    let pts = |lost: bool| {
        m.runs
            .iter()
            .filter(|r| r.lost == lost)
            .map(|r| (r.rs_error_pct, r.psi_f_error_pct))
            .collect()
    };
    blocks.push(Block::Figure(Figure {
        file: "fig6-lock-loss.svg".into(),
        title: format!("{}: lock loss under parameter error", d.motor.name()),
        x_label: "Rs told - true, %".into(),
        y_label: "psi_f told - true, %".into(),
        series: vec![
            Series {
                name: "kept the lock".into(),
                color: GOOD,
                points: pts(false),
                line: false,
            },
            Series {
                name: "lost the lock".into(),
                color: BAD,
                points: pts(true),
                line: false,
            },
        ],
        x_categories: vec![],
        h_lines: vec![],
    }));
    let mut reasons: Vec<(String, usize)> = Vec::new();
    for r in m.runs.iter().filter_map(|r| r.reason.as_ref()) {
        let kind = r.split(" at ").next().unwrap_or(r).to_string();
        match reasons.iter_mut().find(|(k, _)| *k == kind) {
            Some((_, n)) => *n += 1,
            None => reasons.push((kind, 1)),
        }
    }
    reasons.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let angles: Vec<f64> = m
        .runs
        .iter()
        .filter(|r| !r.lost)
        .filter_map(|r| r.angle_error_rms_deg)
        .collect();
    let median = {
        let mut a = angles.clone();
        a.sort_by(f64::total_cmp);
        a.get(a.len() / 2).copied().unwrap_or(f64::NAN)
    };
    blocks.push(Block::Para(format!(
        "Result: lock lost in **{:.1} %** of runs ({}){}; over the runs that kept it, median closed-loop \
         RMS angle error of foc's observer {} deg el. (largest {}).",
        m.lost_pct(),
        rate(m.runs.iter().filter(|r| r.lost).count(), m.runs.len()),
        if reasons.is_empty() {
            String::new()
        } else {
            format!(
                ": {}",
                reasons
                    .iter()
                    .map(|(k, n)| format!("{k} ({n})"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
        f(median, 2),
        f(angles.iter().fold(f64::NAN, |a, &b| a.max(b)), 2)
    )));
    blocks.push(Block::Code(
        "pmsm-sim sweep DIR/montecarlo-plan.toml --out DIR/montecarlo".into(),
    ));
    Section {
        title: SECTION_TITLES[5],
        blocks,
    }
}

fn m4f_section(d: &Datasheet) -> Section {
    let looked = d.m4f.path.clone().unwrap_or_default();
    let Some(c) = &d.m4f.counts else {
        return Section {
            title: SECTION_TITLES[6],
            blocks: vec![
                Block::Para(format!(
                    "Not measured: no counts file at `{looked}`. The counts come from the firmware run under \
                     QEMU (mps2-an386, `-icount`), which writes that file; then rebuild the datasheet \
                     (or give the file with `--m4f-counts FILE`)."
                )),
                Block::Code(m4f::COMMAND.into()),
            ],
        };
    };
    let rows = c
        .instructions_per_call
        .iter()
        .map(|(k, v)| vec![format!("`{k}`"), v.to_string()])
        .collect();
    let mut blocks = vec![
        Block::Para(format!(
            "Method: the firmware example (crates/foc-firmware, release, thumbv7em-none-eabihf) run under \
             QEMU's {} with `-icount shift=10`; the firmware counts the instructions of each routine with \
             the SysTick (instructions, not cycles: wait states and pipeline stalls are not counted). The \
             firmware runs its own built-in motor: the counts depend on the code path (`foc_tick` surface \
             motor in closed loop, `foc_tick_ipm` interior, `foc_tick_hfi` with HFI), not on the motor's \
             values. Read from `{looked}` ({}).",
            c.machine, c.qemu
        )),
        Block::Table(
            ["routine", "instructions per call"]
                .map(String::from)
                .to_vec(),
            rows,
        ),
    ];
    let mem: Vec<String> = [("flash", c.flash_bytes), ("static RAM", c.ram_bytes)]
        .iter()
        .filter_map(|(n, b)| b.map(|b| format!("{n} {b} bytes")))
        .collect();
    let ticks: Vec<String> = ["foc_tick", "foc_tick_ipm", "foc_tick_hfi"]
        .iter()
        .filter_map(|k| {
            c.instructions_per_call
                .get(*k)
                .map(|n| format!("`{k}` **{n} instructions per call**"))
        })
        .collect();
    blocks.push(Block::Para(format!(
        "Result: {}{}.",
        ticks.join(", "),
        if mem.is_empty() {
            String::new()
        } else {
            format!("; the firmware image: {}", mem.join(", "))
        }
    )));
    blocks.push(Block::Code(m4f::COMMAND.into()));
    Section {
        title: SECTION_TITLES[6],
        blocks,
    }
}

/// The header lines: motor, drive, sizes.
pub(super) fn intro(d: &Datasheet) -> String {
    format!(
        "Motor `{}` on the drive of the simulator preset `{}` (rated {} rpm, {} N m), foc sensorless. \
         Seed {}{}. Every figure below comes from a sweep this command ran; each section states its \
         method, its result and the command that reproduces it.",
        d.motor.name(),
        d.preset,
        d.rated_speed_rpm,
        d.rated_torque_nm,
        d.seed,
        if d.quick {
            "; **quick** (small n, short windows: a first look, not the datasheet)"
        } else {
            ""
        }
    )
}

/// Renders `d`: markdown, HTML and the figures' SVG.
pub fn render(d: &Datasheet) -> Result<Rendered, String> {
    let secs = sections(d);
    let mut figures = Vec::new();
    for sec in &secs {
        for b in &sec.blocks {
            if let Block::Figure(fig) = b {
                figures.push((fig.file.clone(), svg(fig)?));
            }
        }
    }
    Ok(Rendered {
        markdown: page::markdown(d, &secs),
        html: page::html(d, &secs, &figures),
        figures,
    })
}
