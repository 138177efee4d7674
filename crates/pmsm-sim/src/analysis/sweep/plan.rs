//! A sweep's plan: the base scenario, what varies and how, expanded into one scenario per run.
//!
//! The base scenario is the resolved scenario written as TOML ([`Scenario::to_toml`]): every
//! key a run may vary is present with its value (the motor's parameters included when the
//! file names a catalog motor). A varied key is a dotted path into that table
//! (`motor.rs_ohm`, `controller.foc.if_current_a`, `load.0.after_nm` for the first `[[load]]`
//! term); missing tables on the way are created (`observer.rs_ohm` in a scenario without an
//! `[observer]` table).
//!
//! Rules of the expansion (the same for `pyfoc.sweep` and `pmsm-sim sweep`):
//! - a list of values is a grid axis; the runs are every combination of the lists (the first
//!   path, in sorted order, varies slowest), each repeated `n` times;
//! - `["uniform", lo, hi]`, `["normal", mean, sd]` and `["relative", sd]` (the base value times
//!   `1 + sd N(0, 1)`) are drawn anew for every run;
//! - a single value (not a list) is a fixed setting of every run (`duration_s = 0.5`);
//! - every run has a noise seed of its own (the scenario's `seed`), unless `seed` is varied.
//!
//! One Xoshiro256++ stream seeded with the sweep's seed draws, run by run in index order, the
//! distributions (paths in sorted order) and then the run's noise seed: the plan, and so the
//! results, depend only on the plan, never on how or where the runs execute.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};

use crate::error::SimError;
use crate::scenario::Scenario;

/// How one path varies.
#[derive(Clone, Debug, PartialEq)]
pub enum Spread {
    /// A grid axis: each value in turn.
    Values(Vec<toml::Value>),
    /// Uniform in `[lo, hi)`.
    Uniform {
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// Normal with this mean and standard deviation.
    Normal {
        /// Mean.
        mean: f64,
        /// Standard deviation (`>= 0`).
        sd: f64,
    },
    /// The base value times `1 + sd N(0, 1)`.
    Relative {
        /// Relative standard deviation (`>= 0`).
        sd: f64,
    },
}

/// The distribution names a list may start with.
pub const DISTRIBUTIONS: [&str; 3] = ["uniform", "normal", "relative"];

fn number(v: &toml::Value) -> Option<f64> {
    match v {
        toml::Value::Float(f) => Some(*f),
        toml::Value::Integer(i) => Some(*i as f64),
        _ => None,
    }
}

impl Spread {
    /// Reads one entry of `vary` (module docs give the spellings); errors name the path.
    pub fn from_value(path: &str, v: &toml::Value) -> Result<Self, String> {
        let toml::Value::Array(items) = v else {
            return Ok(Spread::Values(vec![v.clone()]));
        };
        let Some(name) = items.first().and_then(|x| x.as_str()) else {
            return Self::values(path, items);
        };
        if !DISTRIBUTIONS.contains(&name) {
            return Self::values(path, items);
        }
        let args: Vec<f64> = items[1..].iter().filter_map(number).collect();
        let want = if name == "relative" { 1 } else { 2 };
        if args.len() != items.len() - 1
            || args.len() != want
            || args.iter().any(|a| !a.is_finite())
        {
            let form = match name {
                "uniform" => "(\"uniform\", lo, hi)",
                "normal" => "(\"normal\", mean, sd)",
                _ => "(\"relative\", sd)",
            };
            return Err(format!(
                "vary.{path}: expected {form} with finite numbers, got {v}"
            ));
        }
        let spread = match name {
            "uniform" => Spread::Uniform {
                lo: args[0],
                hi: args[1],
            },
            "normal" => Spread::Normal {
                mean: args[0],
                sd: args[1],
            },
            _ => Spread::Relative { sd: args[0] },
        };
        match spread {
            Spread::Uniform { lo, hi } if lo > hi => Err(format!(
                "vary.{path}: uniform bounds out of order ({lo} > {hi})"
            )),
            Spread::Normal { sd, .. } | Spread::Relative { sd } if sd < 0.0 => Err(format!(
                "vary.{path}: the standard deviation must be >= 0, got {sd}"
            )),
            s => Ok(s),
        }
    }

