//! Self-commissioning on the simulated reference motors (`pmsm_sim::identify`).

use pmsm_sim::identify::{IdentifyOptions, IdentifyReport, identify, table};
use pmsm_sim::scenario::Scenario;

fn preset(name: &str) -> Scenario {
    Scenario::preset(name).unwrap_or_else(|e| panic!("{e}"))
}

fn run(sc: &Scenario, seed: Option<u64>) -> IdentifyReport {
    let r = identify(
        sc,
        &IdentifyOptions {
            seed,
            ..IdentifyOptions::default()
        },
    )
    .unwrap_or_else(|e| panic!("{e}"));
    println!("{}", table(&r));
    r
}

#[test]
fn reference_motors() {
    for name in ["default", "industrial-2k2", "drone", "servo-harsh"] {
        run(&preset(name), None);
    }
}
