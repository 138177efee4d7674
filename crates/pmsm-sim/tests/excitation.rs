//! The d-axis excitation rows of the suite (short run, seed 1): told `Ls` +-20 %, the default
//! EKF handed the excitation estimator's `Ls` meets the goals (module
//! `pmsm_sim::analysis::suite::excitation`).

use pmsm_sim::analysis::suite::excitation::excitation_rows;
use pmsm_sim::analysis::suite::{SuiteMotor, SuiteOptions};

#[test]
fn excitation_rows_meet_their_goals() {
    let opts = SuiteOptions {
        short: true,
        ..SuiteOptions::default()
    };
    let report = excitation_rows(&opts, &SuiteMotor::SURFACE).unwrap();
    println!("{}", report.to_markdown());
    assert_eq!(report.rows.len(), 3 * 3 * 4);
    for c in &report.checks {
        assert!(c.pass, "{c:?}");
    }
}
