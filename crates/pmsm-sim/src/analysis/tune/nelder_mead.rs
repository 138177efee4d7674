//! A small derivative-free minimizer: the Nelder-Mead simplex method with the adaptive
//! coefficients of Gao and Han (2012), which keep it effective beyond two or three dimensions:
//! reflection 1, expansion `1 + 2/n`, contraction `3/4 - 1/(2n)`, shrink `1 - 1/n`.
//!
//! Converged: every vertex within `x_tol` of the best one, and their values within `f_tol`
//! (or the simplex collapsed to rounding, where a noisy objective cannot do better).
//!
//! Non-finite objective values (NaN or infinities) count as `+inf`: such a point is never kept
//! as the best one, so an objective may return `f64::INFINITY` for an infeasible point.
//! After convergence the search restarts once from the best point with the initial step (a
//! collapsed simplex is the method's known failure); the second run's result is returned.

/// Options of [`minimize`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct NmOptions {
    /// Largest number of objective evaluations (the search stops there, unconverged).
    pub max_evaluations: usize,
    /// Converged when every vertex lies within this distance (max norm) of the best one...
    pub x_tol: f64,
    /// ...and the objective values differ by at most this much (absolute).
    pub f_tol: f64,
}

impl Default for NmOptions {
    fn default() -> Self {
        Self {
            max_evaluations: 1000,
            x_tol: 1e-6,
            f_tol: 1e-10,
        }
    }
}

/// The result of [`minimize`].
#[derive(Clone, Debug, PartialEq)]
pub struct NmResult {
    /// The best point found.
    pub x: Vec<f64>,
    /// The objective there (`+inf` if no finite value was found).
    pub f: f64,
    /// Objective evaluations used.
    pub evaluations: usize,
    /// Whether the tolerances were met (rather than the evaluation budget used up).
    pub converged: bool,
}

/// Minimizes `f` from `x0`; the initial simplex is `x0` and `x0 + step[i] e_i`.
///
/// # Panics
///
/// Never for consistent input; `step` must have the length of `x0` (a shorter `step` is
/// padded with its last value, or 1).
pub fn minimize(
    mut f: impl FnMut(&[f64]) -> f64,
    x0: &[f64],
    step: &[f64],
    opts: &NmOptions,
) -> NmResult {
    let n = x0.len();
    let step: Vec<f64> = (0..n)
        .map(|i| {
            step.get(i)
                .or(step.last())
                .copied()
                .filter(|s| s.is_finite() && *s != 0.0)
                .unwrap_or(1.0)
        })
        .collect();
    let count = core::cell::Cell::new(0usize);
    let mut eval = |x: &[f64]| {
        count.set(count.get() + 1);
        let v = f(x);
        if v.is_nan() { f64::INFINITY } else { v }
    };
    if n == 0 {
        let v = eval(x0);
        return NmResult {
            x: Vec::new(),
            f: v,
            evaluations: count.get(),
            converged: true,
        };
    }
    let mut best = (x0.to_vec(), f64::INFINITY);
    let mut converged = false;
    // The first run, then one restart from its best point.
    for _run in 0..2 {
        if count.get() >= opts.max_evaluations {
            break;
        }
        let (x, fx, ok) = run(&mut eval, &best.0, &step, opts, &|| count.get());
        converged = ok;
        if fx <= best.1 || !best.1.is_finite() {
            best = (x, fx);
        }
    }
    let evaluations = count.get();
    NmResult {
        x: best.0,
        f: best.1,
        evaluations,
        converged,
    }
}

