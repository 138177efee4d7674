//! The motor's parameters ([`MotorModel`]: the dq model's constants, the reference motors, the EMF harmonics) and the d-axis saturation option.

use std::sync::Arc;

use super::saturation::{FluxMapTable, Saturation, SaturationSection, TabulatedMap};
use super::*;
use ekf_core::catalog::{self, ReferenceMotor};
use ekf_core::saturation::{SATURATED, SaturatedMotor, SaturationModel, saturated_by_name};

/// Mechanical and electrical parameters of a PMSM (SI units).
///
/// In a scenario's `[motor]` table, `catalog = "servo"` (any name of `ekf_core::catalog`:
/// `servo`, `industrial_2k2`, `small_fast`, `industrial_ipm`, `traction_ipm`) starts from that
/// reference motor; the keys given beside it override its values. `ls_h` sets both `ld_h` and
/// `lq_h` (a surface motor), as it does in `[observer]`; `ld_h` or `lq_h` given beside it wins
/// for its axis. Without `catalog` every key except `coulomb_nm` and `emf_harmonics` is
/// required. Written out, a scenario lists the resolved values.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "MotorSection")]
pub struct MotorModel {
    /// Stator resistance per phase, ohm.
    pub rs_ohm: f64,
    /// Direct-axis inductance, henry.
    pub ld_h: f64,
    /// Quadrature-axis inductance, henry (equal to `ld_h` for a surface motor).
    pub lq_h: f64,
    /// Permanent-magnet flux linkage, weber.
    pub psi_f_wb: f64,
    /// Number of pole pairs.
    pub pole_pairs: u32,
    /// Rotor (plus load) inertia, kg m^2.
    pub j_kg_m2: f64,
    /// Viscous friction coefficient, N m s/rad (on the mechanical speed).
    pub b_nm_s_rad: f64,
    /// Coulomb (dry) friction torque, N m (0: none).
    #[serde(default)]
    pub coulomb_nm: f64,
    /// 5th and 7th harmonics of the magnet flux (`[motor.emf_harmonics]`, module docs;
    /// default none).
    #[serde(default, skip_serializing_if = "EmfHarmonics::is_default")]
    pub emf_harmonics: EmfHarmonics,
    /// Magnetic saturation by an algebraic model (`[motor.saturation]`, module
    /// [`saturation`](super::saturation)); default none.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        serialize_with = "super::saturation::serialize_model"
    )]
    pub saturation: Option<SaturationModel>,
    /// Magnetic saturation by a tabulated flux map (`[motor.flux_map]`); default none.
    #[serde(
        default,
        skip_serializing_if = "Option::is_none",
        serialize_with = "super::saturation::serialize_map"
    )]
    pub flux_map: Option<Arc<TabulatedMap>>,
}

/// The `[motor]` table as written: a catalog name and any values ([`MotorModel`]).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct MotorSection {
    catalog: Option<String>,
    rs_ohm: Option<f64>,
    ls_h: Option<f64>,
    ld_h: Option<f64>,
    lq_h: Option<f64>,
    psi_f_wb: Option<f64>,
    pole_pairs: Option<u32>,
    j_kg_m2: Option<f64>,
    b_nm_s_rad: Option<f64>,
    #[serde(default)]
    coulomb_nm: f64,
    #[serde(default)]
    emf_harmonics: EmfHarmonics,
    saturation: Option<SaturationSection>,
    flux_map: Option<FluxMapTable>,
}

impl TryFrom<MotorSection> for MotorModel {
    type Error = String;

