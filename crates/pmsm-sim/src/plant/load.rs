//! Time profiles (speed reference, load tables) and load-torque models.

use serde::{Deserialize, Serialize};

use crate::error::FieldError;

/// How a [`Profile`] is read between its points.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Interpolation {
    /// Linear between points (ramps).
    #[default]
    Linear,
    /// The value of the last point at or before the time (steps).
    Step,
}

/// A time profile given by points `(t_s, value)`, times non-decreasing. Before the first point
/// it holds the first value, after the last the last value; with no point it is zero.
///
/// In TOML: `{ interpolation = "linear", points = [[0.0, 0.0], [0.3, 2000.0]] }`.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Profile {
    /// Reading between points (default linear).
    #[serde(default)]
    pub interpolation: Interpolation,
    /// The points `[time s, value]`.
    pub points: Vec<(f64, f64)>,
}

impl Profile {
    /// A piecewise-linear profile.
    pub fn linear(points: Vec<(f64, f64)>) -> Self {
        Self {
            points,
            interpolation: Interpolation::Linear,
        }
    }

    /// A piecewise-constant profile.
    pub fn steps(points: Vec<(f64, f64)>) -> Self {
        Self {
            points,
            interpolation: Interpolation::Step,
        }
    }

    /// The value at `t_s`.
    pub fn at(&self, t_s: f64) -> f64 {
        ProfileRef {
            interpolation: self.interpolation,
            points: &self.points,
        }
        .at(t_s)
    }

    /// Checks that every number is finite and times do not decrease; errors name
    /// `field.points[i]`.
    pub fn validate(&self, field: &str) -> Result<(), FieldError> {
        for (i, &(t, v)) in self.points.iter().enumerate() {
            if !t.is_finite() || !v.is_finite() {
                return Err(FieldError::new(
                    format!("{field}.points[{i}]"),
                    format!("must be finite, is [{t}, {v}]"),
                ));
            }
            if i > 0 && t < self.points[i - 1].0 {
                return Err(FieldError::new(
                    format!("{field}.points[{i}]"),
                    format!("time {t} s goes back from {} s", self.points[i - 1].0),
                ));
            }
        }
        Ok(())
    }
}

/// One term of the load torque (`[[load]]` in a scenario, with `kind = "..."`); the load is
/// the sum of its terms. Positive torque brakes positive rotation. Speed-dependent terms use
/// the mechanical speed at the start of the period and are held over it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum LoadTerm {
    /// A constant torque (active, like a hanging mass).
    Constant {
        /// Torque, N m.
        torque_nm: f64,
    },
    /// A step from `before_nm` to `after_nm` at `time_s`.
    Step {
        /// Time of the step, s.
        time_s: f64,
        /// Torque before, N m.
        before_nm: f64,
        /// Torque from `time_s` on, N m.
        after_nm: f64,
    },
    /// A linear ramp from `from_nm` at `start_s` to `to_nm` at `end_s`, held outside.
    Ramp {
        /// Start of the ramp, s.
        start_s: f64,
        /// End of the ramp, s.
        end_s: f64,
        /// Torque up to `start_s`, N m.
        from_nm: f64,
        /// Torque from `end_s` on, N m.
        to_nm: f64,
    },
    /// Speed-proportional (viscous) load `k w_mech`.
    Viscous {
        /// `k`, N m s/rad.
        coefficient_nm_s_rad: f64,
    },
    /// Quadratic fan or pump load `k w_mech |w_mech|`.
    Fan {
        /// `k`, N m s^2/rad^2.
        coefficient_nm_s2_rad2: f64,
    },
    /// A constant-power load (traction, spindles, winders above their base speed): the torque
    /// `min(max_torque_nm, power_w / |w_mech|)` against the direction of rotation (0 at
    /// standstill), i.e. `max_torque_nm` up to the corner speed `power_w / max_torque_nm` and
    /// `max_torque_nm x corner / |w_mech|` above it. Off before `start_s`, then faded in
    /// linearly over `ramp_s`.
    ConstantPower {
        /// Power above the corner speed, W.
        power_w: f64,
        /// Torque up to the corner speed, N m.
        max_torque_nm: f64,
        /// Time the load comes on, s (default 0).
        #[serde(default)]
        start_s: f64,
        /// Time over which it fades in from `start_s`, s (default 0: a step).
        #[serde(default)]
        ramp_s: f64,
    },
    /// A torque table over time.
    Table {
        /// Reading between points (default linear).
        #[serde(default)]
        interpolation: Interpolation,
        /// The points `[time s, torque N m]`.
        points: Vec<(f64, f64)>,
    },
}

