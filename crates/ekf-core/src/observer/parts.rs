//! The pieces of one observer step, callable one at a time, for the Cortex-M4F cost map
//! (`crates/foc-firmware`, README "Cost on the Cortex-M4F"). Not part of the API: hidden from
//! the docs, free to change.
//!
//! A [`Parts`] is a copy of an observer's model, state and covariance; each method runs one
//! piece of a surface motor's untracked step on that copy (nothing is stored) and returns a
//! few of its results, so that a caller can keep them alive (`black_box`) while counting.

use nalgebra::Vector4;

use super::PmsmObserver;
use super::structured::{self, Outcome, Sym4};
use crate::{Float, PmsmModel};

/// A copy of an observer's model, state and covariance (module docs).
#[derive(Clone, Debug)]
pub struct Parts<T: Float> {
    model: PmsmModel<T>,
    x: Vector4<T>,
    p: Sym4<T>,
}

impl<T: Float> Parts<T> {
    /// Copies the observer's model, posterior state and covariance.
    pub fn new(obs: &PmsmObserver<T>) -> Self {
        Self {
            model: obs.model,
            x: obs.x,
            p: obs.p,
        }
    }

    /// Sine and cosine of the angle (the step's trig).
    #[inline(always)]
    pub fn trig(&self) -> (T, T) {
        self.x[3].sin_cos_angle()
    }

    /// The transition terms of a surface motor: trig, the lag-free EMF gain `G(w)` (one
    /// division) and the EMF term with its Jacobian entries.
    #[inline(always)]
    pub fn terms(&self, u: [T; 2]) -> [T; 6] {
        let x = &self.x;
        let t = self
            .model
            .discrete()
            .transition_terms::<false>(x[0], x[1], x[3], x[2], u, false);
        [t.ea, t.eb, t.ea_w, t.ea_th, t.eb_w, t.eb_th]
    }

    /// The whole structured prediction of a surface motor: the terms, the predicted state and
    /// the covariance `Phi P Phi^T + Q` on the 10 unique entries.
    #[inline(always)]
    pub fn predict(&self, u: [T; 2]) -> (Vector4<T>, [T; 10]) {
        let (x, p, _) = structured::predict::<T, false>(
            self.model.discrete(),
            self.model.q_sym(),
            &self.x,
            &self.p,
            u,
            false,
        );
        (x, flat(&p))
    }

    /// The correction's innovation part only: `S = P00.. + R`, its determinant and inverse
    /// (one division), the innovation and the NIS (the gate's input); no gain, no update.
    #[inline(always)]
    pub fn innovation(&self, i: [T; 2]) -> Option<T> {
        match structured::correct(&self.model, &self.x, &self.p, i, |_| true) {
            Ok(Outcome::Skipped(c)) => Some(c.nis),
            _ => None,
        }
    }

    /// The whole structured correction: innovation, gain `K = P H^T S^-1`, state update, the
    /// configured covariance update and the finiteness check of the result.
    #[inline(always)]
    pub fn correct(&self, i: [T; 2]) -> Option<(Vector4<T>, [T; 10])> {
        match structured::correct(&self.model, &self.x, &self.p, i, |_| false) {
            Ok(Outcome::Updated(post)) => Some((post.x, flat(&post.p))),
            _ => None,
        }
    }
}

fn flat<T: Float>(p: &Sym4<T>) -> [T; 10] {
    [
        p.p00, p.p01, p.p02, p.p03, p.p11, p.p12, p.p13, p.p22, p.p23, p.p33,
    ]
}