    fn values(path: &str, items: &[toml::Value]) -> Result<Self, String> {
        if items.is_empty() {
            return Err(format!("vary.{path}: an empty list of values"));
        }
        Ok(Spread::Values(items.to_vec()))
    }

    fn is_grid(&self) -> bool {
        matches!(self, Spread::Values(_))
    }
}

/// A sweep: the base scenario (as a TOML table), the varied paths (sorted), the number of
/// draws per grid point and the seed.
#[derive(Clone, Debug)]
pub struct Plan {
    base: toml::Table,
    vary: Vec<(String, Spread, Option<f64>)>,
    n: usize,
    seed: u64,
}

/// One run of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct RunSpec {
    /// Position in the plan, from 0.
    pub index: usize,
    /// The value of each varied path, in the plan's (sorted) order.
    pub values: Vec<(String, toml::Value)>,
    /// The run's noise seed (the scenario's `seed`).
    pub seed: u64,
    /// The run's scenario as TOML text.
    pub toml: String,
}

/// The most runs one plan may hold.
pub const MAX_RUNS: usize = 10_000_000;

/// A path's segments, or an error naming it.
fn segments(path: &str) -> Result<Vec<&str>, String> {
    let segs: Vec<&str> = path.split('.').collect();
    if segs.iter().any(|s| s.is_empty()) {
        return Err(format!(
            "vary: {path:?} is not a dotted path of scenario keys (e.g. \"motor.rs_ohm\")"
        ));
    }
    Ok(segs)
}

/// The value at `path` in `table`, if there is one.
fn get<'a>(table: &'a toml::Table, path: &str) -> Option<&'a toml::Value> {
    let mut segs = path.split('.');
    let mut cur = table.get(segs.next()?)?;
    for s in segs {
        cur = match cur {
            toml::Value::Table(t) => t.get(s)?,
            toml::Value::Array(a) => a.get(s.parse::<usize>().ok()?)?,
            _ => return None,
        };
    }
    Some(cur)
}

/// Sets `path` in `table` to `value`, creating missing tables; errors name the path.
fn set(table: &mut toml::Table, path: &str, value: toml::Value) -> Result<(), String> {
    let segs = segments(path)?;
    let (last, parents) = segs
        .split_last()
        .ok_or_else(|| "vary: an empty path".to_string())?;
    let mut cur: &mut toml::Table = table;
    let mut walked = String::new();
    for (k, s) in parents.iter().enumerate() {
        if !walked.is_empty() {
            walked.push('.');
        }
        walked.push_str(s);
        let entry = cur
            .entry(s.to_string())
            .or_insert_with(|| toml::Value::Table(toml::Table::new()));
        cur = match entry {
            toml::Value::Table(t) => t,
            toml::Value::Array(a) => {
                // An index into an array of tables (`load.0.after_nm`).
                return set_in_array(a, &segs[k + 1..], value, path, &walked);
            }
            _ => {
                return Err(format!(
                    "vary.{path}: {walked} is a value, not a table of the scenario"
                ));
            }
        };
    }
    cur.insert(last.to_string(), value);
    Ok(())
}

/// [`set`] below an array: the first segment is the index.
fn set_in_array(
    a: &mut [toml::Value],
    rest: &[&str],
    value: toml::Value,
    path: &str,
    walked: &str,
) -> Result<(), String> {
    let (idx, rest) = rest
        .split_first()
        .ok_or_else(|| format!("vary.{path}: {walked} is a list: give an index"))?;
    let len = a.len();
    let i = idx
        .parse::<usize>()
        .ok()
        .filter(|i| *i < len)
        .ok_or_else(|| {
            format!("vary.{path}: {walked} has {len} entries, {idx:?} is not an index of one")
        })?;
    if rest.is_empty() {
        a[i] = value;
        return Ok(());
    }
    match &mut a[i] {
        toml::Value::Table(t) => set(t, &rest.join("."), value)
            .map_err(|e| e.replace(&format!("vary.{}", rest.join(".")), &format!("vary.{path}"))),
        _ => Err(format!("vary.{path}: {walked}.{idx} is not a table")),
    }
}

