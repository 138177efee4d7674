//! The reference filter's PMSM observer: an EKF on the alpha-beta model of a surface-mounted
//! PMSM, and of an interior one through the active flux (section below).
//!
//! State `x = [i_a, i_b, w_e, theta]` (A, A, rad/s electrical, rad electrical), input
//! `u = [u_a, u_b]` (V), measurement `z = [i_a, i_b]` (A), `H = [I2 0]`. Continuous model
//! (`docs/design.md` section 2, with the sign of `u` of the reference filter's matrix form):
//!
//! ```text
//! di_a/dt = (-Rs i_a + w psi sin(th) + u_a) / Ls
//! di_b/dt = (-Rs i_b - w psi cos(th) + u_b) / Ls
//! dw/dt   = 0        (random walk through Q)
//! dth/dt  = w
//! ```
//!
//! # Timing (`docs/design.md` section 4)
//!
//! `step(u_prev, i)` at sample `k` predicts over `[t_{k-1}, t_k)` with `u_prev = u[k-1]`, the
//! voltage the inverter held over that period, then corrects with `i = i[k]`, the currents
//! sampled at `t_k`. A new observer's `x0`, `P0` describe the estimate one period before its
//! first sample, and its first call passes `u_prev = 0`. The angle is wrapped to `[-pi, pi)`
//! after the prediction and after the correction.
//!
//! # Discretizations ([`Discretization`])
//!
//! With `a = Rs / Ls`, `c = psi_f / Ls`, `x = [i_a, i_b, w, th]` the posterior at `t_{k-1}`:
//!
//! **`ForwardEuler`** (the reference filter's loop, exactly): `x- = x + Ts (f(x) + B u)`,
//! `Phi = I + Ts F(x)`:
//!
//! ```text
//! i_a- = i_a + Ts (-a i_a + c w sin th + u_a / Ls)
//! i_b- = i_b + Ts (-a i_b - c w cos th + u_b / Ls)
//! w-   = w,   th- = th + Ts w
//! ```
//!
//! The back-EMF is frozen at the start-of-period angle, although the rotor turns by `w Ts` during
//! the period; the angle estimate is biased by about `w Ts / 2`.
//!
//! **`LagFree`** (the default): the exact solution of the current equations over one period for a
//! voltage held constant and a rotor turning at constant speed `w`. With `alpha = exp(-a Ts)` and
//! the complex gain
//!
//! ```text
//! G(w) = (exp(j w Ts) - alpha) / (a + j w)            [s],   G -> Ts as a, w -> 0
//! i-   = alpha i + (1 - alpha) / Rs u + c w Re/Im{ -j e^{j th} G(w) }
//!      i.e. i_a- = alpha i_a + (1 - alpha) u_a / Rs + c w ( sin th Re G + cos th Im G)
//!           i_b- = alpha i_b + (1 - alpha) u_b / Rs + c w ( sin th Im G - cos th Re G)
//! w- = w,   th- = th + Ts w
//! ```
//!
//! For small `a Ts`, `G ~ Ts e^{j w Ts / 2}`: the EMF is in effect taken at the mid-period angle
//! `th + w Ts / 2`, which removes the lag. `Phi` is the exact Jacobian of this map (`d/dth`
//! rotates the EMF term by 90 deg; `d/dw` uses `d(w G)/dw = G + w G'`,
//! `G' = j (Ts e^{j w Ts} - G) / (a + j w)`).
//!
//! # Interior (salient) motors: the active-flux model
//!
//! With `Ld != Lq` ([`MotorParams::kind`](crate::MotorParams::kind)) the stator equations in the
//! alpha-beta frame have an angle-dependent inductance matrix. Of the two usual ways to write an
//! observer model for them, the **active flux** (Boldea 2008) is used here, not the extended EMF
//! (Chen 2003): it keeps the state, the input and, above all, the structure of the surface model
//! (a diagonal current block in `Phi`, the same 10-entry covariance schedule, the same lag-free
//! discretization and safeguards), so `Ld == Lq` *is* the surface observer and a salient step
//! costs a few tens of instructions more, not a new filter. The extended EMF would need the EMF's
//! magnitude, which changes with the load and the current's derivative, as a state or a fast
//! parameter.
//!
//! The active flux `psi_a = psi_f + (Ld - Lq) i_d` along the rotor's d axis turns the machine
//! into a non-salient one of inductance `Lq`:
//!
//! ```text
//! Lq di/dt = u - Rs i - j w psi_a e^{j th} - (d psi_a/dt) e^{j th}        (i = i_a + j i_b)
//! ```
//!
//! **Step.** The surface step above with `Ls -> Lq` and `c = psi_a / Lq`, where
//! `i_d = i_a cos th + i_b sin th` comes from the posterior at the start of the period. In steady
//! state `psi_a` is constant and the step is exact (no lag, no bias; measured in
//! `docs/accuracy.md`). The last term, `(Ld - Lq) di_d/dt`, matters only while `i_d` moves (MTPA
//! load steps): the model lets `i_d` respond through `Lq`, the motor through `Ld`, so to first
//! order the motor's change of `i_d` over the period is `Lq / Ld` times the model's. The step
//! adds
//!
//! ```text
//! (Lq / Ld - 1) (i_d- - i_d) e^{j (th + w Ts)}       (i_d- the model's predicted d current)
//! ```
//!
//! which is zero in steady state (so it cannot bias) and keeps load steps clean
//! (`docs/accuracy.md`). It applies once the filter has **locked** (angle tracked and the
//! innovations settled, the gate's running NIS at or below its settled level) and while the angle
//! stays tracked; during the initial convergence the d axis is unknown, and the correction would
//! triple (traction motor: `Lq / Ld = 3`) the model's d-axis response along a wrong axis.
//!
//! **Jacobian.** `Phi` keeps the block structure `[[A, J], [0, B]]`; for a salient motor the
//! current block `A` is a full 2 x 2 (`decay I` plus the active flux's
//! `d psi_a / d i = (Ld - Lq) (cos th, sin th)` and the correction's dependence on the currents),
//! and `J` carries both terms' derivatives in `w` and `th` (`d psi_a / d th = (Ld - Lq) i_q`).
//! The covariance schedule then has a salient variant (a dozen more products). Without these
//! terms the gain is wrong (the fixed point is not) and the interior convergence grid fails cells
//! with the correction on. The generic [`PmsmModel`] carries the same terms, so the structured
//! update still equals the generic `Ekf` (`tests/structured.rs`).
//!
//! **Tracking.** The tracked parameter is the magnet flux `psi_f`; `psi_a` follows from it and
//! `i_d` each step (`d psi_a / d psi_f = 1`: the flux's Jacobian column is the surface one).
//!
//! # Implausible input (always on)
//!
//! Before anything else a step refuses, state kept, a voltage that is not finite or that would
//! move the stator flux by more than [`MAX_INPUT_FLUX_RATIO`] (20) magnet fluxes over one
//! sample time (`|u| Ts > 20 psi_f`: [`EkfError::ImplausibleInput`](crate::EkfError)), and a
//! measured current that is not finite or above [`MAX_CURRENT_RATIO`] (100) characteristic
//! currents `psi_f / L_d` ([`EkfError::ImplausibleMeasurement`](crate::EkfError)). Neither
//! occurs on a drive: at full bus voltage a motor whose base speed turns `w Ts <= 1.3` rad per
//! period (the fastest recorded drive here) applies at most a few `psi_f` per period, and its
//! currents stay within a few `psi_f / L_d`. They are corrupted samples: one voltage of
//! 670 kV and one current of 1.4e17 A in a real ESC log, where taking them ruined the
//! estimate for the rest of the record (the feedforward's load estimate took the first, the
//! covariance health's reset from the measured currents the second). A caller with
//! per-sample periods treats a refused sample as a skipped cycle (`pyfoc` adds its period to
//! the next row's). The test is one comparison of each squared magnitude on the common path.
//!
//! # Safeguards (on in [`ObserverConfig::new`], off in [`ObserverConfig::seed`])
//!
//! After the correction of every step, in this order; each is an `Option` field of
//! [`ObserverConfig`], reported per step in [`Estimate`] and counted in [`ObserverCounters`].
//! Together they add a few tens of instructions to a step (no division, no square root).
//!
//! **Innovation gate** ([`InnovationGate`]). The correction's `NIS = y^T S^-1 y` is, for a
//! consistent filter, chi-square distributed with 2 degrees of freedom:
//! `P(NIS > g) = exp(-g / 2)`. While the filter is *settled* (angle variance below the status
//! limit and the running mean of the accepted NIS, each clamped to the threshold, at most
//! `settled_nis`), a sample with `NIS > nis_threshold` is rejected: the step keeps the prediction
//! (`x = x-`, `P = P-`, as if the sample were missing) and reports `rejected`. After
//! `max_consecutive` rejections in a row the next sample is accepted whatever its NIS and the
//! gate stays open until an accepted NIS is below the threshold again, so that a real change is
//! not locked out (counted as `gate_reopened`). During the initial convergence (NIS far above 2)
//! the gate does not act.
//!
//! **Wrong branch** ([`BranchCheck`]). `(w, th)` and `(-w, th + pi)` give the same back-EMF
//! (`docs/design.md` section 3); only `dth/dt = w` tells them apart. On the wrong branch the
//! prediction turns the angle at `w_hat` while the measured EMF turns the other way, so the
//! corrections `K_th y` keep cancelling the predicted motion. A CUSUM test accumulates that
//! missing motion (in radians) while the filter is tracking above a minimum speed; past
//! `threshold_rad` the state moves to the other branch: `theta += pi`, `w = -w`, `P = T P T` with
//! `T = diag(1, 1, -1, 1)`, and the angle variance is raised by `flip_angle_sigma_rad^2`
//! (reported as `branch_flipped`). Near standstill, where the EMF and hence the branch is not
//! observable, the test sleeps and forgets.
//!
//! **Covariance health** ([`CovarianceHealth`]). `P` must have a positive diagonal and
//! `trace(P) <= trace_factor * trace(P0)` (its entries are finite: every step that would make
//! them non-finite is refused), and the state must be plausible: `|i_a| + |i_b|` at most
//! `current_factor` (100) times the short-circuit current `psi_f / Ls`, `|w_e| Ts <= pi`. (The
//! state bound matters after absurd but finite data, e.g. a sample of 1e30 A accepted during
//! convergence: without it the next steps overflow and are refused forever.) `trace(P)` mixes
//! units; with [`default_p0`] it is dominated by the speed variance, `(0.05 / Ts)^2`, so the
//! default bound (factor 100) means a speed standard deviation of about `0.5 / Ts` (5000 rad/s
//! el. at 10 kHz): the filter has lost the rotor entirely. On failure the observer resets itself:
//! currents = the measured currents (after [`PmsmObserver::predict`]: the estimated ones), each 0
//! when beyond its bound; speed kept when within its bound, angle when finite (else 0), `P = P0`,
//! gate and branch test restarted; reported as `covariance_reset`. The check runs after every
//! `step`, `predict` and `correct`, and also when a step is refused for a singular `S` or a
//! non-finite result: when the stored `P` or state is unhealthy, or at the [`MAX_REFUSALS`]-th
//! (3rd) such refusal in a row, the reset replaces the error (so the filter is never stuck on a
//! state it cannot step from, e.g. an `S` singular to rounding in `f32`). Refusals of non-finite
//! input are the caller's and do not count.
//!
//! **Divergence** (part of the covariance health). A filter can settle where its covariance
//! claims to know the angle while its innovations say the model cannot explain the data (an
//! interior motor at rated load started far off: `docs/accuracy.md`). When the `NIS` exceeds
//! `divergence_nis` (1000: a chi-square(2) tail of `e^-500`) in `divergence_samples` (200)
//! tracked steps in a row (counted by the innovation gate: the check needs it), the observer
//! resets itself as above.
//!
//! **Consistency** ([`ConsistencyCheck`]). The covariance reflects the model's noise, not a model
//! error: it stays small while the filter sits on a wrong solution or falls behind a fast
//! transient it cannot follow. The innovations see it. The check keeps a fast mean (4 samples)
//! and a slow, clamped baseline (1024 samples) of the `NIS`; while the fast mean exceeds 8 times
//! the baseline, or one sample 10 times, the status reads [`Status::Uncertain`] (reported as
//! [`Estimate::inconsistent`]), until the fast mean has stayed at or below half that limit for 32
//! steps. The baseline learns the innovation level of the data (a recorded drive's noise and
//! model error that the configured `R` does not describe); its clamp at 4 times itself keeps a
//! loss from teaching it, its ceiling (400) bounds the error ever accepted as noise. It changes
//! no state: only the status. With the check on, the status also requires the back-EMF to be
//! known to be there: at the ends of the last 8 blocks of 8 samples in a row (tested once per
//! block), the speed estimate away from zero by five of its standard deviations
//! (`w^2 >= 25 P22`) and the back-EMF above what the told voltage errors' uncertainty can fake,
//! `(w psi_f)^2 >= 9 ((sigma_Rs |i|)^2 + sigma_v^2)` with the tracking's standard deviation of
//! `Rs` (none without tracking) and `sigma_v` half the told inverter voltage
//! ([`ObserverConfig::inverter_voltage_v`]; none untold; the two added in quadrature, as
//! independent errors): a told inverter voltage that is wrong fakes an EMF of its size, which
//! the innovations cannot tell from the right one (`tests/inverter_floor.rs`: the small fast
//! motor told 0.5 V reads `Uncertain` at 115 rad/s el., 0.69 V of EMF, where it read `Tracking`
//! 79 % of the time without the term; on a recorded ESC drive told 0.3 V for about 0.03 V it
//! read `Tracking` more than 45 deg off on 1928 samples, at low speed, and on none with it);
//! or an angle fused by [`PmsmObserver::correct_angle`] within the last 64 steps
//! (high-frequency injection at standstill). Two wrong solutions have innovations as small as
//! the right one's there. (1) The `theta + pi` branch: `(w, th)` and `(-w, th + pi)` give the
//! same EMF, and only the angle's motion tells them apart, which the speed drift below sees
//! once `|w|` is several of its deviations and it has had its time constant (32 samples)
//! twice: a filter started from rest, or coming out of a zero crossing, on the wrong branch
//! (the drone and 2.2 kW presets' starts) read `Tracking` for up to 73 samples before the
//! hold. (2) Told a resistance too high at low speed under load, the voltage a wrong `Rs`
//! leaves is read as back-EMF, and the filter can settle at a speed of the wrong sign (the
//! suite's reversal row of the small fast motor told it 100 K cold). At a start from rest the filter's angle
//! variance collapses within a few samples although no EMF has told it anything; this rule keeps
//! such a start `Uncertain`. ([`Estimate::angle_tracked`] and [`Estimate::inconsistent`] give the
//! parts; the check's effect on recorded drives is in `docs/accuracy.md`.)
//!
//! **Speed drift** (part of the consistency check). A filter whose model is far from the motor
//! (a saturating machine told its small-signal inductances) can settle on a wrong solution where
//! its angle advances at the rotor's rate while its speed state is elsewhere: each correction
//! pulls the angle back by the same amount, `K_th y` has a non-zero mean, and the innovations,
//! which the baseline has learnt, look ordinary. In a healthy filter the angle advances by
//! `w Ts` plus corrections that average out (an acceleration leaves a mean correction of the
//! speed lag only). The check keeps the mean `d` of the angle correction over `drift_samples`
//! (32) steps and reads the status `Uncertain` while `|d| > drift_ratio |w| Ts + drift_sigmas
//! sqrt(P_ww) Ts` (0.25 and 3), trusted again after the hold with `|d|` at or below half that.
//! (foc's health monitor makes the same comparison on its own averages.) On the saturated
//! PM-SyRM told its small-signal constants through [`ObserverConfig::new`] it finds the 0.4 s after a generating step where the
//! filter sits 145 deg off with its speed 1.8 times the rotor's (`docs/accuracy.md`).
//!
//! **Model fit** (part of the consistency check). A model far from the motor can also settle
//! where its innovations are ordinary and its angle turns at its speed state: the checks above
//! see nothing, yet the angle is far off. What such a state cannot hide is the flux the model
//! reads the angle from. The angle is the direction of the active flux
//! `psi_a = psi_f + (Ld - Lq) i_d` (section "Interior motors"), which points along the magnet
//! (`psi_a > 0`) for every current a drive applies: with `Lq > Ld` every closed-loop law (MTPA,
//! field weakening) drives `i_d <= 0`, so `psi_a >= psi_f`, and an open-loop start (I/f), whose
//! current leads the rotor and so has `i_d > 0`, keeps it positive as long as `i_d` stays below
//! the reluctance limit `psi_f / (Lq - Ld)` (120 A on the traction IPM, whose I/f current is
//! 81 A: `psi_a` falls to a third there, which is why the bound is zero and not a fraction of
//! `psi_f`); with `Ld > Lq`, `psi_a >= psi_f Lq / Ld` for any `|i_d|` up to the characteristic
//! current `psi_f / Ld`. At the end of each block of 8 samples the check reads the estimate as
//! the model does, and finds the fit implausible when
//!
//! - the estimate's active flux (the tracked flux, `i_d` in the estimated frame) is below
//!   zero: the estimated d axis is not the magnet's. A filter that holds the motor's q current
//!   as a positive d current reads the EMF of a reluctance flux its model invented, a magnet
//!   pointing backwards, or
//! - the tracked `psi_f` is at a bound of its range ([`ParameterTracking::psi_f_range`], 0.5 to
//!   1.5 times the configured value by default; within 2 % of the configured value of it): the
//!   data ask for a flux the motor's magnet cannot have (heat moves it by about 12 % per
//!   100 K), so the fit has pushed the flux to absorb another error of the model, and the
//!   angle carries what is left of it.
//!
//! While implausible the status reads [`Status::Uncertain`] ([`Estimate::inconsistent`]: foc's
//! health monitor sees it too) until a block's end finds the fit plausible and the hold (32
//! steps) has passed. It changes no state. It runs out of line once in 8 samples (the
//! Cortex-M4F step: 1030 instructions, 1028 without it, a change of register allocation; no
//! work on the other 7 samples). The observer on a flux map
//! ([`MapObserver`](crate::saturated::MapObserver)) reads its flux from the map, not from
//! constants: only the tracked flux's bound applies there, and it tracks none.
//!
//! Measured on the independent saturating PM-SyRM plant (`cargo test --release -p ekf-core
//! --test saturated -- --nocapture`): samples `Tracking` while more than 45 deg off 0 / 0 / 0
//! for the observer told the small-signal constants through [`ObserverConfig::saturating`] /
//! [`ObserverConfig::new`] / told the rated chord values (1719 / 8369 / 65 without the model
//! fit). There the small-signal filter settles 105-125 deg off with an active flux of -0.8 to
//! -1.7 Wb (`i_d` estimated +10 to +18 A while the motor runs at `i_d = 0`); the other two sit
//! 38-50 deg off after the 150 % current step with their tracked flux at its lower bound and
//! a NIS about 300 that the consistency baseline has learnt within 60 ms, then 125-130 deg off
//! after the generating step with an active flux of -0.4 Wb. The price is there too: their status reads
//! `Tracking` within 45 deg 38.4 / 8.5 / 53.5 % of the run (55.4 / 8.5 / 64.0 % without), the
//! difference the 11-19 deg off stretch after the reversal, whose flux is still at its bound.
//! On `pmsm-sim suite` (every row, the Tracking shares included), `pmsm-sim faults` and the
//! three recorded drives of the real-data score nothing changes.
//!
//! **Speed noise adaptation** ([`SpeedNoiseAdaptation`]; on in [`ObserverConfig::new`], off in
//! foc's drive configuration and in [`ObserverConfig::seed`]). The model holds the speed constant
//! between samples, with a random walk sized for a steady drive; a recorded ESC can go from
//! 150 to 4000 rad/s in 25 ms, and a filter that cannot follow falls behind until the angle slips
//! by a turn or lands on `theta + pi`. An acceleration the model does not know shows as
//! innovations larger than the filter expects. The adaptation keeps a running mean `m` of the NIS
//! (8 samples; the samples the innovation gate rejects left out) and multiplies `Q_ww` of the next prediction by
//! `clamp((m / (4 b / 2))^2, 1, 10^4)`, where `b` is the consistency check's baseline (the
//! innovation level learnt from the data, 2 for a consistent filter): the speed's process noise
//! grows only while the innovations are more than twice their usual level, and at most a hundred
//! times in standard deviation. A persistent model error (a wrong `psi_f`, a recording's
//! unmodelled voltage error) raises the baseline, not the factor; only a change does. It acts
//! once the filter has settled (256 tracked steps in a row at the reference level) and stops
//! whenever the angle is not tracked, so the initial convergence and a restart keep their own
//! covariance. Why the speed: an unmodelled acceleration leaves innovations along the back-EMF
//! that grow with time (the angle error is the integral of the speed error), which is what the
//! speed's variance lets the gain correct; inflating the current or angle noise instead would
//! make the filter follow the measurement noise. It cannot tell a burst of sensor noise from an
//! acceleration: foc's drive turns it off (a closed speed loop amplifies the speed noise; the
//! drive knows its own torque command).
//!
//! **Acceleration feedforward** ([`AccelerationFeedforward`]; off in [`ObserverConfig::new`],
//! [`ObserverConfig::seed`] and foc's drive, on in `pyfoc.Ekf`'s defaults for recorded drives). Torque is
//! `3/2 p psi_f i_q`, so the rotor's electrical acceleration is `k i_q - a_L` with
//! `k = 3/2 p^2 psi_f / J` unknown (the inertia is the drive's, propeller or load included) and
//! `a_L` the load's share. The prediction adds `Ts a` to the speed and `Ts^2 a / 2` to the angle,
//! `a = k i_q - a_L_hat`, with `i_q` from the posterior the prediction starts from (in its frame:
//! the step's own sine and cosine). The load estimate `a_L_hat` is a disturbance observer: a
//! low-pass over 8 samples of `k i_q - dw / Ts`, the part of the filter's own speed change the
//! current does not explain. A current step therefore moves the predicted speed at once, a load
//! that follows (a propeller's, a friction that flips at zero speed) is taken up within a few
//! samples, and a steady state is neutral: `a` averages to zero there. Within a dead band of `k`
//! times three standard deviations of the measurement noise it adds nothing.
//!
//! `k` is learnt by least squares with forgetting (100 blocks): each block of 32 samples whose
//! angle stayed tracked gives the filter's speed change against the block's sums of `i_q`, `1`
//! and `w` (normalized by `I_c = psi_f / L_q` and `Ts`: `dw Ts = t0 sum(i_q / I_c) + t1 n +
//! t2 sum(w Ts)`); the constant and speed terms absorb a load that moves with the speed, so that
//! `k = t0 / (I_c Ts^2)` is not biased by it. It is solved by Cramer's rule once the information
//! matrix's determinant is at least `10^-3` of its diagonal's product, bounded to
//! `[0, 0.1 / (Ts^2 I_c)]` (a rate at which `I_c` turns `w Ts` by 0.1 rad per period); until then,
//! and after a fit with `k <= 0`, the speed is the random walk exactly.
//!
//! Observability: `k` is a ratio of what the filter measures while it tracks, the speed's change
//! against the q current; it is told from the load only when the current moves independently of
//! the speed (current or duty steps: the conditioning test), so a drive that never changes its
//! torque never uses it. A speed estimate that lags an acceleration biases `k` low (simulated:
//! 5 % low), toward the random walk.
//!
//! Why: at low speed the back-EMF is small beside the resistive and inverter voltage errors, and
//! a current step there (a duty or torque step) is when a filter whose speed is a random walk
//! reads the voltage error as a speed and slips; the model keeps the speed on the trajectory the
//! current sets until the EMF is large enough to correct it. Its input is not
//! covariance-weighted (the current enters as an input, its Jacobian left out). `k` is kept
//! through resets; a branch flip turns the sign of the load estimate. Why not in the firmware's
//! defaults: foc's drive knows its own torque command, and on simulated drives whose filter
//! already follows it changes little (on motulator's V/f trace of the 2.2 kW motor it learns
//! 500 rad/s^2 per A for a true 490 and moves the angle by 0.03 deg on average); it
//! is compiled only with the cargo feature `acceleration-feedforward` (on with `std`), so the
//! `no_std` step carries none of its code. Measured in `docs/accuracy.md` ("Recorded
//! drives").
//!
//! **Voltage timing** ([`ObserverConfig::voltage_delay_s`], default 0). The model takes `u_prev`
//! as the voltage held over the period. A drive's log may not hold that: firmware that updates
//! the PWM part-way through the next period and turns its command ahead by the speed times the
//! time to the update applies a vector that leads the logged one; a computation delay makes it
//! lag. For a vector turning with the rotor, a delay `d` is a rotation: the prediction uses
//! `u_prev e^(-j w d)`, `w` the speed estimate at the period's start (negative `d`: a lead). What
//! a wrong `d` does: the angle estimate moves by about `-w d` (the back-EMF the model infers
//! turns with the voltage), an error proportional to the speed. At one speed it cannot be told
//! from an angle offset, so it is not observable from the voltages and currents at constant
//! speed; only the drive's timing (or a reference angle at two speeds) gives it. On three
//! recorded ESC runs the firmware's lead is 0.3-0.6 periods (`docs/accuracy.md`).
//! [`ObserverConfig::inverter_voltage_v`] subtracts the inverter's voltage error (dead time)
//! that a log's commanded voltage does not show: `v (sgn i_a + sgn i_b e^(j2pi/3) +
//! sgn i_c e^(j4pi/3)) / 2` with the phase currents estimated at mid-period (the posterior
//! currents turned by `w Ts / 2`), each sign linear within `0.02 I_c` of zero; `v` is the value
//! foc's self-commissioning reports (the loss along a current aligned with a phase). Untold, it
//! reads as a resistance that falls with the current (`v / |i|` on top of `Rs`).
//!
//! **Irregular periods.** [`PmsmObserver::step_dt`] predicts over the period that actually ended
//! at the sample (a skipped control cycle, a log's time stamps) with the model for that period
//! ([`PmsmModel::with_period`]); at `dt == Ts` it is [`PmsmObserver::step`] itself.
//!
//! # Saturating motors told their small-signal constants ([`ObserverConfig::saturating`])
//!
//! A PM-assisted synchronous reluctance machine or a strongly saturating interior motor has a
//! q-axis inductance that falls under load (the 5.6 kW PM-SyRM of
//! [`saturation`](crate::saturation): 150 mH unsaturated, a chord `psi_q / i_q` of 83 mH and an
//! incremental 30 mH at rated current). A low-current commissioning measures the unsaturated
//! values. What a wrong `Lq` does to this observer: its angle is that of the active flux
//! `psi - Lq i` (section above), so at steady state an error `dLq` turns the estimate by about
//! `atan(dLq i_q / psi_a)`, and nothing in the steady-state voltages tells that from an angle
//! error (two equations, the angle, `psi_f`, `Ld` and `Lq` unknown). Only current transients
//! separate them, and through the *incremental* inductance, not the chord that sets the
//! steady-state angle; an online estimate would have to learn the curve `psi_q(i_q)`, i.e. a
//! flux map (module [`saturated`](crate::saturated)). So the choice is a prior on `Lq`.
//!
//! The mode takes the midpoint `(Ld + Lq) / 2` of the told values ([`saturating_lq`]). Why: q
//! saturation lowers the q path's permeance toward that of the d path, which the magnet and
//! the flux barriers already make low, so the chord `Lq` under load lies between the
//! small-signal `Ld` and `Lq` (both reference motors: 83-103 mH of [30, 150] mH at rated,
//! 35-38 mH of [30, 42] mH); the midpoint is the minimax choice over that range and halves the
//! worst steady-state angle error. At low current the error it adds is small because `i_q` is.
//! Measured (`pmsm-sim suite`, saturated section, foc sensored with load steps
//! 100/150/-100/100 % and a reversal under rated load): the PM-SyRM 7.5 deg RMS, at most
//! 33 deg off (told the constants through [`ObserverConfig::new`]: 60 deg RMS, 16.5 % of the
//! samples more than 45 deg off), the saturating interior motor 4.2 deg (7.9); never
//! `Tracking` while more than 45 deg off (`docs/saturation.md`). Other ways were measured
//! there and rejected: `R` or `Q_ii` widened (at no scale of 10 to 1000 is the lock kept), and
//! it is no default: on an interior motor that does not saturate the midpoint leaves a bias of
//! `atan((Lq - Ld) i_q / (2 psi_a))` under load. It costs nothing per step (a constructor).
//!
//! # Files
//!
//! | file | concept |
//! | --- | --- |
//! | `observer/model.rs` | [`PmsmModel`], [`Discretization`]: the model and its discrete step |
//! | `observer/structured.rs` | the hand-scheduled predict and correct on the 10 entries of `P` |
//! | `observer/config.rs` | [`ObserverConfig`], [`default_p0`]: configuration and validation |
//! | `observer/pmsm.rs` | [`PmsmObserver`]: the state, construction, accessors |
//! | `observer/step.rs` | one step: prediction, correction, gate and branch test |
//! | `observer/fusion.rs` | [`PmsmObserver::correct_angle`]: an external angle fused |
//! | `observer/safeguards.rs` | the safeguards' configuration and running state |
//! | `observer/adaptation.rs` | [`SpeedNoiseAdaptation`]: `Q_ww` raised through transients |
//! | `observer/feedforward.rs` | [`AccelerationFeedforward`]: the speed prediction follows the q current |
//! | `observer/recovery.rs` | what the safeguards do: rejection, flip, self-reset |
//! | `observer/estimate.rs` | [`Estimate`], [`Status`], [`ObserverCounters`]: what is reported |
//! | `observer/tracking.rs` | [`ParameterTracking`]: online `psi_f` and `Rs` |
//! | `observer/host.rs` | the step compiled for AVX2 and FMA (x86-64 hosts) |