    fn try_from(s: MotorSection) -> Result<Self, String> {
        let saturated = match &s.catalog {
            Some(name) => saturated_by_name(name),
            None => None,
        };
        let base = match &s.catalog {
            Some(name) => Some(
                catalog::by_name(name)
                    .or(saturated.map(|m| &m.reference))
                    .ok_or_else(|| {
                        let known: Vec<&str> = catalog::ALL
                            .iter()
                            .chain(SATURATED.iter().map(|m| &m.reference))
                            .map(|m| m.name)
                            .collect();
                        format!(
                            "motor.catalog: no reference motor named {name:?} (known: {})",
                            known.join(", ")
                        )
                    })?,
            ),
            None => None,
        };
        // Saturation: given, or the saturating reference motor's own model.
        let saturation = match &s.saturation {
            Some(sec) => Some(sec.resolve()?),
            None if s.flux_map.is_none() => saturated.map(|m| m.model),
            None => None,
        };
        let flux_map = match &s.flux_map {
            Some(table) => Some(Arc::new(TabulatedMap {
                map: table.build()?,
                table: table.clone(),
            })),
            None => None,
        };
        if saturation.is_some() && flux_map.is_some() {
            return Err("motor: give either [motor.saturation] or [motor.flux_map]".into());
        }
        let magnetics = match (&saturation, &flux_map) {
            (Some(m), _) => Some(Saturation::Algebraic(*m)),
            (_, Some(t)) => Some(Saturation::Map(t.clone())),
            _ => None,
        };
        if magnetics.is_some() && s.emf_harmonics.is_on() {
            return Err(
                "motor.emf_harmonics: not available on a saturating motor (its flux is the \
                 saturation model's)"
                    .into(),
            );
        }
        // A saturating motor's small-signal values come from its model unless given.
        let small = match &magnetics {
            Some(m) if s.catalog.is_none() => Some(m.small_signal()?),
            _ => None,
        };
        // `ls_h` is resolved into `ld_h` and `lq_h` here: checked here, by its own name, where
        // it sets an axis (the other keys are checked by `MotorModel::validate`).
        if let Some(ls) = s.ls_h
            && (s.ld_h.is_none() || s.lq_h.is_none())
            && !(ekf_core::MIN_INDUCTANCE_H..=ekf_core::MAX_INDUCTANCE_H).contains(&ls)
        {
            use crate::error::plain;
            return Err(format!(
                "motor.ls_h: allowed: {} <= x <= {} H, is {}",
                plain(ekf_core::MIN_INDUCTANCE_H),
                plain(ekf_core::MAX_INDUCTANCE_H),
                plain(ls)
            ));
        }
        let pick = |v: Option<f64>, from: fn(&ReferenceMotor) -> f64, key: &str| {
            v.or(base.map(from)).ok_or_else(|| {
                format!("motor.{key} is missing (give it, or motor.catalog = a reference motor)")
            })
        };
        Ok(Self {
            rs_ohm: pick(s.rs_ohm, |m| m.rs_ohm, "rs_ohm")?,
            ld_h: pick(s.ld_h.or(s.ls_h).or(small.map(|v| v.0)), |m| m.ld_h, "ld_h")?,
            lq_h: pick(s.lq_h.or(s.ls_h).or(small.map(|v| v.1)), |m| m.lq_h, "lq_h")?,
            psi_f_wb: pick(
                s.psi_f_wb.or(small.map(|v| v.2)),
                |m| m.psi_f_wb,
                "psi_f_wb",
            )?,
            pole_pairs: s.pole_pairs.or(base.map(|m| m.pole_pairs)).ok_or_else(|| {
                "motor.pole_pairs is missing (give it, or motor.catalog = a reference motor)"
                    .to_string()
            })?,
            j_kg_m2: pick(s.j_kg_m2, |m| m.j_kg_m2, "j_kg_m2")?,
            b_nm_s_rad: pick(s.b_nm_s_rad, |m| m.b_nm_s_rad, "b_nm_s_rad")?,
            coulomb_nm: s.coulomb_nm,
            emf_harmonics: s.emf_harmonics,
            saturation,
            flux_map,
        })
    }
}

/// Smallest rotor inertia, kg m^2 (a 10 mm hobby motor has about 1e-8).
pub const MIN_J_KG_M2: f64 = 1e-10;
/// Largest rotor-plus-load inertia, kg m^2.
pub const MAX_J_KG_M2: f64 = 1e6;
/// Largest viscous friction coefficient, N m s/rad.
pub const MAX_B_NM_S_RAD: f64 = 1e6;
/// Largest Coulomb friction torque, N m.
pub const MAX_COULOMB_NM: f64 = 1e6;

/// RK4 sub-steps per period of the plant with back-EMF harmonics.
pub const HARMONIC_SUBSTEPS: u32 = 8;

/// Largest harmonic amplitude accepted, fraction of `psi_f`.
pub const MAX_HARMONIC: f64 = 0.2;

/// The 5th and 7th harmonics of the magnet flux (module docs): amplitudes `h5`, `h7` as
/// fractions of `psi_f` (the EMF's are 5 and 7 times these, as fractions of its
/// fundamental), phases in rad (of `cos(5 th + phi5)` in phase `a`'s flux).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EmfHarmonics {
    /// 5th-harmonic flux amplitude, fraction of `psi_f`, `[0, 0.2]`.
    pub h5: f64,
    /// Its phase, rad.
    pub h5_phase_rad: f64,
    /// 7th-harmonic flux amplitude, fraction of `psi_f`, `[0, 0.2]`.
    pub h7: f64,
    /// Its phase, rad.
    pub h7_phase_rad: f64,
}

