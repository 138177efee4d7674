//! The tracking's configuration: [`ParameterTracking`] and [`RsTracking`], their defaults and
//! their validation (module docs of [`tracking`](super) give the method).

use crate::motor::positive;
use crate::observer::config::non_negative;
use crate::{ConfigError, Float, Param, to_t};

/// How the tracked `Rs` is found (module docs, "What can be told apart").
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum RsTracking<T> {
    /// `Rs` stays at its configured value; the tracked `psi_f` absorbs an `Rs` error on the
    /// q axis (the angle stays right with `i_d = 0`).
    Fixed,
    /// The split filter (module docs): the EKF's lumped flux, averaged over windows of
    /// `window_samples`, is the measurement `psi_f + Rs i_q / w` of a two-state Kalman filter
    /// on `(psi_f, Rs)`, with a pseudo-measurement tying both to one temperature (the thermal
    /// link) that decides only what the data leaves open; the resulting `Rs` is fed back
    /// into the EKF's model.
    Split {
        /// Temperature coefficient of the magnets' flux, 1/K (NdFeB about -0.0012, ferrite
        /// about -0.002). Must be negative.
        magnet_coefficient_per_k: T,
        /// Standard deviation of the thermal link, K: how far the windings' and the magnets'
        /// temperature rises may differ (module docs, "Resistance").
        link_sigma_k: T,
        /// Samples averaged into one measurement of the split filter. Windows turning slower
        /// than twice the tracking's minimum speed are skipped.
        window_samples: u32,
        /// Standard deviation of one window's lumped flux, fraction of the configured
        /// `psi_f`.
        measurement_sigma: T,
    },
}

/// Online tracking of `psi_f` and `Rs` (module docs). All fractions are of the configured
/// (nominal) parameter values of [`ObserverConfig::motor`](crate::observer::ObserverConfig::motor).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParameterTracking<T> {
    /// Initial standard deviation of `psi_f`, fraction of the configured value. Also the
    /// ceiling of its standard deviation (no process noise is added above it).
    pub psi_f_sigma0: T,
    /// Initial standard deviation of `Rs`, fraction of the configured value; also its ceiling.
    pub rs_sigma0: T,
    /// Random walk of `psi_f`, fraction of the configured value per square root of a second.
    pub psi_f_walk_per_sqrt_s: T,
    /// Random walk of `Rs`, fraction of the configured value per square root of a second.
    pub rs_walk_per_sqrt_s: T,
    /// Tracking is frozen while `|w_hat|` is below this speed, rad/s electrical, while the
    /// speed's standard deviation exceeds a fifth of `|w_hat|`, while the speed departs from
    /// its low-pass over 64 samples by more than 1 % plus three standard deviations (fast
    /// acceleration), and while the angle is
    /// uncertain.
    pub min_speed_rad_s: T,
    /// Tracking starts only after the angle has been tracked above the minimum speed for
    /// this many samples in a row (the convergence's large corrections must not move the
    /// parameters).
    pub settle_samples: u32,
    /// Lower and upper bound of the tracked `psi_f`, fractions of the configured value.
    pub psi_f_range: [T; 2],
    /// Lower and upper bound of the tracked `Rs`, fractions of the configured value.
    pub rs_range: [T; 2],
    /// Winding temperature at which the configured `Rs` and `psi_f` hold, deg C.
    pub reference_temperature_c: T,
    /// Temperature coefficient of the winding's resistance, 1/K (copper: 0.00393).
    pub rs_temperature_coefficient_per_k: T,
    /// How `Rs` is tracked.
    pub rs: RsTracking<T>,
    /// Start-up flux from the split filter's windows (with [`RsTracking::Split`] only; on by
    /// default in builds with the cargo feature `std`, off without it): until the EKF's own tracking has ended a window, the windows
    /// also run while the flux is frozen (a speed change, the settling time), and each window
    /// of an acceleration corrects the frozen flux (module docs of
    /// `ekf_core::observer::tracking`, "Tracking during transients"). Needs the cargo feature
    /// `std` ([`ConfigError::TransientFluxNotCompiled`](crate::ConfigError) without).
    pub transient_flux: bool,
    /// The thermal link's reference `(psi_f, Rs)` follows the split filter's windows wherever
    /// they have told `Rs` by themselves (the windows-only deviation of `Rs` within the link's
    /// own, `link_sigma_k alpha_cu Rs`): after a load step or through a speed ramp the link
    /// does not pull `Rs` back to the told value (module docs of
    /// `ekf_core::observer::tracking`, "The link's reference"). Off by default (the firmware's
    /// filter); `pyfoc.Ekf`'s defaults for a recorded drive turn it on with the input
    /// calibration. Needs the cargo feature `std`
    /// ([`ConfigError::LinkFollowsDataNotCompiled`](crate::ConfigError) without).
    pub link_follows_data: bool,
}

