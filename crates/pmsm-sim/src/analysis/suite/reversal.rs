//! Mismatch rows through a reversal under rated load at 10 % rated speed (module docs of
//! [`super`], "Mismatch through a reversal").
//!
//! The run of one surface motor: the observers converge at 50 % rated speed from the
//! unknown start, the speed falls to +10 % of rated, the rated load torque steps on (a
//! constant torque: braking at +10 %, driving the rotor at -10 %, where the drive generates),
//! and after a settling time the speed reverses to -10 % of rated and holds there. The window
//! starts [`SETTLE_S`] after the load step and ends with the run: it holds the loaded
//! +10 % phase, the reversal through zero and the loaded -10 % phase. Through zero speed the
//! back-EMF vanishes and the told resistance sets what the observer reads from the voltage;
//! the tracked `psi_f` and `Rs` are held there (consider states) and must carry over.

use super::*;

/// Time from the load step to the start of the scored window, s.
pub const SETTLE_S: f64 = 0.25;

/// The condition of these rows (as [`MismatchRow::condition`]).
pub const CONDITION: &str = "10 %, reversal under rated load";

impl Plan {
    /// The reversal run (module [`self`]): `short` shortens the convergence phase and the
    /// holds.
    pub(super) fn reversal(short: bool) -> Self {
        let (conv, hold) = if short { (0.3, 0.2) } else { (0.5, 0.35) };
        let at_10 = conv + 0.2;
        let step_s = at_10 + 0.1;
        let w0 = step_s + SETTLE_S;
        let rev0 = w0 + 0.1;
        let rev1 = rev0 + 0.2;
        let end = rev1 + hold;
        Self {
            conv_end_s: conv,
            windows: vec![(CONDITION, 0.1, true, w0, end)],
            step_s,
            step_end_s: w0,
            duration_s: end,
            speed_points: vec![
                (0.0, 0.5),
                (conv, 0.5),
                (at_10, 0.1),
                (rev0, 0.1),
                (rev1, -0.1),
            ],
        }
    }
}

/// The reversal rows of one surface motor: the default EKF and the baseline told each case
/// of [`MISMATCHES`] (the same observers as the main run's mismatch rows).
pub(super) fn reversal_rows(
    motor: SuiteMotor,
    opts: &SuiteOptions,
) -> Result<Vec<MismatchRow>, SimError> {
    let plan = Plan::reversal(opts.short);
    let mut sc = scenario_with(motor, opts, &plan, INITIAL_ANGLE_RAD);
    sc.name = format!("suite-{}-reversal", motor.name());
    let kinds = [ObserverKind::DefaultEkf, ObserverKind::FluxBaseline];
    let (scored, _, _) = run_scored_with(&sc, &plan, &kinds, true, Vec::new())?;
    let truth = (sc.motor.psi_f_wb, sc.motor.rs_ohm);
    let mut rows = Vec::new();
    // The default EKF and the baseline told the truth, for reference (the case [`EXACT`]).
    for s in scored.iter().filter(|s| s.told.is_none()) {
        rows.extend(rows_of(motor, &plan, s, EXACT, truth));
    }
    rows.extend(mismatch_rows(motor, &plan, &scored, truth));
    Ok(rows)
}

/// The case name of the rows of the EKF told the true motor.
pub const EXACT: &str = "exact";

/// The mismatch rows of the observers told a wrong motor over the plan's windows, with the
/// mean tracked `psi_f` and `Rs` against the `truth` (`(psi_f, Rs)`).
pub(super) fn mismatch_rows(
    motor: SuiteMotor,
    plan: &Plan,
    scored: &[Scored],
    truth: (f64, f64),
) -> Vec<MismatchRow> {
    scored
        .iter()
        .filter_map(|s| s.told.map(|i| (s, MISMATCHES[i].name)))
        .flat_map(|(s, case)| rows_of(motor, plan, s, case, truth))
        .collect()
}

/// The rows of one scored observer over the plan's windows.
fn rows_of(
    motor: SuiteMotor,
    plan: &Plan,
    s: &Scored,
    case: &'static str,
    truth: (f64, f64),
) -> Vec<MismatchRow> {
    let ekf = s.kind == ObserverKind::DefaultEkf;
    s.windows
        .iter()
        .zip(&plan.windows)
        .zip(&s.param_sums)
        .map(|((sums, w), ps)| {
            let n = sums.n as f64;
            MismatchRow {
                observer: s.kind,
                motor,
                case,
                condition: w.0.to_string(),
                speed_fraction: w.1,
                samples: sums.n,
                angle_rms_deg: sums.angle_rms_deg(),
                angle_max_deg: sums.max_e,
                angle_mean_deg: sums.angle_mean_deg(),
                psi_f_error_pct: ekf.then(|| 100.0 * (ps[0] / n / truth.0 - 1.0)),
                rs_error_pct: 100.0 * (ps[1] / n / truth.1 - 1.0),
                tracking_pct: sums.tracking_pct(),
                tracking_while_lost: sums.tracking_lost,
                run_tracking_while_lost: s.run.tracking_lost,
            }
        })
        .collect()
}