impl EmfHarmonics {
    /// No harmonics.
    pub const NONE: Self = Self {
        h5: 0.0,
        h5_phase_rad: 0.0,
        h7: 0.0,
        h7_phase_rad: 0.0,
    };

    /// All fields zero (the default; not written to TOML).
    pub fn is_default(&self) -> bool {
        *self == Self::NONE
    }

    /// Whether any harmonic is present.
    pub fn is_on(&self) -> bool {
        self.h5 != 0.0 || self.h7 != 0.0
    }

    /// The harmonic part of the motional EMF per electrical speed, `(e_d, e_q) / w_e` less the
    /// fundamental `(0, psi_f)`, at the electrical angle `th` (module docs), Wb.
    #[inline]
    pub fn emf_per_speed(&self, psi_f_wb: f64, th: f64) -> (f64, f64) {
        let (s6, c6) = (6.0 * th).sin_cos();
        let (s5p, c5p) = self.h5_phase_rad.sin_cos();
        let (s7p, c7p) = self.h7_phase_rad.sin_cos();
        // a = 6 th + phi: sin a, cos a by the angle-addition formula.
        let (s5, c5) = (s6 * c5p + c6 * s5p, c6 * c5p - s6 * s5p);
        let (s7, c7) = (s6 * c7p + c6 * s7p, c6 * c7p - s6 * s7p);
        let (a5, a7) = (5.0 * self.h5, 7.0 * self.h7);
        (
            -psi_f_wb * (a5 * s5 + a7 * s7),
            psi_f_wb * (-a5 * c5 + a7 * c7),
        )
    }

    /// Checks the amplitudes and phases; errors name `<prefix>.<field>`.
    pub fn validate(&self, prefix: &str) -> Result<(), FieldError> {
        for (name, v) in [("h5", self.h5), ("h7", self.h7)] {
            if !(v.is_finite() && (0.0..=MAX_HARMONIC).contains(&v)) {
                return Err(FieldError::new(
                    format!("{prefix}.{name}"),
                    format!("must be in [0, {MAX_HARMONIC}] (a fraction of psi_f), is {v}"),
                ));
            }
        }
        for (name, v) in [
            ("h5_phase_rad", self.h5_phase_rad),
            ("h7_phase_rad", self.h7_phase_rad),
        ] {
            if !v.is_finite() {
                return Err(FieldError::new(
                    format!("{prefix}.{name}"),
                    format!("must be finite, is {v}"),
                ));
            }
        }
        Ok(())
    }
}

impl MotorModel {
    /// A reference motor of the catalog (`ekf_core::catalog`, docs/design.md, "Reference motors"):
    /// its electrical data and mechanics, no Coulomb friction, a sinusoidal EMF.
    pub fn from_catalog(m: &ReferenceMotor) -> Self {
        Self {
            rs_ohm: m.rs_ohm,
            ld_h: m.ld_h,
            lq_h: m.lq_h,
            psi_f_wb: m.psi_f_wb,
            pole_pairs: m.pole_pairs,
            j_kg_m2: m.j_kg_m2,
            b_nm_s_rad: m.b_nm_s_rad,
            coulomb_nm: 0.0,
            emf_harmonics: EmfHarmonics::NONE,
            saturation: None,
            flux_map: None,
        }
    }

    /// A reference saturating motor (`ekf_core::saturation::SATURATED`): its small-signal
    /// parameters, mechanics and algebraic saturation model.
    pub fn from_saturated(m: &SaturatedMotor) -> Self {
        Self {
            saturation: Some(m.model),
            ..Self::from_catalog(&m.reference)
        }
    }

    /// The flux-current relation when the motor saturates (`[motor.saturation]` or
    /// `[motor.flux_map]`), else `None`: the linear model.
    pub fn magnetics(&self) -> Option<Saturation> {
        match (&self.saturation, &self.flux_map) {
            (Some(m), _) => Some(Saturation::Algebraic(*m)),
            (_, Some(t)) => Some(Saturation::Map(t.clone())),
            _ => None,
        }
    }

    /// The catalog's servo motor.
    pub fn servo() -> Self {
        Self::from_catalog(&catalog::SERVO)
    }

    /// The catalog's industrial 2.2 kW motor, surface variant.
    pub fn industrial_2k2() -> Self {
        Self::from_catalog(&catalog::INDUSTRIAL_2K2)
    }

    /// The catalog's small fast (drone class) motor.
    pub fn small_fast() -> Self {
        Self::from_catalog(&catalog::SMALL_FAST)
    }