/// The base value of a `relative` path: the table's, or for the observer's motor parameters
/// (unset: the motor's), the value the observers are given.
fn base_value(table: &toml::Table, sc: &Scenario, path: &str) -> Result<f64, String> {
    if let Some(v) = get(table, path) {
        return number(v).ok_or_else(|| {
            format!("vary.{path}: \"relative\" needs a number, the scenario has {v}")
        });
    }
    let p = sc.observer_params();
    match path {
        "observer.rs_ohm" => Ok(p.rs_ohm),
        "observer.ld_h" => Ok(p.ld_h),
        "observer.lq_h" => Ok(p.lq_h),
        "observer.psi_f_wb" => Ok(p.psi_f_wb),
        "observer.ls_h" if p.ld_h == p.lq_h => Ok(p.ld_h),
        _ => Err(format!(
            "vary.{path}: \"relative\" needs a base value and the scenario has none there"
        )),
    }
}

impl Plan {
    /// A plan over `scenario`; `vary` maps dotted paths to their spread ([`Spread::from_value`]).
    /// Errors (a malformed spread, a path that cannot be set, a relative spread without a base
    /// value, a plan of more than [`MAX_RUNS`] runs) name the path.
    pub fn new(
        scenario: &Scenario,
        vary: &[(String, toml::Value)],
        n: usize,
        seed: u64,
    ) -> Result<Self, String> {
        let base = match toml::Value::try_from(scenario) {
            Ok(toml::Value::Table(t)) => t,
            Ok(_) => return Err("the scenario is not a table".into()),
            Err(e) => return Err(format!("the scenario cannot be written as TOML: {e}")),
        };
        if n == 0 {
            return Err("n must be at least 1".into());
        }
        let mut entries = Vec::with_capacity(vary.len());
        let mut seen = std::collections::BTreeSet::new();
        for (path, v) in vary {
            segments(path)?;
            if !seen.insert(path.clone()) {
                return Err(format!("vary: {path} is given twice"));
            }
            let spread = Spread::from_value(path, v)?;
            let rel = match spread {
                Spread::Relative { .. } => Some(base_value(&base, scenario, path)?),
                _ => None,
            };
            // A path that cannot be set fails here, once, rather than in every run.
            let probe = match &spread {
                Spread::Values(v) => v[0].clone(),
                _ => toml::Value::Float(0.0),
            };
            set(&mut base.clone(), path, probe)?;
            entries.push((path.clone(), spread, rel));
        }
        entries.sort_by(|a, b| a.0.cmp(&b.0));
        let plan = Self {
            base,
            vary: entries,
            n,
            seed,
        };
        let total = plan.grid_size().and_then(|g| g.checked_mul(n));
        match total {
            Some(t) if t <= MAX_RUNS => Ok(plan),
            _ => Err(format!(
                "the plan has more than {MAX_RUNS} runs (grid points x n)"
            )),
        }
    }

    fn grid_size(&self) -> Option<usize> {
        self.vary.iter().try_fold(1usize, |acc, (_, s, _)| match s {
            Spread::Values(v) => acc.checked_mul(v.len()),
            _ => Some(acc),
        })
    }

    /// Number of runs: the grid's points times `n`.
    pub fn len(&self) -> usize {
        self.grid_size().unwrap_or(0) * self.n
    }

    /// Whether the plan has no runs (never, once built).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The varied paths, sorted (the table's columns after the run index).
    pub fn paths(&self) -> Vec<String> {
        self.vary.iter().map(|(p, _, _)| p.clone()).collect()
    }