mod adaptation;
mod config;
mod estimate;
mod feedforward;
mod fusion;
#[cfg(all(feature = "std", target_arch = "x86_64"))]
mod host;
mod mapstep;
pub(crate) mod model;
#[doc(hidden)]
pub mod parts;
mod pmsm;
mod recovery;
mod safeguards;
mod step;
pub(crate) mod structured;
pub mod tracking;

pub(crate) use adaptation::AdaptationState;
pub use adaptation::SpeedNoiseAdaptation;
pub use config::{
    MAX_COVARIANCE_ENTRY, MAX_TS_S, MIN_TS_S, ObserverConfig, check_covariance, default_p0,
    saturating_lq,
};
pub use estimate::{Estimate, ObserverCounters, Status};
pub use feedforward::AccelerationFeedforward;
pub use model::{Discretization, PmsmModel};
pub use pmsm::PmsmObserver;
#[cfg(feature = "std")]
pub use pmsm::{MAX_RETELLS, RETELL_MIN_TRACKING, RETELL_SHARE};
pub(crate) use safeguards::ConsistencyState;
pub use safeguards::{
    BranchCheck, ConsistencyCheck, CovarianceHealth, InnovationGate, MAX_REFUSALS,
};
pub use step::{MAX_CURRENT_RATIO, MAX_INPUT_FLUX_RATIO, MAX_PERIOD_FACTOR, SkippedCycles};
pub use tracking::{ParameterTracking, RsTracking};