    /// The catalog's industrial interior PMSM (Lq/Ld 1.4).
    pub fn industrial_ipm() -> Self {
        Self::from_catalog(&catalog::INDUSTRIAL_IPM)
    }

    /// The catalog's traction interior PMSM (Lq/Ld 3).
    pub fn traction_ipm() -> Self {
        Self::from_catalog(&catalog::TRACTION_IPM)
    }

    /// The d-axis current of the maximum-torque-per-ampere law for a current magnitude
    /// `|i| = i_a` (docs/design.md, "The real motor"): `i_d = (psi_f - sqrt(psi_f^2 + 8 (Lq - Ld)^2 i^2))
    /// / (4 (Lq - Ld))`, A; `0` for a surface motor (and for `Lq < Ld`, which this law does not
    /// cover). Non-positive for `Lq > Ld`, and `|i_d| <= |i|`.
    pub fn mtpa_i_d_a(&self, i_a: f64) -> f64 {
        let dl = self.lq_h - self.ld_h;
        if dl <= 0.0 {
            return 0.0;
        }
        let psi = self.psi_f_wb;
        // The same value as the textbook form, written without its cancellation at small i:
        // (psi - r) / (4 dl) = -8 dl^2 i^2 / ((psi + r) 4 dl) = -2 dl i^2 / (psi + r).
        let r = (psi * psi + 8.0 * dl * dl * i_a * i_a).sqrt();
        -2.0 * dl * i_a * i_a / (psi + r)
    }

    /// The dq currents on the MTPA line for the torque `t_nm` (sign included), and their
    /// magnitude: `(i_d, i_q, |i|)`, A, by bisection on `|i|` (`i_d = 0` for a surface motor).
    pub fn mtpa_currents_for_torque(&self, t_nm: f64) -> (f64, f64, f64) {
        let target = t_nm.abs();
        let at = |i: f64| {
            let id = self.mtpa_i_d_a(i);
            let iq = (i * i - id * id).max(0.0).sqrt();
            (id, iq)
        };
        let mut hi = target / self.torque_constant_nm_a();
        let mut lo = 0.0;
        // |i| at i_d = 0 gives at least the torque (MTPA only adds reluctance torque).
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            let (id, iq) = at(mid);
            if self.torque_nm(id, iq) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let (id, iq) = at(hi);
        (id, iq.copysign(t_nm), hi)
    }

    /// Magnitude of the steady-state stator voltage at the dq currents and electrical speed
    /// `w_e`, V: `|(Rs i_d - w Lq i_q, Rs i_q + w (Ld i_d + psi_f))|`.
    pub fn steady_voltage_v(&self, i_d_a: f64, i_q_a: f64, omega_e_rad_s: f64) -> f64 {
        let w = omega_e_rad_s;
        let u_d = self.rs_ohm * i_d_a - w * self.lq_h * i_q_a;
        let u_q = self.rs_ohm * i_q_a + w * (self.ld_h * i_d_a + self.psi_f_wb);
        u_d.hypot(u_q)
    }