    /// Every run, in index order (deterministic for the plan; module docs).
    pub fn runs(&self) -> Result<Vec<RunSpec>, SimError> {
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(self.seed);
        let grid: Vec<&Vec<toml::Value>> = self
            .vary
            .iter()
            .filter_map(|(_, s, _)| match s {
                Spread::Values(v) => Some(v),
                _ => None,
            })
            .collect();
        let seed_varied = self.vary.iter().any(|(p, _, _)| p == "seed");
        let mut runs = Vec::with_capacity(self.len());
        for index in 0..self.len() {
            // Grid coordinates: the last grid path varies fastest; repeats innermost.
            let mut point = index / self.n;
            let mut coords = vec![0usize; grid.len()];
            for (c, axis) in coords.iter_mut().zip(&grid).rev() {
                *c = point % axis.len();
                point /= axis.len();
            }
            let mut g = 0;
            let mut values = Vec::with_capacity(self.vary.len());
            for (path, spread, rel) in &self.vary {
                let v = match spread {
                    Spread::Values(v) => {
                        g += 1;
                        v[coords[g - 1]].clone()
                    }
                    Spread::Uniform { lo, hi } => {
                        toml::Value::Float(lo + (hi - lo) * unit(&mut rng))
                    }
                    Spread::Normal { mean, sd } => {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        toml::Value::Float(mean + sd * z)
                    }
                    Spread::Relative { sd } => {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        toml::Value::Float(rel.unwrap_or(0.0) * (1.0 + sd * z))
                    }
                };
                values.push((path.clone(), v));
            }
            let drawn = {
                use rand::Rng;
                rng.next_u64() >> 32
            };
            let mut table = self.base.clone();
            table.insert("seed".into(), toml::Value::Integer(drawn as i64));
            for (path, v) in &values {
                set(&mut table, path, v.clone()).map_err(|problem| SimError::Scenario {
                    file: "sweep".into(),
                    field: path.clone(),
                    problem,
                })?;
            }
            let seed = match table.get("seed") {
                Some(toml::Value::Integer(s)) if seed_varied => *s as u64,
                _ => drawn,
            };
            let toml = toml::to_string(&table).map_err(|e| SimError::Scenario {
                file: "sweep".into(),
                field: "-".into(),
                problem: format!("cannot write run {index} as TOML: {e}"),
            })?;
            runs.push(RunSpec {
                index,
                values,
                seed,
                toml,
            });
        }
        Ok(runs)
    }

    /// Whether any path is drawn from a distribution (otherwise `n` repeats the grid with new
    /// noise seeds).
    pub fn has_distributions(&self) -> bool {
        self.vary.iter().any(|(_, s, _)| !s.is_grid())
    }
}

