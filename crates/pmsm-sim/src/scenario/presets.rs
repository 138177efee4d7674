//! The built-in scenarios: the files of `crates/pmsm-sim/scenarios/`, embedded in the binary.

/// Built-in scenarios `(name, TOML text)`; the first is the default.
pub const PRESETS: &[(&str, &str)] = &[
    ("default", include_str!("../../scenarios/default.toml")),
    (
        "servo-sensored",
        include_str!("../../scenarios/servo-sensored.toml"),
    ),
    (
        "servo-ideal",
        include_str!("../../scenarios/servo-ideal.toml"),
    ),
    (
        "servo-harsh",
        include_str!("../../scenarios/servo-harsh.toml"),
    ),
    (
        "industrial-2k2",
        include_str!("../../scenarios/industrial-2k2.toml"),
    ),
    ("drone", include_str!("../../scenarios/drone.toml")),
    (
        "industrial-ipm",
        include_str!("../../scenarios/industrial-ipm.toml"),
    ),
    (
        "traction-ipm",
        include_str!("../../scenarios/traction-ipm.toml"),
    ),
    (
        "industrial-ipm-fw",
        include_str!("../../scenarios/industrial-ipm-fw.toml"),
    ),
    (
        "traction-ipm-fw",
        include_str!("../../scenarios/traction-ipm-fw.toml"),
    ),
    ("servo-fw", include_str!("../../scenarios/servo-fw.toml")),
    (
        "motor-heating",
        include_str!("../../scenarios/motor-heating.toml"),
    ),
];