impl LoadTerm {
    /// The term's torque at `t_s` and mechanical speed `omega_mech_rad_s`, N m.
    pub fn torque_nm(&self, t_s: f64, omega_mech_rad_s: f64) -> f64 {
        match self {
            LoadTerm::Constant { torque_nm } => *torque_nm,
            LoadTerm::Step {
                time_s,
                before_nm,
                after_nm,
            } => {
                if t_s >= *time_s {
                    *after_nm
                } else {
                    *before_nm
                }
            }
            LoadTerm::Ramp {
                start_s,
                end_s,
                from_nm,
                to_nm,
            } => {
                if t_s <= *start_s {
                    *from_nm
                } else if t_s >= *end_s {
                    *to_nm
                } else {
                    from_nm + (to_nm - from_nm) * (t_s - start_s) / (end_s - start_s)
                }
            }
            LoadTerm::Viscous {
                coefficient_nm_s_rad,
            } => coefficient_nm_s_rad * omega_mech_rad_s,
            LoadTerm::Fan {
                coefficient_nm_s2_rad2,
            } => coefficient_nm_s2_rad2 * omega_mech_rad_s * omega_mech_rad_s.abs(),
            LoadTerm::ConstantPower {
                power_w,
                max_torque_nm,
                start_s,
                ramp_s,
            } => {
                let fade = if t_s < *start_s {
                    return 0.0;
                } else if t_s < start_s + ramp_s {
                    (t_s - start_s) / ramp_s
                } else {
                    1.0
                };
                let w = omega_mech_rad_s.abs();
                if w == 0.0 {
                    return 0.0;
                }
                let t = if max_torque_nm * w > *power_w {
                    power_w / w
                } else {
                    *max_torque_nm
                };
                fade * t.copysign(omega_mech_rad_s)
            }
            LoadTerm::Table {
                interpolation,
                points,
            } => {
                // Same reading as a Profile, without cloning it.
                let p = ProfileRef {
                    interpolation: *interpolation,
                    points,
                };
                p.at(t_s)
            }
        }
    }

    /// Checks the term; errors name `field` (e.g. `load[2]`) and the parameter.
    pub fn validate(&self, field: &str) -> Result<(), FieldError> {
        let finite = |name: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(FieldError::new(
                    format!("{field}.{name}"),
                    format!("must be finite, is {v}"),
                ))
            }
        };
        match self {
            LoadTerm::Constant { torque_nm } => finite("torque_nm", *torque_nm),
            LoadTerm::Step {
                time_s,
                before_nm,
                after_nm,
            } => {
                finite("time_s", *time_s)?;
                finite("before_nm", *before_nm)?;
                finite("after_nm", *after_nm)
            }
            LoadTerm::Ramp {
                start_s,
                end_s,
                from_nm,
                to_nm,
            } => {
                finite("start_s", *start_s)?;
                finite("end_s", *end_s)?;
                finite("from_nm", *from_nm)?;
                finite("to_nm", *to_nm)?;
                if end_s <= start_s {
                    return Err(FieldError::new(
                        format!("{field}.end_s"),
                        format!("must be after start_s = {start_s} s, is {end_s} s"),
                    ));
                }
                Ok(())
            }
            LoadTerm::Viscous {
                coefficient_nm_s_rad,
            } => finite("coefficient_nm_s_rad", *coefficient_nm_s_rad),
            LoadTerm::Fan {
                coefficient_nm_s2_rad2,
            } => finite("coefficient_nm_s2_rad2", *coefficient_nm_s2_rad2),
            LoadTerm::ConstantPower {
                power_w,
                max_torque_nm,
                start_s,
                ramp_s,
            } => {
                for (name, v) in [("power_w", *power_w), ("max_torque_nm", *max_torque_nm)] {
                    if !(v.is_finite() && v > 0.0) {
                        return Err(FieldError::new(
                            format!("{field}.{name}"),
                            format!("must be finite and > 0, is {v}"),
                        ));
                    }
                }
                finite("start_s", *start_s)?;
                if !(ramp_s.is_finite() && *ramp_s >= 0.0) {
                    return Err(FieldError::new(
                        format!("{field}.ramp_s"),
                        format!("must be finite and >= 0, is {ramp_s}"),
                    ));
                }
                Ok(())
            }
            LoadTerm::Table {
                interpolation,
                points,
            } => Profile {
                interpolation: *interpolation,
                points: points.clone(),
            }
            .validate(field),
        }
    }
}

/// A borrowed profile, to read a table term without cloning.
struct ProfileRef<'a> {
    interpolation: Interpolation,
    points: &'a [(f64, f64)],
}