/// A uniform draw in `[0, 1)` (53 bits).
fn unit(rng: &mut Xoshiro256PlusPlus) -> f64 {
    use rand::Rng;
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sc() -> Scenario {
        Scenario::default_servo()
    }

    fn v(text: &str) -> toml::Value {
        let t: toml::Table = toml::from_str(&format!("x = {text}")).unwrap();
        t["x"].clone()
    }

    fn vary(items: &[(&str, &str)]) -> Vec<(String, toml::Value)> {
        items.iter().map(|(p, t)| (p.to_string(), v(t))).collect()
    }

    #[test]
    fn grids_times_n_with_distributions_drawn_per_run() {
        let plan = Plan::new(
            &sc(),
            &vary(&[
                ("inverter.dead_time_s", "[0.0, 1e-6]"),
                ("motor.rs_ohm", r#"["uniform", 2.5, 3.2]"#),
                ("controller.kind", r#"["foc", "foc_sensored", "foc"]"#),
                ("duration_s", "0.1"),
            ]),
            4,
            7,
        )
        .unwrap();
        assert_eq!(plan.len(), 2 * 3 * 4);
        let runs = plan.runs().unwrap();
        assert_eq!(runs, plan.runs().unwrap(), "deterministic");
        // Sorted paths; the last grid path (inverter...) fastest after the repeats.
        let names: Vec<_> = runs[0].values.iter().map(|(p, _)| p.as_str()).collect();
        assert_eq!(
            names,
            [
                "controller.kind",
                "duration_s",
                "inverter.dead_time_s",
                "motor.rs_ohm"
            ]
        );
        assert_eq!(runs[3].values[2].1, v("0.0"));
        assert_eq!(runs[4].values[2].1, v("1e-6"));
        assert_eq!(runs[8].values[0].1, v(r#""foc_sensored""#));
        let rs: Vec<f64> = runs
            .iter()
            .map(|r| r.values[3].1.as_float().unwrap())
            .collect();
        assert!(rs.iter().all(|x| (2.5..3.2).contains(x)));
        assert!(rs.windows(2).all(|w| w[0] != w[1]));
        let seeds: std::collections::BTreeSet<u64> = runs.iter().map(|r| r.seed).collect();
        assert_eq!(seeds.len(), runs.len());
        // The run's scenario carries its values.
        let s = Scenario::from_toml_str(&runs[5].toml, "run 5").unwrap();
        assert_eq!(s.motor.rs_ohm, rs[5]);
        assert_eq!(s.seed, runs[5].seed);
        assert_eq!(s.duration_s, 0.1);
        // Another seed, other draws.
        let other = Plan::new(
            &sc(),
            &vary(&[("motor.rs_ohm", r#"["normal", 3.0, 0.1]"#)]),
            2,
            8,
        )
        .unwrap()
        .runs()
        .unwrap();
        assert_ne!(other[0].seed, runs[0].seed);
    }

    #[test]
    fn relative_uses_the_told_parameter_and_paths_create_tables() {
        let plan = Plan::new(
            &sc(),
            &vary(&[
                ("observer.psi_f_wb", r#"["relative", 0.1]"#),
                ("load.0.after_nm", "[0.5, 1.0]"),
            ]),
            50,
            1,
        )
        .unwrap();
        let runs = plan.runs().unwrap();
        let psi = sc().motor.psi_f_wb;
        let mean = runs
            .iter()
            .map(|r| r.values[1].1.as_float().unwrap() / psi)
            .sum::<f64>()
            / runs.len() as f64;
        assert!((mean - 1.0).abs() < 0.05, "{mean}");
        let s = Scenario::from_toml_str(&runs[60].toml, "run").unwrap();
        assert_eq!(s.observer.psi_f_wb, runs[60].values[1].1.as_float());
        assert!(s.load.len() == 1);
    }

    #[test]
    fn bad_plans_are_refused_by_path() {
        let bad = |items: &[(&str, &str)], n: usize, want: &str| {
            let e = Plan::new(&sc(), &vary(items), n, 1).unwrap_err();
            assert!(e.contains(want), "{e}");
        };
        bad(
            &[("motor.rs_ohm", r#"["uniform", 3.0]"#)],
            1,
            "vary.motor.rs_ohm: expected",
        );
        bad(
            &[("motor.rs_ohm", r#"["uniform", 3.0, 2.0]"#)],
            1,
            "out of order",
        );
        bad(&[("motor.rs_ohm", r#"["normal", 3.0, -1.0]"#)], 1, ">= 0");
        bad(&[("motor.rs_ohm", "[]")], 1, "empty list");
        bad(&[("motor.rs_ohm.x", "[1.0]")], 1, "motor.rs_ohm is a value");
        bad(&[("load.3.after_nm", "[1.0]")], 1, "has 1 entries");
        bad(&[("motor..rs", "[1.0]")], 1, "not a dotted path");
        bad(
            &[("nothing.here", r#"["relative", 0.1]"#)],
            1,
            "needs a base value",
        );
        bad(&[], 0, "n must be");
        bad(&[("seed", "[1, 2]")], MAX_RUNS, "more than");
    }

    #[test]
    fn a_varied_seed_is_the_run_seed() {
        let runs = Plan::new(&sc(), &vary(&[("seed", "[11, 12]")]), 1, 1)
            .unwrap()
            .runs()
            .unwrap();
        assert_eq!(runs.iter().map(|r| r.seed).collect::<Vec<_>>(), [11, 12]);
    }
}