impl<T: Float> ParameterTracking<T> {
    /// The default for a sample time: initial (and ceiling) standard deviations 10 % of
    /// `psi_f` (a start 20 % off converges; a larger value makes the first adaptation after a
    /// hand-over jumpy) and 50 % of `Rs`; random walks 1 % of `psi_f` and 5 % of `Rs` per square root
    /// of a second; frozen below `|w_e| = 0.002 / Ts` (20 rad/s el. at 10 kHz; 2.4 % of the
    /// servo's rated speed) and for the first 500 samples (50 ms at 10 kHz) after the angle
    /// is tracked; `psi_f` within `[0.5, 1.5]` and `Rs` within `[0.3, 3]` times the
    /// configured values, which hold at 20 deg C; copper; `Rs` by the split filter with an
    /// NdFeB thermal link of 60 K, windows of 100 samples, 1 % per window; the start-up flux
    /// on where it is compiled (feature `std`; module docs of `ekf_core::observer::tracking`,
    /// "Tracking during transients").
    pub fn default_for(ts_s: T) -> Self {
        Self {
            psi_f_sigma0: to_t(0.1),
            rs_sigma0: to_t(0.5),
            psi_f_walk_per_sqrt_s: to_t(0.01),
            rs_walk_per_sqrt_s: to_t(0.05),
            min_speed_rad_s: to_t::<T>(0.002) / ts_s,
            settle_samples: 500,
            psi_f_range: [to_t(0.5), to_t(1.5)],
            rs_range: [to_t(0.3), to_t(3.0)],
            reference_temperature_c: to_t(20.0),
            rs_temperature_coefficient_per_k: to_t(0.00393),
            rs: RsTracking::Split {
                magnet_coefficient_per_k: to_t(-0.0012),
                link_sigma_k: to_t(60.0),
                window_samples: 100,
                measurement_sigma: to_t(0.01),
            },
            transient_flux: cfg!(feature = "std"),
            link_follows_data: false,
        }
    }

    /// Checks every field: standard deviations positive, walks and the minimum speed not
    /// negative, ranges finite with `0 < low <= 1 <= high`, the reference temperature
    /// finite, the copper coefficient positive, the magnet coefficient negative, the link's
    /// deviation and the window's deviation positive, a window of at least one sample.
    pub fn validate(&self) -> Result<(), ConfigError> {
        positive(self.psi_f_sigma0, Param::TrackingPsiSigma)?;
        positive(self.rs_sigma0, Param::TrackingRsSigma)?;
        non_negative(self.psi_f_walk_per_sqrt_s, Param::TrackingPsiWalk)?;
        non_negative(self.rs_walk_per_sqrt_s, Param::TrackingRsWalk)?;
        non_negative(self.min_speed_rad_s, Param::TrackingMinSpeed)?;
        for (range, param) in [
            (self.psi_f_range, Param::TrackingPsiRange),
            (self.rs_range, Param::TrackingRsRange),
        ] {
            let [lo, hi] = range;
            if !(lo.is_finite() && hi.is_finite()) {
                return Err(ConfigError::NonFinite(param));
            }
            if !(lo > T::zero() && lo <= T::one() && hi >= T::one()) {
                return Err(ConfigError::OutOfRange(param));
            }
        }
        if !self.reference_temperature_c.is_finite() {
            return Err(ConfigError::NonFinite(Param::TrackingReferenceTemperature));
        }
        positive(
            self.rs_temperature_coefficient_per_k,
            Param::TrackingTemperatureCoefficient,
        )?;
        if let RsTracking::Split {
            magnet_coefficient_per_k: b,
            link_sigma_k,
            window_samples,
            measurement_sigma,
        } = self.rs
        {
            if !b.is_finite() {
                return Err(ConfigError::NonFinite(Param::TrackingMagnetCoefficient));
            }
            if b >= T::zero() {
                return Err(ConfigError::OutOfRange(Param::TrackingMagnetCoefficient));
            }
            positive(link_sigma_k, Param::TrackingLinkSigma)?;
            positive(measurement_sigma, Param::TrackingWindowSigma)?;
            if window_samples == 0 {
                return Err(ConfigError::OutOfRange(Param::TrackingWindow));
            }
        }
        Ok(())
    }
}

impl<T: Float> ParameterTracking<T> {
    /// [`validate`](Self::validate), and the derived variances finite and positive for the
    /// motor's `psi_f`, `Rs` and the sample time (no overflow or underflow to 0), the
    /// kelvins per ohm finite.
    pub fn validate_for(&self, psi_f: T, rs: T, ts_s: T) -> Result<(), ConfigError> {
        self.validate()?;
        let usable = |v: T| v.is_finite() && v > T::zero();
        let sq = |v: T| v * v;
        if !usable(sq(self.psi_f_sigma0 * psi_f)) {
            return Err(ConfigError::OutOfRange(Param::TrackingPsiSigma));
        }
        if !usable(sq(self.rs_sigma0 * rs)) {
            return Err(ConfigError::OutOfRange(Param::TrackingRsSigma));
        }
        let q_psi = sq(self.psi_f_walk_per_sqrt_s * psi_f) * ts_s;
        if !q_psi.is_finite() {
            return Err(ConfigError::OutOfRange(Param::TrackingPsiWalk));
        }
        let q_rs = sq(self.rs_walk_per_sqrt_s * rs) * ts_s * to_t(f64::from(u32::MAX));
        if !q_rs.is_finite() {
            return Err(ConfigError::OutOfRange(Param::TrackingRsWalk));
        }
        if !(T::one() / (self.rs_temperature_coefficient_per_k * rs)).is_finite() {
            return Err(ConfigError::OutOfRange(
                Param::TrackingTemperatureCoefficient,
            ));
        }
        Ok(())
    }
}