    /// Base speed, mechanical rpm: the speed at which the steady voltage at the MTPA currents
    /// of `t_nm` reaches the linear SVPWM limit `u_dc / sqrt 3` (bisection).
    pub fn base_speed_rpm(&self, t_nm: f64, u_dc_v: f64) -> f64 {
        let (id, iq, _) = self.mtpa_currents_for_torque(t_nm);
        let u_max = u_dc_v / 3f64.sqrt();
        let (mut lo, mut hi) = (0.0, 10.0 * u_max / self.psi_f_wb);
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            if self.steady_voltage_v(id, iq, mid) < u_max {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo / self.p() * 30.0 / PI
    }

    /// The surface-motor inductance the observer's model uses: `(Ld + Lq) / 2`.
    pub fn ls_mean_h(&self) -> f64 {
        0.5 * (self.ld_h + self.lq_h)
    }

    /// The electrical parameters as the observer takes them (`Ls = (Ld + Lq) / 2`).
    pub fn params(&self) -> MotorParams<f64> {
        MotorParams::from_f64(
            self.rs_ohm,
            self.ls_mean_h(),
            self.psi_f_wb,
            self.pole_pairs,
        )
    }

    /// Pole pairs as `f64`.
    pub fn p(&self) -> f64 {
        f64::from(self.pole_pairs)
    }

    /// Torque constant `1.5 p psi_f`, N m per ampere of `i_q` (at `i_d = 0`).
    pub fn torque_constant_nm_a(&self) -> f64 {
        1.5 * self.p() * self.psi_f_wb
    }

    /// Electromagnetic torque at the dq currents, N m.
    pub fn torque_nm(&self, i_d_a: f64, i_q_a: f64) -> f64 {
        1.5 * self.p() * (self.psi_f_wb + (self.ld_h - self.lq_h) * i_d_a) * i_q_a
    }

    /// Checks that every parameter is physically valid and one a motor can have; the error
    /// names the field (`motor.<name>`) and the allowed range. The electrical bounds are the
    /// observer's (`ekf_core::MAX_RS_OHM`, ...): `0 < Rs <= 1000` ohm,
    /// `1e-8 <= Ld, Lq <= 10` H, `0 < psi_f <= 100` Wb, `1 <= p <= 1000`; the mechanical ones
    /// [`MIN_J_KG_M2`] `<= J <=` [`MAX_J_KG_M2`], `0 <= B <=` [`MAX_B_NM_S_RAD`],
    /// `0 <= Tc <=` [`MAX_COULOMB_NM`].
    pub fn validate(&self) -> Result<(), FieldError> {
        use crate::error::plain;
        use ekf_core::{
            MAX_INDUCTANCE_H, MAX_POLE_PAIRS, MAX_PSI_F_WB, MAX_RS_OHM, MIN_INDUCTANCE_H,
        };
        let (l_lo, l_hi) = (MIN_INDUCTANCE_H, MAX_INDUCTANCE_H);
        let checks = [
            ("rs_ohm", self.rs_ohm, 0.0, false, MAX_RS_OHM, "ohm"),
            ("ld_h", self.ld_h, l_lo, true, l_hi, "H"),
            ("lq_h", self.lq_h, l_lo, true, l_hi, "H"),
            ("psi_f_wb", self.psi_f_wb, 0.0, false, MAX_PSI_F_WB, "Wb"),
            (
                "j_kg_m2",
                self.j_kg_m2,
                MIN_J_KG_M2,
                true,
                MAX_J_KG_M2,
                "kg m^2",
            ),
            (
                "b_nm_s_rad",
                self.b_nm_s_rad,
                0.0,
                true,
                MAX_B_NM_S_RAD,
                "N m s/rad",
            ),
            (
                "coulomb_nm",
                self.coulomb_nm,
                0.0,
                true,
                MAX_COULOMB_NM,
                "N m",
            ),
        ];
        for (name, v, lo, closed, hi, unit) in checks {
            let above = if closed { v >= lo } else { v > lo };
            if !(above && v <= hi) {
                let op = if closed { "<=" } else { "<" };
                return Err(FieldError::new(
                    format!("motor.{name}"),
                    format!(
                        "allowed: {} {op} x <= {} {unit}, is {}",
                        plain(lo),
                        plain(hi),
                        plain(v)
                    ),
                ));
            }
        }
        if !(1..=MAX_POLE_PAIRS).contains(&self.pole_pairs) {
            return Err(FieldError::new(
                "motor.pole_pairs",
                format!(
                    "allowed: 1 <= x <= {MAX_POLE_PAIRS}, is {}",
                    self.pole_pairs
                ),
            ));
        }
        self.emf_harmonics.validate("motor.emf_harmonics")
    }
}

/// d-axis saturation for positive `i_d` (module docs): the incremental inductance falls by
/// the fraction `drop` of `Ld` at `current_a`, linearly from zero current.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct DSaturation {
    /// Fraction of `Ld` lost at `current_a` (and above), in `[0, 1)`.
    pub drop: f64,
    /// d current at which the drop is complete, A (positive).
    pub current_a: f64,
}

impl DSaturation {
    /// Incremental d inductance at `i_d`, H.
    pub fn ld_inc_h(&self, ld_h: f64, i_d_a: f64) -> f64 {
        ld_h * (1.0 - self.drop * (i_d_a / self.current_a).clamp(0.0, 1.0))
    }

    /// d flux linkage at `i_d`, Wb.
    pub fn psi_d_wb(&self, ld_h: f64, psi_f_wb: f64, i_d_a: f64) -> f64 {
        let (k, is) = (self.drop, self.current_a);
        if i_d_a <= 0.0 {
            psi_f_wb + ld_h * i_d_a
        } else if i_d_a <= is {
            psi_f_wb + ld_h * (i_d_a - k * i_d_a * i_d_a / (2.0 * is))
        } else {
            psi_f_wb + ld_h * (is * (1.0 - 0.5 * k) + (1.0 - k) * (i_d_a - is))
        }
    }
}