/// One Nelder-Mead run; returns `(best x, best f, converged)`.
fn run(
    f: &mut dyn FnMut(&[f64]) -> f64,
    x0: &[f64],
    step: &[f64],
    opts: &NmOptions,
    used: &dyn Fn() -> usize,
) -> (Vec<f64>, f64, bool) {
    let n = x0.len();
    let nf = n as f64;
    let (alpha, chi, gamma, sigma) = if n >= 2 {
        (1.0, 1.0 + 2.0 / nf, 0.75 - 0.5 / nf, 1.0 - 1.0 / nf)
    } else {
        (1.0, 2.0, 0.5, 0.5)
    };
    let mut simplex: Vec<(Vec<f64>, f64)> = Vec::with_capacity(n + 1);
    simplex.push((x0.to_vec(), f(x0)));
    for i in 0..n {
        let mut x = x0.to_vec();
        x[i] += step[i];
        let v = f(&x);
        simplex.push((x, v));
    }
    let point = |c: &[f64], d: &[f64], t: f64| -> Vec<f64> {
        c.iter().zip(d).map(|(c, d)| c + t * (d - c)).collect()
    };
    loop {
        simplex.sort_by(|a, b| a.1.total_cmp(&b.1));
        let f_best = simplex[0].1;
        let f_worst = simplex[n].1;
        let x_spread = simplex[1..]
            .iter()
            .flat_map(|(x, _)| x.iter().zip(&simplex[0].0).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max);
        let f_spread = if f_worst.is_finite() {
            f_worst - f_best
        } else {
            f64::INFINITY
        };
        // A simplex collapsed to rounding cannot improve: the objective is noisy at this
        // scale (e.g. a filter's sensitivity to the last bits of its parameters).
        let scale = simplex[0].0.iter().fold(1.0f64, |m, v| m.max(v.abs()));
        let collapsed = x_spread <= 1e-12 * scale;
        if x_spread <= opts.x_tol && (f_spread <= opts.f_tol || collapsed) {
            return (simplex[0].0.clone(), f_best, true);
        }
        if used() >= opts.max_evaluations {
            return (simplex[0].0.clone(), f_best, false);
        }
        // Centroid of all but the worst.
        let mut c = vec![0.0; n];
        for (x, _) in &simplex[..n] {
            for (ci, xi) in c.iter_mut().zip(x) {
                *ci += xi / nf;
            }
        }
        let worst = simplex[n].0.clone();
        let xr = point(&c, &worst, -alpha);
        let fr = f(&xr);
        if fr < f_best {
            let xe = point(&c, &xr, chi);
            let fe = f(&xe);
            simplex[n] = if fe < fr { (xe, fe) } else { (xr, fr) };
            continue;
        }
        if fr < simplex[n - 1].1 {
            simplex[n] = (xr, fr);
            continue;
        }
        let (xc, fc, accept) = if fr < f_worst {
            // Outside contraction.
            let xc = point(&c, &xr, gamma);
            let fc = f(&xc);
            (xc, fc, fc <= fr)
        } else {
            // Inside contraction.
            let xc = point(&c, &worst, gamma);
            let fc = f(&xc);
            (xc, fc, fc < f_worst)
        };
        if accept {
            simplex[n] = (xc, fc);
            continue;
        }
        // Shrink towards the best vertex.
        let x_best = simplex[0].0.clone();
        for v in simplex.iter_mut().skip(1) {
            let x = point(&x_best, &v.0, sigma);
            let fx = f(&x);
            *v = (x, fx);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rosenbrock_2d() {
        let rosen = |x: &[f64]| 100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2);
        let r = minimize(rosen, &[-1.2, 1.0], &[0.5], &NmOptions::default());
        assert!(r.converged, "{r:?}");
        assert!(
            (r.x[0] - 1.0).abs() < 1e-4 && (r.x[1] - 1.0).abs() < 1e-4,
            "{r:?}"
        );
        assert!(r.f < 1e-8);
        assert!(r.evaluations <= 1000);
    }

    #[test]
    fn badly_scaled_quadratic_6d() {
        let scales = [1.0, 10.0, 100.0, 0.1, 3.0, 30.0];
        let target = [0.5, -2.0, 1.0, 3.0, -0.25, 0.0];
        let q = |x: &[f64]| {
            x.iter()
                .zip(&target)
                .zip(&scales)
                .map(|((x, t), s)| s * (x - t).powi(2))
                .sum::<f64>()
        };
        let r = minimize(
            q,
            &[0.0; 6],
            &[1.0],
            &NmOptions {
                max_evaluations: 5000,
                ..NmOptions::default()
            },
        );
        assert!(r.converged, "{r:?}");
        for (x, t) in r.x.iter().zip(&target) {
            assert!((x - t).abs() < 1e-3, "{r:?}");
        }
    }

    #[test]
    fn infeasible_and_nan_regions_are_avoided() {
        // Minimum at x = 2 on the edge of a NaN region (x > 2.5) and an infinite one (x < 0).
        let g = |x: &[f64]| {
            if x[0] > 2.5 {
                f64::NAN
            } else if x[0] < 0.0 {
                f64::INFINITY
            } else {
                (x[0] - 2.0).powi(2) + (x[1] + 1.0).powi(2)
            }
        };
        let r = minimize(g, &[1.0, 0.0], &[1.0], &NmOptions::default());
        assert!(r.f.is_finite());
        assert!(
            (r.x[0] - 2.0).abs() < 1e-4 && (r.x[1] + 1.0).abs() < 1e-4,
            "{r:?}"
        );
    }

    #[test]
    fn budget_is_respected_and_reported() {
        let mut calls = 0;
        let rosen = |x: &[f64]| {
            calls += 1;
            100.0 * (x[1] - x[0] * x[0]).powi(2) + (1.0 - x[0]).powi(2)
        };
        let opts = NmOptions {
            max_evaluations: 40,
            ..NmOptions::default()
        };
        let r = minimize(rosen, &[-1.2, 1.0], &[0.5], &opts);
        assert!(!r.converged);
        // A step may finish a shrink (n evaluations) past the budget.
        assert!(r.evaluations <= 40 + 2, "{}", r.evaluations);
        assert_eq!(r.evaluations, calls);
    }

    #[test]
    fn noisy_objective_converges_to_the_noise_floor() {
        // A quadratic plus deterministic noise of 1e-6 that changes with the last bits of x.
        let noisy = |x: &[f64]| {
            let h = x.iter().fold(0u64, |h, v| {
                (h ^ v.to_bits()).wrapping_mul(0x9e37_79b9_7f4a_7c15)
            });
            (x[0] - 1.0).powi(2)
                + (x[1] + 2.0).powi(2)
                + 1e-6 * (h >> 11) as f64 / (1u64 << 53) as f64
        };
        let r = minimize(noisy, &[0.0, 0.0], &[1.0], &NmOptions::default());
        assert!(r.converged, "{r:?}");
        assert!(
            (r.x[0] - 1.0).abs() < 2e-3 && (r.x[1] + 2.0).abs() < 2e-3,
            "{r:?}"
        );
    }

    #[test]
    fn one_dimension_and_zero_dimensions() {
        let r = minimize(
            |x: &[f64]| (x[0] - 3.0).powi(2),
            &[0.0],
            &[1.0],
            &NmOptions::default(),
        );
        assert!((r.x[0] - 3.0).abs() < 1e-5, "{r:?}");
        let r = minimize(|_: &[f64]| 7.0, &[], &[], &NmOptions::default());
        assert_eq!((r.f, r.evaluations), (7.0, 1));
    }
}
