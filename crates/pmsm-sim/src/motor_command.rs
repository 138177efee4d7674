//! `pmsm-sim motor`: a `[motor]` table from datasheet values, with the conventions of
//! `ekf_core::catalog::datasheet` (line-to-line `R` and `L` halved to per phase; `psi_f` from
//! `Kv` in rpm per volt of line-to-line peak back-EMF, or from `Kt` in N m per peak phase
//! ampere). The printed block is what a scenario file's `[motor]` table takes.

use clap::Args;
use ekf_core::MotorParams;
use ekf_core::catalog::datasheet;

/// The datasheet values.
#[derive(Args, Debug, Clone)]
pub struct MotorArgs {
    /// Pole pairs (poles / 2).
    #[arg(long)]
    pub pole_pairs: u32,
    /// Resistance between two terminals, ohm.
    #[arg(long, allow_hyphen_values = true)]
    pub r_ll: f64,
    /// Inductance between two terminals, H (a surface motor).
    #[arg(long, allow_hyphen_values = true, conflicts_with_all = ["ld_ll", "lq_ll"])]
    pub l_ll: Option<f64>,
    /// Smallest line-to-line inductance over a turn, H (an interior motor's d axis).
    #[arg(long, allow_hyphen_values = true, requires = "lq_ll")]
    pub ld_ll: Option<f64>,
    /// Largest line-to-line inductance over a turn, H (an interior motor's q axis).
    #[arg(long, allow_hyphen_values = true, requires = "ld_ll")]
    pub lq_ll: Option<f64>,
    /// Speed constant, rpm per volt of line-to-line peak back-EMF.
    #[arg(
        long,
        allow_hyphen_values = true,
        conflicts_with = "kt",
        required_unless_present = "kt"
    )]
    pub kv: Option<f64>,
    /// Torque constant, N m per peak phase ampere.
    #[arg(long, allow_hyphen_values = true)]
    pub kt: Option<f64>,
    /// Rotor plus load inertia, kg m^2 (default: left for you to fill in).
    #[arg(long, allow_hyphen_values = true)]
    pub j: Option<f64>,
    /// Viscous friction, N m s/rad.
    #[arg(long, allow_hyphen_values = true)]
    pub b: Option<f64>,
}

/// The `[motor]` block, or the reason the values are refused (naming the value).
pub fn motor_block(a: &MotorArgs) -> Result<String, String> {
    let positive = |name: &str, v: f64| {
        if v.is_finite() && v > 0.0 {
            Ok(v)
        } else {
            Err(format!("--{name} must be positive and finite, got {v}"))
        }
    };
    let rs = datasheet::phase_from_line_to_line(positive("r-ll", a.r_ll)?);
    let (ld, lq) = match (a.l_ll, a.ld_ll, a.lq_ll) {
        (Some(l), None, None) => {
            let l = datasheet::phase_from_line_to_line(positive("l-ll", l)?);
            (l, l)
        }
        (None, Some(d), Some(q)) => (
            datasheet::phase_from_line_to_line(positive("ld-ll", d)?),
            datasheet::phase_from_line_to_line(positive("lq-ll", q)?),
        ),
        _ => return Err("give --l-ll (surface motor) or --ld-ll and --lq-ll".into()),
    };
    let (psi, from) = match (a.kv, a.kt) {
        (Some(kv), None) => (
            datasheet::psi_f_from_kv(positive("kv", kv)?, a.pole_pairs),
            format!("Kv {kv} rpm/V (line-to-line peak)"),
        ),
        (None, Some(kt)) => (
            datasheet::psi_f_from_kt(positive("kt", kt)?, a.pole_pairs),
            format!("Kt {kt} N m/A (peak phase)"),
        ),
        _ => return Err("give exactly one of --kv and --kt".into()),
    };
    MotorParams::<f64>::salient_from_f64(rs, ld, lq, psi, a.pole_pairs)
        .validate()
        .map_err(|e| e.to_string())?;
    let opt = |v: Option<f64>, name: &str| -> Result<String, String> {
        match v {
            Some(x) if x.is_finite() && x >= 0.0 => Ok(format!("{name} = {x}\n")),
            Some(x) => Err(format!("--{} must be finite and >= 0, got {x}", &name[..1])),
            None => Ok(format!("# {name} = ...   (required: fill in)\n")),
        }
    };
    Ok(format!(
        "# From the datasheet: R_ll {r_ll} ohm, L_ll halved, {from}, {p} pole pairs.\n\
         [motor]\n\
         rs_ohm = {rs}\n\
         ld_h = {ld}\n\
         lq_h = {lq}\n\
         psi_f_wb = {psi}\n\
         pole_pairs = {p}\n\
         {j}{b}",
        r_ll = a.r_ll,
        p = a.pole_pairs,
        j = opt(a.j, "j_kg_m2")?,
        b = opt(a.b, "b_nm_s_rad")?,
    ))
}