impl ProfileRef<'_> {
    fn at(&self, t_s: f64) -> f64 {
        let pts = self.points;
        let Some(&(t0, v0)) = pts.first() else {
            return 0.0;
        };
        if t_s < t0 {
            return v0;
        }
        let idx = pts.partition_point(|&(t, _)| t <= t_s).saturating_sub(1);
        let (ta, va) = pts[idx];
        match (self.interpolation, pts.get(idx + 1)) {
            (Interpolation::Linear, Some(&(tb, vb))) if tb > ta => {
                va + (vb - va) * (t_s - ta) / (tb - ta)
            }
            _ => va,
        }
    }
}

/// The total load torque of a list of terms, N m.
pub fn load_torque_nm(terms: &[LoadTerm], t_s: f64, omega_mech_rad_s: f64) -> f64 {
    terms
        .iter()
        .map(|t| t.torque_nm(t_s, omega_mech_rad_s))
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn profiles_interpolate_and_hold() {
        let p = Profile::linear(vec![(1.0, 0.0), (2.0, 10.0), (2.0, 20.0), (3.0, 20.0)]);
        assert_eq!(p.at(0.0), 0.0);
        assert_eq!(p.at(1.5), 5.0);
        assert_eq!(p.at(2.0), 20.0);
        assert_eq!(p.at(9.0), 20.0);
        let s = Profile::steps(vec![(0.0, 1.0), (0.5, 2.0)]);
        assert_eq!(s.at(0.49), 1.0);
        assert_eq!(s.at(0.5), 2.0);
        assert_eq!(Profile::steps(vec![]).at(3.0), 0.0);
        let e = Profile::linear(vec![(1.0, 0.0), (0.5, 0.0)]).validate("x");
        assert_eq!(e.map_err(|e| e.field), Err("x.points[1]".to_string()));
    }

    #[test]
    fn load_terms() {
        let terms = vec![
            LoadTerm::Constant { torque_nm: 0.1 },
            LoadTerm::Step {
                time_s: 1.0,
                before_nm: 0.0,
                after_nm: 2.0,
            },
            LoadTerm::Ramp {
                start_s: 0.0,
                end_s: 2.0,
                from_nm: 0.0,
                to_nm: 1.0,
            },
            LoadTerm::Viscous {
                coefficient_nm_s_rad: 0.01,
            },
            LoadTerm::Fan {
                coefficient_nm_s2_rad2: 1e-4,
            },
            LoadTerm::Table {
                interpolation: Interpolation::Step,
                points: vec![(0.0, 0.0), (0.5, 0.3)],
            },
        ];
        // t = 0.5, w = -100: 0.1 + 0 + 0.25 - 1 - 1 + 0.3.
        let t = load_torque_nm(&terms, 0.5, -100.0);
        assert!((t - (0.1 + 0.25 - 1.0 - 1.0 + 0.3)).abs() < 1e-12, "{t}");
        // t = 1.5, w = 100: 0.1 + 2 + 0.75 + 1 + 1 + 0.3.
        let t = load_torque_nm(&terms, 1.5, 100.0);
        assert!((t - 5.15).abs() < 1e-12, "{t}");
        let bad = LoadTerm::Ramp {
            start_s: 1.0,
            end_s: 1.0,
            from_nm: 0.0,
            to_nm: 1.0,
        };
        assert_eq!(
            bad.validate("load[0]").map_err(|e| e.field),
            Err("load[0].end_s".to_string())
        );
    }
    #[test]
    fn constant_power_load() {
        // 1000 W, 10 N m: corner at 100 rad/s; on at 1 s, faded in over 0.5 s.
        let cp = LoadTerm::ConstantPower {
            power_w: 1000.0,
            max_torque_nm: 10.0,
            start_s: 1.0,
            ramp_s: 0.5,
        };
        assert_eq!(cp.torque_nm(0.9, 50.0), 0.0);
        assert_eq!(cp.torque_nm(2.0, 0.0), 0.0);
        assert_eq!(cp.torque_nm(2.0, 50.0), 10.0);
        assert_eq!(cp.torque_nm(2.0, -50.0), -10.0);
        assert!((cp.torque_nm(2.0, 200.0) - 5.0).abs() < 1e-12);
        assert!((cp.torque_nm(2.0, -400.0) + 2.5).abs() < 1e-12);
        assert!((cp.torque_nm(1.25, 200.0) - 2.5).abs() < 1e-12);
        assert!(cp.validate("load[0]").is_ok());
        let bad = LoadTerm::ConstantPower {
            power_w: -1.0,
            max_torque_nm: 10.0,
            start_s: 0.0,
            ramp_s: 0.0,
        };
        assert_eq!(
            bad.validate("load[0]").map_err(|e| e.field),
            Err("load[0].power_w".to_string())
        );
    }
}
