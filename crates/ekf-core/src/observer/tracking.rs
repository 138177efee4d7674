//! Online tracking of the flux linkage `psi_f` and the stator resistance `Rs`
//! ([`ParameterTracking`]; on in [`ObserverConfig::new`](super::ObserverConfig::new), off in
//! [`ObserverConfig::seed`](super::ObserverConfig::seed)).
//!
//! # Design: an augmented EKF, written out on blocks
//!
//! The state is augmented to `x = [i_a, i_b, w, th, psi_f, Rs]`; both parameters are random
//! walks. The prediction uses the tracked values (the step's constants `c = psi_f / Ls`,
//! `alpha = exp(-Rs Ts / Ls)`, `(1 - alpha) / Rs` are recomputed each step, the exponential
//! by a short series). Their Jacobian columns, nonzero in the current rows only, are
//!
//! ```text
//! d i-/d psi_f = the step's EMF term per weber                   (exact)
//! d i-/d Rs    = -(g / 2) (i + i-),   g = (1 - alpha) / Rs        (the resistive drop over the
//!                                                                   period at the mid-period current)
//! ```
//!
//! The covariance is kept as the 4-state `P` of the observer (unchanged code), the 4 x 2
//! cross-covariance `X` of the state with the parameters, and the 2 x 2 parameter covariance
//! `C`. With `Gamma` the two Jacobian columns and `Phi4` the 4-state transition:
//!
//! ```text
//! predict:  X- = Phi4 X + Gamma C
//!           P- = Phi4 P Phi4^T + Q4 + X- Gamma^T + Gamma X-^T - Gamma C Gamma^T
//!           C- = C + Qp                           (Qp only while tracking is active)
//! correct:  K4 as before (from P-),  Lp = X-[rows i_a, i_b]^T,  Kp = Lp S^-1
//!           X = X- - K4 Lp^T,  psi_f += Kp[0] y,  Rs += Kp[1] y,  C = C- - Kp Lp^T
//! ```
//!
//! which is the 6-state EKF exactly (the `P` block's update depends on `P-` alone). The cost
//! over the 4-state step is about 90 multiply-adds and one division.
//!
//! # What can be told apart (observability)
//!
//! In the rotor frame, with `i_d = 0` at one steady operating point, the voltage equations are
//! `u_d = -w Ls i_q - w psi_f sin(e)` and `u_q = Rs i_q + w psi_f cos(e)` (`e` the angle
//! error). Two equations, three unknowns (`e`, `Rs`, `psi_f`): an error `dRs` and an error
//! `dpsi` with `dRs i_q + w dpsi = 0` give the same voltages, so the filter sees only the
//! combination `Rs i_q + w psi_f` on the q axis. That is harmless for the angle: the d axis
//! still pins `e = 0`, and whatever split of the combination the filter holds, the modelled
//! EMF has the right direction. The split is told apart by anything that moves `i_q / w`:
//! a speed change (the EMF scales with `w`, the drop with `i_q`), a load change, or a d-axis
//! current that varies in time (`Rs i_d(t)` on the d axis, which a constant angle error cannot
//! mimic); `foc` can inject a slow, small `i_d` square wave for that purpose. In between, the
//! filter's covariance carries the unobservable direction: its gain along it is zero (the
//! estimates do not move along it), and its variance is held at or below the initial one
//! (no process noise is added to a parameter whose variance has reached its initial value), so
//! a later excitation resolves it quickly and nothing grows without bound.
//!
//! `psi_f` is observable only while the rotor turns (its column scales with `w`); `Rs` only
//! while current flows, and at low speed the inverter's voltage error (dead time) looks like
//! a resistance. **Tracking is active only while the filter tracks the angle (status
//! `Tracking`) and `|w_hat| >= min_speed_rad_s`**; otherwise the parameters are *consider*
//! states (Schmidt): their estimates and variances freeze (no gain, no process noise), while
//! their uncertainty still widens the state's covariance. At standstill and through a
//! reversal they keep their last values; they never wander. The estimates are also held
//! inside configured bounds.
//!
//! # Resistance (the split filter)
//!
//! The EKF's flux is the lumped `psi_f + dRs i_q / w` of the operating point. `Rs` comes from
//! a slow filter on `(psi_f, Rs)` fed once per window of samples (100 by default) with the
//! length of the window's back-EMF vector, read in the estimated frame:
//!
//! ```text
//! e(Rs) = u - Rs i - L di/dt - j w L i,        |e(Rs)| = |w| psi_f
//! m = (|e0| + Rs0 n.i) / |w| = psi_f + Rs r,   r = n.i / |w|
//! ```
//!
//! (`e0 = e(Rs0)` at the filter's own `Rs0`, `n = e0 / |e0|`: `|e(Rs)|` to first order in
//! `Rs - Rs0`; with the right angle `n` is the q axis and `r = i_q / w`), with the means over
//! the window of the voltage (each period's turned to the period's middle and scaled by
//! `sinc(w Ts / 2)`, as a voltage held while the frame turns), of `i_q`, `i_d` (the mean of
//! the window's ends), the change of the currents over the window, and `w` the rotation rate
//! of the **estimated angle** over the window. The speed state is not used for `w`: told a
//! wrong `Rs` at low speed under load, the filter reads the drop as back-EMF and its speed
//! state is off by `dRs i_q / psi_f`, while its angle still turns at the rotor's speed on
//! average (it cannot drift without bound).
//!
//! Why the length and not the q-axis equation alone: an angle error `e` turns the whole
//! voltage equation (voltage, currents and EMF alike) by `e`, which leaves the EMF's length
//! unchanged; the q-axis equation alone reads `u_q cos e + u_d sin e`, and at low speed under
//! load `u_d = -w L i_q` is a sizeable part of the voltage (a third of the EMF on the 2.2 kW
//! motor at 10 % speed and rated torque), so a few degrees off mix into the flux and, with
//! `r` large there, into `Rs`. That is the case where `Rs` matters: after a load step at low
//! speed told a wrong `Rs` the angle is off by 10-20 deg until the first windows correct it,
//! and those windows decide the `Rs` carried through a reversal. Independent of the EKF's
//! flux, the measurement does not feed the EKF's own correction back into itself. What is
//! left: the window's speed from the angle's advance is biased while the angle pulls in (its
//! error changes within the window), and a wrong `Ls` adds `w dL i_q` across the EMF (second
//! order in the length).
//!
//! What a window tells: `m` at one `r` pins `psi_f + Rs r`. At small `r` (light load, high
//! speed) that is the flux; at large `r` (low speed, high current, where the resistive drop is
//! a sizeable part of the voltage) mostly `Rs`; two windows of different `r` (a speed change, a
//! load step, a braking ramp, the two sides of a reversal) give both. What the data leaves open
//! is decided by the thermal link, a pseudo-measurement that the temperatures read from `psi_f`
//! (`beta`) and from `Rs` (`alpha_cu`) agree, applied only where the window measures the flux
//! (the drop `|Rs r|` within 15 % of `psi_f`): there it carries the flux's temperature over to
//! `Rs` (a motor warming at one operating point); applied where the window measures `Rs`, once
//! per window, it would outweigh that measurement.
//!
//! Windows left out: below twice the tracking's minimum speed (no EMF to read); with a mean
//! current below 2 % of `psi_f / L_d` (the inverter's voltage error, which a drive compensates
//! by the current's sign, is least known there and reads as a flux error); with a change of
//! `i_q` over the window above a fifth of the current (a load step: the angle and speed are in
//! transit); with a period other than `Ts` (`step_dt`); and not consecutive with the last
//! one (tracking paused in between). Below ten times the minimum speed a window's variance
//! grows as `1 / w^2` (a voltage error over the speed). Measured: the suite's reversal rows
//! (`pmsm-sim suite`, `docs/accuracy.md`).
//!
//! # The link's reference
//!
//! The thermal link reads both temperatures against a reference pair `(psi_a, Rs_a)` taken
//! at the anchor: the EKF's converged flux and the `Rs` in use, the told one. Told a wrong
//! `Rs`, that pair is not one of the motor's. Where the windows tell `Rs` by themselves (a
//! load step moves `r = i_q / w` away from the anchor's, and the flux is known from before
//! it), the link, applied on every window that measures the flux, still pulls `Rs` back
//! toward `Rs_a` while the flux moves to keep the lumped value: on motulator's closed-loop
//! start-up of the small fast motor told 100 K cold (`Rs` 39 % low), the tracked `Rs` goes
//! from 0.099 to 0.079 ohm within 0.3 s of the rated load step (the motor's is 0.12), so the
//! record's retelling (module docs of [`crate::calibration`], "Told by the record") never
//! reaches it, and every pass carries the step's transient (1-2 deg for 0.1 s).
//!
//! With [`ParameterTracking::link_follows_data`] (host builds; on in `pyfoc.Ekf`'s defaults
//! for a recorded drive, with the input calibration; off in the firmware's filter) the split
//! filter keeps a second covariance of `(psi_f, Rs)` that only the windows update: the same
//! random walks, never the link. At the anchor it reads the EKF's flux as the lumped
//! `psi_f + Rs r` of the anchor's operating point (`r = i_q / w` at the window's end): that
//! combination known to the EKF's flux variance, `Rs` to its initial variance. At one
//! operating point it therefore learns the lumped flux and nothing of `Rs`; only windows at
//! another `r` bring its deviation of `Rs` down. Once that deviation is within the link's
//! own, `link_sigma_k alpha_cu Rs` (24 % of `Rs` by default), the windows have told `Rs`
//! better than the link would, and the link takes the filter's present pair as its
//! reference: from there it carries only later changes of temperature. At a steady operating
//! point the random walk widens the windows-only deviation again (about 20 s to pass the
//! link's at the default walk), and the link holds the last pair the windows told. Test:
//! `cargo test --release -p ekf-core --test tracking the_link_follows -- --nocapture` (the
//! servo at 20 % speed told `Rs` -30 %, a rated load step: `Rs` -37.2 % at the end without,
//! -2.7 % with).
//!
//! Why not in the firmware's filter: on the suite's reversal rows of the 2.2 kW motor at 10 %
//! speed under rated load (`pmsm-sim suite`, seeds 1-3) it moves told 100 K hot 0.58 -> 0.74
//! deg and told `Rs` -30 % 0.52 -> 0.67 (seed 1; 1.11-1.28 x over the seeds), past the
//! suite's 1.1 x regression rule, although the told-cold row goes 0.80 -> 0.55 and the
//! filter told the exact motor is at 0.61-0.63 there: with the told pair as the reference,
//! those two rows were below the exact motor's. Measured with `pyfoc.Ekf`'s defaults on
//! motulator's closed-loop runs (`docs/accuracy.md`, "Closed-loop runs on a third-party
//! plant"): the start-up told 100 K cold 0.51 -> 0.26 deg RMS, `Rs` -30 % 0.37 -> 0.16; the
//! small fast motor told 100 K cold 0.75 -> 0.11, `Rs` -30 % 0.69 -> 0.17; the reversal,
//! motulator's V/f trace and the three ESC recordings unchanged.
//!
//! # Resistance while the filter is in trouble
//!
//! Told `Rs` far too high at low speed under load, the EKF can find no lock: at its frozen flux
//! the modelled EMF `w psi_f` cannot match the measured `|w psi_f - dRs i_q|`, so its speed state
//! settles at `|e| / psi_f` and the angle slips a turn after another (the small fast motor told
//! 100 K cold, `Rs` +65 %, at 10 % speed and rated torque: the drop error is a third of the EMF,
//! and after the load step's speed dip the filter slipped for the rest of the run). Its own
//! tracking never starts (the speed is never steady), and the split filter's windows, which need
//! the tracking active, never come.
//!
//! The window's measurement does not need the lock: the back-EMF length is independent of the
//! angle, and the window's speed, the estimated angle's advance, stays near the rotor's even
//! while the speed state is far off (the angle is pulled toward the EMF every step; it falls
//! behind only by the slips). So in host builds (with [`ParameterTracking::transient_flux`]),
//! once the filter has tracked and the split filter anchored, a window that ends with the
//! EKF's tracking frozen **and** the consistency check reading the innovations out of line
//! updates the split filter's `Rs` as an active window would, on two conditions: the window
//! measures `Rs` (the resistive drop `|Rs r|` above 15 % of the flux; where it measures the flux,
//! the EKF's lumped flux takes over once tracking resumes) and its variance is ten times the
//! active window's (the angle's advance is biased while the angle pulls in, by the change of
//! its error over the window). A filter that pulls in after a load step with consistent
//! innovations is left alone; one whose innovations are still out of line while it pulls in
//! takes these windows too (the small fast motor told `Rs` +30 %: its first such window reads
//! `Rs` 14 % low, and the EKF's own tracking corrects it once it resumes).
//!
//! A filter can also be stuck with consistent innovations: after a load step at low speed told
//! `Rs` far off, the lumped flux it carries from before the step (`psi_f + dRs r` at the old
//! `r = i_q / w`) is wrong at the new `r`, so the speed state settles where the modelled EMF's
//! length fits (`|e| / psi`), off the rotor's, while the d-axis correction holds the angle a
//! fixed amount behind, turning with the rotor. The innovations are small, the speed never
//! steady enough for the tracking to start, and the angle stays 10-15 deg off (the 2.2 kW
//! motor told 100 K cold, `Rs` +65 %, at 10 % speed under rated load: the speed state at 36-44
//! rad/s for a rotor at 47, for 0.2 s). The signature is the conflict itself: **a window whose
//! speed state (its mean) and angle advance differ by more than 12 % of the advance (the
//! split filter's `SPEED_CONFLICT`) is taken as a window of a
//! filter in trouble**, with the same two conditions. A filter in step has the two within a few
//! per cent (the advance differs from the speed state by the correction's share of the angle's
//! motion); a pull-in after a load step reaches 10-16 % for a window or two, which is where the
//! limit's trade-off lies (below).
//!
//! Measured (`pmsm-sim suite`, the reversal rows at 10 % speed; three seeds): the small fast
//! motor told 100 K cold 49.9 / 49.0 / 49.2 deg RMS without, 0.27 / 0.42 / 0.47 deg with these
//! windows; the other rows of the three surface motors within 0.73-1.14 x on seeds 2 and 3,
//! on seed 1 the small fast motor's `Rs` +30 % and 100 K hot rows 1.52 x and 1.37 x (0.48 and
//! 0.59 deg, inside the 1 deg goal: the reversal's transient follows from the pull-in's `Rs`;
//! a variance factor of 3, 30 or 100 instead of 10 leaves these at 1.49-1.65 x, and 3 loses the
//! cold row on seed 3).
//!
//! The speed conflict, measured on the same rows (`pmsm-sim suite --seed N`): the 2.2 kW motor
//! told 100 K cold 2.33 / 0.62 / 1.67 deg RMS without, 0.80 / 0.62 / 0.85 with it (seeds 1 / 2 /
//! 3; the goal is 1 deg); the servo told `Rs` +30 % 0.66 / 0.58 / 0.62 -> 0.27 / 0.23 / 0.24;
//! the servo told 100 K cold 0.25 / 0.25 / 0.26 -> 0.34 / 0.30 / 0.29 (its `Rs` ends closer,
//! +0.6 % instead of -0.2 %, but its correction comes in the window); no other row of the suite
//! moves except the PM-SyRM told its small-signal constants (7.39 -> 7.45 deg, never `Tracking`
//! while lost). The limit: at 5 % the servo's `Rs` -30 % row goes 0.20 -> 0.41 deg and the small
//! fast motor's 100 K cold 0.27 -> 0.49; at 10 % those 0.31 / 0.51; at 15 % the 2.2 kW cold row
//! is 0.97; at 20 % it is left as it was. A filter slipping turn after turn (the angle's advance
//! no longer the rotor's) is not helped: its windows fail the current-step test, the frame's
//! `i_q` turning with the slip.
//!
//! # Resistance on a braking ramp
//!
//! A drive that runs unloaded at a steady speed shows the split filter only the flux: there
//! `r = i_q / w` is near zero, and the thermal link, whose reference is the pair at the anchor
//! (the converged flux and the told `Rs`), carries over only what the flux does after it.
//! Told `Rs` far off, such a drive can reach a load step at low speed with the told `Rs`
//! still in use: the 2.2 kW motor told 100 K cold (`Rs` +65 %), after 0.5 s unloaded at 50 %
//! speed and a braking ramp to 10 %, slipped from the rated load step through the reversal
//! that follows (44 deg RMS) on 5 of 24 sensor seeds, those on which no active window had
//! moved `Rs` before the ramp.
//!
//! The braking ramp itself shows `Rs`. Braking, the current flows against the back-EMF (`r <
//! 0`, the drive generating), and as the speed falls at a steady braking current, `|r|` grows
//! as `1 / w`: on that ramp (`i_q` about -1.7 A, 50 % to 10 % in 0.2 s) the resistive drop
//! goes from about 5 % of the flux at 50 % speed to about 24 % at 10 %. The EKF's own
//! tracking is frozen there (the speed is not steady), but the window's measurement holds
//! through a ramp ("Tracking during transients": the speed enters the mean q voltage
//! linearly, and the window's speed is the estimated angle's advance). So in host builds
//! (with [`ParameterTracking::transient_flux`]), once the filter has tracked and anchored, a
//! window that ends with the EKF's tracking frozen and the filter consistent (not one of a
//! filter in trouble, above) updates the split filter's `Rs` as an active window would when
//! it is one of a braking ramp: its speed below the previous such window's by more than 2 %
//! (two consecutive windows of a slowing rotor), the drive generating (`r < 0`), and the
//! resistive drop `|Rs r|` above 15 % of the flux (the window measures `Rs`; the thermal link
//! is then left out, as on any such window).
//!
//! Why braking only: a window of a frozen, consistent filter is otherwise mostly one of an
//! angle's pull-in after a load step or through a reversal under load, where the window's
//! speed is biased by the change of the angle error within it. Taking every frozen window
//! that measures `Rs` (with the active window's variance, or ten times it) moved the servo
//! told `Rs` -30 % through the reversal from 0.20 to 0.41 deg RMS and the small fast motor told
//! `Rs` +30 % from 0.30 to 0.60, on every seed; with the braking rule neither moves.
//!
//! Measured (`pmsm-sim suite --seed S`, S = 0..23, the 2.2 kW motor's reversal rows at 10 %
//! speed, default EKF, angle RMS deg): told 100 K cold 0.45-0.71 on every seed (the 5 lost
//! seeds 44.1-44.3 before; one other 2.65); the row's median over the seeds 0.73 -> 0.57, told
//! `Rs` +30 % 0.77 -> 0.67 (largest 1.08 -> 0.92), `psi_f` -10 % largest 1.03 -> 0.88; every
//! other row's median within 1.013 x of before, the largest single change 1.45 x (`Rs` +30 %
//! on seed 19, 0.52 -> 0.75). The other motors' rows rise by at most 0.9 %; no row reads
//! `Tracking` while more than 45 deg off. The PM-SyRM told its small-signal constants (a
//! constant model that does not fit that motor, whose braking windows move `Rs`) is 7.15-7.58
//! deg RMS (7.15-8.25 before) and reads `Tracking` on 86.6-89.0 % of its samples (87.3-93.3
//! before). The firmware's filter (no `std`) is unchanged. Tests: `cargo test --release -p
//! pmsm-sim --test suite braking_ramp`, `cargo test -p ekf-core --lib braking_ramp`.
//!
//! # Tracking during transients (start-up flux)
//!
//! The EKF's flux is frozen while the speed estimate departs from its low-pass (a speed
//! ramp): its speed state is a random walk and lags an acceleration `a` by about `a / k`
//! (`k` its speed gain), and the lumped flux would absorb that lag as `psi_f dw / w`. With
//! [`ParameterTracking::transient_flux`] (the default in host builds, feature `std`; off
//! and refused without it, whose step carries none of its code) the split filter's window
//! goes on while the flux is frozen (a speed change, the settling time) as long as the angle is tracked above the minimum speed, and each
//! window of an acceleration corrects the frozen flux. This is a two-time-scale design: the
//! fast part (the EKF's current, speed and angle) runs at the frozen flux; the slow part
//! reads the flux once per window from quantities that an acceleration does not bias.
//!
//! Why the window's measurement holds through a ramp: the voltage equation on the q axis is
//! linear in the speed, `u_q = Rs i_q + w L_d i_d + L_q di_q/dt + w psi_f`, so its mean over
//! the window is `psi_f mean(w) + Rs mean(i_q) + L_d mean(w i_d) + L_q (change of i_q) /
//! span`: a speed that changes within the window enters only through its mean. That mean is
//! taken from the estimated angle's advance over the window, not from the lagging speed
//! state: the angle cannot drift from the rotor's by more than its error's change over the
//! window, so its advance is the rotor's. What is left is the angle error `e` (the voltage
//! read in a frame `e` off: `cos e` on the EMF and `sin e` times `u_d` from the d axis), a
//! few per cent for the first window after a 10 % flux error, less at each window as the
//! corrected flux pulls the angle in; and the cross term `mean(w i_d)` read as `mean(w)
//! mean(i_d)` (exact at a constant `i_d`). `mean(i_d)` is the window's own mean of the
//! current in the frame of each period's start, not the mean of the window's two ends: where
//! a ramp ends within a window the current turns (on motulator's V/f trace of the 2.2 kW
//! motor `i_d` swings by 0.2 A there), and `w L_d` times the ends' error read as a flux
//! error of 0.5 % (`test_third_party.py`: the EKF's RMS 0.137 deg with the ends' mean, 0.059
//! deg with the window's, as without the start-up flux).
//!
//! The update: `m - Rs r` (at the `Rs` in use, the lumped flux the EKF's model needs) is a
//! measurement of the frozen flux with the window's variance, in a scalar Kalman update of the
//! flux and its variance; the variance is held at or above `(1 % psi_f)^2`, so that the EKF's
//! own tracking (and the split filter's anchor, which waits for 0.5 %) still starts from a
//! flux it may move. Only windows of an acceleration correct: the window's speed (the
//! angle's advance) is above the previous window's by more than 2 % (a start-up). Left out
//! besides the windows the split filter leaves out (the mean-current test aside: at start-up
//! the current is small, and the EKF's lumped flux absorbs the inverter's error there as
//! well): the first window after a gap (no speed to compare with), windows at a steady
//! speed or braking, windows with a resistive drop `|Rs r|` above 30 % of the flux (low speed
//! under load: below), windows beyond 5 standard deviations, and every window
//! once one has ended with the EKF's tracking active (from then on the EKF's own tracking
//! follows the flux: the correction is for the start-up) or once a window has read a braking
//! (the start-up is over: later accelerations are the steps and reversals of a drive under
//! way). The first tracked step after a frozen one starts a new window, as without the
//! start-up flux: the split filter's `Rs` windows hold tracked periods only.
//!
//! Why a resistive drop up to 30 % of the flux: the update corrects the lumped flux at the
//! `Rs` in use, `psi_f + (Rs_true - Rs) r`, which is what the EKF's model needs at the window's
//! `r = i_q / w`; a ramp keeps `r` nearly constant (a V/f or speed-loop start accelerates at a
//! steady current, so `r` falls as `1 / w`), and the lumped flux then holds along it. At a
//! larger drop (low speed under load) `r` changes several-fold as the speed rises, and a wrong
//! `Rs` there would leave the lumped flux off by `dRs` times that change. Measured on
//! motulator's V/f trace of the 2.2 kW motor (`pyfoc.Ekf` defaults, scored from 0.25 s; its
//! start-up windows have `|Rs r|` at 17-22 % of the flux told 100 K hot), RMS deg at the
//! limits 15 / 20 / 25 / 30 %: flux -10 % 1.93 / 0.16 / 0.09 / 0.06, flux +10 % 0.17 / 0.11 /
//! 0.08 / 0.08, 100 K hot 4.38 / 3.05 / 1.90 / 1.90, `Rs` +30 % 3.75 / 1.47 / 1.47 / 1.47, the
//! exact motor 0.06 throughout, the other cases within 0.1 deg (50 % and 100 % as 30 %). The
//! simulator's outputs (`scripts/same-outputs.sh`: run, suite, faults, identify, tune) are the
//! same at 15 and 30 %; the convergence table's 2.2 kW rows told the flux -10 % and 100 K cold
//! are at worst 0.86 and 0.28 deg closer after the ramp, told +10 % 0.25 deg closer in angle and
//! 0.9 % further in flux (`cargo test --release -p pmsm-sim --test convergence -- --nocapture`).
//!
//! Why a braking ends the start-up: on a recorded drive whose own tracking never starts (the
//! steps and reversals of a real ESC, where the EKF's speed is never steady for the settling
//! time), every acceleration corrected the flux, from windows at low current where the
//! inverter's voltage error is least known: on the second motor's run (`Ekf.run` without
//! periods) the flux wandered from -19 % to +12 % and the angle error went from 8.08 to 12.30
//! deg RMS. With the rule that run is 8.08 deg again (its flux stays at the told value); the
//! convergence test, motulator's trace (`test_third_party.py`) and the suite's rows are
//! unchanged (the suite within 1.06 x).
//!
//! Why accelerations only: at a steady speed the EKF's own tracking takes over after the
//! settling time anyway, and a correction there (the angle's pull-in after a lock at speed
//! reads as a speed change of a few per cent between windows) only moves the point from
//! which it starts. The suite's reversal rows at 10 % speed (0.2-0.5 deg RMS), where the
//! observers lock at a steady 50 % speed, react to that start by up to 1.19 x; with the rule
//! the suite's rows are those of the filter without the start-up flux (`pmsm-sim suite`).
//!
//! Measured (`cargo test --release -p pmsm-sim --test convergence -- --nocapture`; table in
//! `docs/accuracy.md`, "Convergence"): told the flux 10 % off, the servo and the small fast
//! motor are within 1 % and 0.3 deg of the filter told the right motor 0.01-0.07 s after the
//! rotor passes 10 % of rated speed (0.10-0.28 s without the start-up flux). The 2.2 kW motor
//! takes 0.27 s either way: its flux tracking starts at the ramp's end, where the speed loop
//! sheds its overshoot with the current through zero and the dead time is compensated worst
//! (the angle moves 2.2 deg there whatever the filter is told).
//!
//! # Resistance while the speed is never steady
//!
//! A drive whose speed never settles (a V/f drive under load, whose speed swings by a few per
//! cent at the load's resonance; steps and swings that follow each other) never starts the
//! EKF's tracking, so neither the EKF's flux nor the split filter's windows move after the
//! start-up: told a wrong `Rs`, the angle stays off by about `dRs i_d / (w psi_f)` wherever the
//! current has a d component, and the lumped flux fits only the `r` it was read at. Those
//! swings are what makes `Rs` observable, though: `r = i_q / w` moves with them (on
//! motulator's V/f trace of the 2.2 kW motor under a 5 Nm load, between 0.011 and 0.030 s·A/rad
//! from one window to the next).
//!
//! So in host builds (with [`ParameterTracking::transient_flux`]) the split filter also runs
//! on the frozen windows of such a drive, once the start-up's flux agrees with the windows and
//! the EKF's own tracking has had time to start. Counted on the start-up flux's windows: the
//! EKF's flux variance at most (1.5 % of the configured flux)^2 (the start-up flux has
//! converged), the window's speed at least ten times the tracking's minimum (its variance not
//! widened), and its lumped flux `m - Rs r` within two standard deviations of the EKF's; after
//! four such windows in a row the split filter anchors there, at the EKF's flux and `Rs`, and
//! ten windows later (twice the default settling time of the EKF's own tracking), if that
//! tracking still has not run, each window updates `(psi_f, Rs)` as an active window would but
//! without the thermal link (its anchor is the lumped flux of the `Rs` in use, not a pair at
//! one temperature), and the EKF takes both: with the split filter's `Rs` in its model, the
//! flux it needs is the split filter's. Until then the start-up flux's windows go on as
//! without these rules, and the first window of the EKF's own tracking drops this anchor (the
//! filter anchors again where the EKF's flux converges): a drive whose speed settles runs as
//! without them.

//! These windows read the current differently from the active ones. Within a window of a
//! swinging speed the current swings too: the window's `i_d` is its own mean, not the mean of
//! its ends (`w L_d` times the difference read as a flux error of up to 4 %), and a current
//! step up to half the current is kept (a fifth for the active windows). Read that way, the
//! window's back-EMF length in the **rotor's** frame is within 0.1 % of `|w| psi_f` on that
//! trace through the swings; in the estimated frame the angle's pull-in after a flux error
//! biases it by the change of the angle error over the window relative to the window's
//! rotation (a 3 deg pull-in over a window at 90 rad/s el., 2.3 %), which is what the
//! agreement rule waits out.
//!
//! Measured on motulator's trace (RMS deg from 0.25 s; `pyfoc.Ekf(motor, ts,
//! input_calibration=False)`, the feedforward on, so that no priming is involved; in brackets
//! without these windows): 100 K hot 1.44 (1.86), 100 K cold 1.46 (1.70), `Rs` +30 % 1.16
//! (1.43), `Rs` -30 % 1.15 (1.32); the exact motor 0.04 (0.04), the flux +-10 % 0.07 / 0.07
//! (0.07 / 0.04). Told a wrong `Ls` it loses, 4.08 / 3.93 (2.85 / 3.02): in the V/f swings
//! `i_d` moves with `r` (high `i_q` with `i_d` near -3 A), so the window's `w dL i_d` along the
//! back-EMF reads as a resistance; the firmware's filter in a host build does the same (4.11 /
//! 3.91). What is left is the start-up: before the first swing the told `Rs` holds, and the V/f
//! start's d current (2.4 A at 0.25 s) puts the angle `dRs i_d / (w psi_f)` off; after it `Rs`
//! converges over the swings at the rate the spread of `r` allows (told 100 K hot, 5.01 ohm at
//! 0.5 s, 4.46 at 0.8 s, 4.27 at the end; told 100 K cold, 2.19, 2.68, 2.88; the motor's is
//! 3.6). `pyfoc.Ekf`'s defaults retell a whole record's `Rs` before they run it (module docs of
//! [`crate::calibration`], "Told by the record"): 0.07 / 0.09 / 0.40 / 0.46 deg on those four,
//! `Ls` +-20 % 2.27 / 2.47. The suite (`pmsm-sim suite`, seeds 1-3), whose observers lock at a
//! steady speed, moves in one row only, the small fast motor with 1 % of its periods skipped at
//! rated load (foc's observer 2.88 deg on seed 1, 3.07 without; 3.01 and 3.06 on seed 2); the
//! three ESC recordings are unchanged by these windows (their start-up flux never converges to
//! 1.5 %), and so are ekf-core's tracking tests at a steady speed (`cargo test --release -p
//! ekf-core --test tracking -- --nocapture`: their own tracking starts within the grace).
//!
//! # Inductance
//!
//! `Ls` is not tracked. An error `dL` shows on the d axis as `w dL i_q`, the same signature as
//! an angle error: the angle is biased by `atan(dL i_q / psi_f)`, about `dL/L * Ls i_q /
//! psi_f` rad. Tracking `psi_f` and `Rs` does not change that (the pm flux absorbs the small
//! magnitude part); the cost on the reference motors is in `docs/accuracy.md`.
//!
//! Current transients do not separate it either, on a surface motor: in the stationary frame
//! `u = Rs i + d/dt (L i + psi_f e^{j th})`, so told `L_t` the same voltages and currents fit
//! the model exactly with the fictitious rotor flux `psi' = psi_f e^{j th} + (L - L_t) i`. The
//! filter's angle is that of `psi'`, `atan((L - L_t) i_q / psi_f)` off the rotor's at every
//! instant (with `i_d = 0`), through a current step as much as at steady state, and `|psi'|`
//! changes by second order, which the flux tracking absorbs. What does separate them: a d
//! current that varies in time (it moves `|psi'|` at a rate no magnet flux follows: foc's
//! d-axis excitation, [`crate::excitation`], whose estimate
//! [`PmsmObserver::set_inductances`](super::PmsmObserver::set_inductances) takes), or a
//! mechanical model that knows what the q current does to the speed (the fictitious angle
//! steps with `i_q`, the rotor's cannot). Measured (`cargo test --release -p ekf-core --test
//! inductance_transients -- --nocapture`): the servo motor at 1500 rad/s el. with `i_q`
//! stepping 0 / 3 A in 2 ms, the default observer told `Ls` +-20 %: 1.17 deg RMS off, and
//! within 0.06 deg RMS of the fictitious flux's angle throughout.
//!
//! # The window's d current
//!
//! A window's voltage equation carries `w L_d i_d` in its q voltage, so the window's mean `i_d`
//! goes into its flux reading with the weight `L_d`. The firmware's filter takes the mean of
//! the window's two ends (no sum of `i_d` on the MCU), which is the window's own mean while
//! `i_d` holds or moves linearly. foc's d-axis excitation (a square wave of `+-a`) breaks
//! that: a window that spans whole periods with both ends in one half reads a mean `+-a` off,
//! the flux `L_d a` off, and the thermal link turns that into `Rs`. Host builds keep a sum of
//! `i_d` and take the window's own mean where it differs from the ends' by more than 5 % of
//! the window's current (floored at a tenth of `psi_f / L_d`, so that noise on a light load
//! does not trigger it). Measured (`pmsm-sim suite`, its excitation section): the 2.2 kW
//! motor at 50 % speed without load under the excitation read the flux 3.5 % high and `Rs`
//! 7.5 % low, and the reversal under load that follows was 1.2-2.1 deg RMS off; now 0.65-0.84
//! (seed 1). Without the excitation 47-66 of the suite's 340 rows move, by at most 0.7 %.
//!
//! # Winding temperature
//!
//! `T = T_ref + (Rs_hat / Rs_ref - 1) / alpha_cu` with the configured `Rs` taken at `T_ref`
//! and copper's `alpha_cu = 0.00393 / K` by default
//! ([`Estimate::winding_temperature_c`](super::Estimate::winding_temperature_c)).

use nalgebra::Vector4;

use super::model::{Discrete, TransitionTerms};
use super::structured::{Posterior, Sym4};
use crate::{Float, to_t};

mod config;
mod split;

/// The start-up flux from the split filter's windows is compiled in (host builds, feature
/// `std`): without it the step carries none of its code.
const TRANSIENT: bool = cfg!(feature = "std");

pub use config::{ParameterTracking, RsTracking};
pub(super) use split::Split;

/// The per-step state of the tracking (small: it is copied through a step and committed only
/// when the step succeeds): the EKF's flux with its cross-covariance and variance, the `Rs`
/// in use, the activity test, the split filter's window sums, the reported deviations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Tracker<T> {
    /// Tracked (lumped) `psi_f`, Wb: the EKF's augmented state.
    pub psi: T,
    /// `Rs` used by the model, ohm (the split filter's, or the configured one).
    pub rs: T,
    /// Reported standard deviations of `psi_f` and `Rs` (refreshed every 64 steps).
    pub psi_sigma: T,
    pub rs_sigma: T,
    /// The fields a step changes (the flux aside).
    pub s: TrackerStep<T>,
}

/// The fields of a [`Tracker`] that a step changes (all but `psi`, returned beside it by the
/// correction, and the values changed only by the slow work): the step's prior, then its
/// posterior, committed only when the step succeeds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TrackerStep<T> {
    /// Cross-covariance `X` of `[i_a, i_b, w, th]` with `psi_f`.
    pub x: [T; 4],
    /// Variance of `psi_f`.
    pub c_pp: T,
    /// Whether the last step tracked (else the parameters were frozen).
    pub active: bool,
    /// Samples in a row with the angle tracked above the minimum speed (up to the settling
    /// time).
    pub settled: u32,
    /// Low-pass of the speed estimate (steadiness test), rad/s.
    pub w_lp: T,
    /// Window sums of the split filter (module docs, "Resistance"): the voltage `u_d`,
    /// `u_q` and the current `i_q` in the frame of the angle at the start of each period,
    /// the speed estimate `w`; samples in the window.
    pub sum_ud: T,
    pub sum_uq: T,
    pub sum_iq: T,
    pub sum_w: T,
    pub sum_id: T,
    pub n: u32,
    /// Whether the window follows the previous one without a gap (its start is the previous
    /// window's end).
    pub contiguous: bool,
    /// Steps since the reported deviations were refreshed.
    pub since_sigma: u32,
}

impl<T: Float> TrackerStep<T> {
    /// A frozen step (not tracking) with the flux variance `c_pp`, no cross-covariance and an
    /// empty split-filter window; the activity test's running values as given.
    #[inline(always)]
    fn frozen(c_pp: T, settled: u32, w_lp: T, since_sigma: u32) -> Self {
        Self {
            x: [T::zero(); 4],
            c_pp,
            active: false,
            settled,
            w_lp,
            sum_ud: T::zero(),
            sum_uq: T::zero(),
            sum_iq: T::zero(),
            sum_w: T::zero(),
            sum_id: T::zero(),
            n: 0,
            contiguous: false,
            since_sigma,
        }
    }
}

/// The activity test's verdict for a step and its running values (committed with the step).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Activity<T> {
    pub active: bool,
    /// Frozen, the split filter's window goes on (module docs, "Tracking during
    /// transients").
    pub window: bool,
    pub w_lp: T,
    pub settled: u32,
}

/// The slow part of the tracking: constants, and the split filter (changed in place at the
/// end of a window, after a step has been committed).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TrackerSlow<T> {
    pub k: TrackerConstants<T>,
    pub split: Option<Split<T>>,
}

/// The sums of one window of the split filter (module docs, "Resistance").
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Window<T> {
    pub ud: T,
    pub uq: T,
    pub iq: T,
    pub w: T,
    pub id: T,
    pub n: u32,
    pub contiguous: bool,
}

/// Constants of the tracking.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct TrackerConstants<T> {
    /// Process noise per sample of `psi_f`.
    pub q_psi: T,
    /// Initial variance of `psi_f`, also its ceiling.
    pub var0_psi: T,
    /// Floor of the variance of `psi_f` after a correction, `eps var0_psi` (rounding must not
    /// leave it non-positive).
    pub var_floor_psi: T,
    /// Initial variance of `Rs` (split filter).
    pub var0_rs: T,
    pub min_speed2: T,
    pub settle_samples: u32,
    /// Samples per window of the split filter (`u32::MAX` without it).
    pub window: u32,
    /// The split filter's windows correct the frozen flux at start-up
    /// ([`ParameterTracking::transient_flux`]).
    pub transient: bool,
    /// The thermal link's reference follows the windows
    /// ([`ParameterTracking::link_follows_data`]; host builds).
    #[cfg(feature = "std")]
    pub follows: bool,
    pub psi_min: T,
    pub psi_max: T,
    pub rs_min: T,
    pub rs_max: T,
    /// Configured values.
    pub psi0: T,
    pub rs0: T,
    /// Sample time, s; the inductances `L_d`, `L_q`, H.
    pub ts: T,
    pub ld: T,
    pub lq: T,
    pub t_ref: T,
    /// `1 / (alpha_cu Rs0)`, K/ohm.
    pub kelvin_per_ohm: T,
}

impl<T: Float> Tracker<T> {
    /// A tracker at the configured parameters with the initial covariance, and its slow part.
    pub fn new(
        cfg: &ParameterTracking<T>,
        psi0: T,
        rs0: T,
        (ld, lq): (T, T),
        ts_s: T,
    ) -> (Self, TrackerSlow<T>) {
        let sq = |v: T| v * v;
        let var0_psi = sq(cfg.psi_f_sigma0 * psi0);
        let mut k = TrackerConstants {
            q_psi: sq(cfg.psi_f_walk_per_sqrt_s * psi0) * ts_s,
            var0_psi,
            var_floor_psi: T::default_epsilon() * var0_psi,
            var0_rs: sq(cfg.rs_sigma0 * rs0),
            min_speed2: sq(cfg.min_speed_rad_s),
            settle_samples: cfg.settle_samples,
            window: u32::MAX,
            transient: cfg.transient_flux,
            #[cfg(feature = "std")]
            follows: cfg.link_follows_data,
            psi_min: cfg.psi_f_range[0] * psi0,
            psi_max: cfg.psi_f_range[1] * psi0,
            rs_min: cfg.rs_range[0] * rs0,
            rs_max: cfg.rs_range[1] * rs0,
            psi0,
            rs0,
            ts: ts_s,
            ld,
            lq,
            t_ref: cfg.reference_temperature_c,
            kelvin_per_ohm: T::one() / (cfg.rs_temperature_coefficient_per_k * rs0),
        };
        let split = match cfg.rs {
            RsTracking::Fixed => None,
            RsTracking::Split {
                magnet_coefficient_per_k: b,
                link_sigma_k,
                window_samples,
                measurement_sigma,
            } => {
                k.window = window_samples;
                let window_s = ts_s * to_t(f64::from(window_samples));
                let alpha = cfg.rs_temperature_coefficient_per_k;
                Some(Split {
                    psi: psi0,
                    rs: rs0,
                    c00: k.var0_psi,
                    c01: T::zero(),
                    c11: k.var0_rs,
                    // The temperature walks by rs_walk / alpha_cu per root second; the flux
                    // besides by its own walk.
                    q_t: sq(cfg.rs_walk_per_sqrt_s / alpha) * window_s,
                    q_psi: sq(cfg.psi_f_walk_per_sqrt_s * psi0) * window_s,
                    r_m: sq(measurement_sigma * psi0),
                    psi_a: psi0,
                    rs_a: rs0,
                    r_link: sq(link_sigma_k),
                    anchored: false,
                    tracked: false,
                    alpha,
                    beta: b,
                    end_theta: T::zero(),
                    end_id: T::zero(),
                    end_iq: T::zero(),
                    last_w: T::zero(),
                    braked: false,
                    #[cfg(feature = "std")]
                    brake_w: T::zero(),
                    #[cfg(feature = "std")]
                    unsteady: split::Unsteady::default(),
                    #[cfg(feature = "std")]
                    follow: split::Follow {
                        d00: k.var0_psi,
                        d01: T::zero(),
                        d11: k.var0_rs,
                        last_r: T::zero(),
                    },
                })
            }
        };
        let tracker = Self {
            psi: psi0,
            rs: rs0,
            psi_sigma: k.var0_psi.sqrt(),
            rs_sigma: if split.is_some() {
                k.var0_rs.sqrt()
            } else {
                T::zero()
            },
            s: TrackerStep::frozen(k.var0_psi, 0, T::zero(), 0),
        };
        (tracker, TrackerSlow { k, split })
    }

    /// Whether the parameters are tracked in the coming step: the angle has been tracked
    /// for the settling time, the speed estimate `w` is at least the minimum, known to 20 %
    /// (its variance `w_var <= (w / 5)^2`) and steady (within 1 % plus 3 standard deviations
    /// of its low-pass over 64 samples: during a fast acceleration the speed estimate lags
    /// and the flux would absorb the lag). Counts the settling time.
    #[inline(always)]
    pub fn should_track(
        &self,
        k: &TrackerConstants<T>,
        angle_tracking: bool,
        w: T,
        w_var: T,
    ) -> Activity<T> {
        let w2 = w * w;
        // Steady speed: within 1 % plus three of its standard deviations of its low-pass
        // (time constant 64 samples).
        let w_lp = self.s.w_lp + (w - self.s.w_lp) * to_t::<T>(1.0 / 64.0);
        let dw = w - w_lp;
        let steady = dw * dw <= w_var * to_t(9.0) + w2 * to_t(1e-4);
        let usable = angle_tracking && w2 >= k.min_speed2 && w_var * to_t(25.0) <= w2;
        if !(usable && steady) {
            return Activity {
                active: false,
                window: TRANSIENT && usable && k.transient,
                w_lp,
                settled: 0,
            };
        }
        if self.s.settled < k.settle_samples {
            return Activity {
                active: false,
                window: TRANSIENT && k.transient,
                w_lp,
                settled: self.s.settled + 1,
            };
        }
        Activity {
            active: true,
            window: true,
            w_lp,
            settled: self.s.settled,
        }
    }

    /// The tracker's part of the prediction (module docs): returns the prior tracker and
    /// adds the flux's terms to the prior `P-` of the state. `t` holds the step's EMF terms,
    /// `x` is the posterior the step starts from, `u` the period's voltage. While active, also one sample of the split
    /// filter's window.
    #[inline(always)]
    pub fn predict<const S: bool>(
        &self,
        k: &TrackerConstants<T>,
        disc: &Discrete<T>,
        t: &TransitionTerms<T>,
        (x, u): (&Vector4<T>, [T; 2]),
        pm: &mut Sym4<T>,
        a: Activity<T>,
    ) -> TrackerStep<T> {
        let since_sigma = self.s.since_sigma + 1;
        let Activity {
            active,
            window,
            w_lp,
            settled,
        } = a;
        if !active {
            // Frozen: the flux is a known constant for this step (the 4-state filter
            // exactly, at the frozen value); its correlation with the state is dropped. The
            // split filter's window restarts (a window holds consecutive periods only), or
            // goes on for the start-up flux.
            let frozen = TrackerStep::frozen(self.s.c_pp, settled, w_lp, since_sigma);
            if window {
                return TrackerStep {
                    x: frozen.x,
                    c_pp: frozen.c_pp,
                    active: false,
                    ..self.with_sample(&self.s, t, (x, u), settled, w_lp, since_sigma)
                };
            }
            return frozen;
        }
        let d = disc.decay;
        // Jacobian column of psi_f (current rows): the EMF term per weber.
        let (g0, g1) = (t.ea_psi, t.eb_psi);
        let c = self.s.c_pp;
        let xo = &self.s.x;
        // X- = Phi4 X + Gamma c.
        let (x0, x1) = if S {
            // Full current block of a salient motor.
            (t.a00 * xo[0] + t.a01 * xo[1], t.a10 * xo[0] + t.a11 * xo[1])
        } else {
            (d * xo[0], d * xo[1])
        };
        let xm = [
            x0 + t.ea_w * xo[2] + t.ea_th * xo[3] + g0 * c,
            x1 + t.eb_w * xo[2] + t.eb_th * xo[3] + g1 * c,
            xo[2],
            disc.ts * xo[2] + xo[3],
        ];
        // P- += X- Gamma^T + Gamma X-^T - Gamma c Gamma^T (rows/columns i_a, i_b only).
        let (gc0, gc1) = (g0 * c, g1 * c);
        pm.p00 += (xm[0] + xm[0] - gc0) * g0;
        pm.p01 += xm[0] * g1 + xm[1] * g0 - gc0 * g1;
        pm.p11 += (xm[1] + xm[1] - gc1) * g1;
        pm.p02 += g0 * xm[2];
        pm.p03 += g0 * xm[3];
        pm.p12 += g1 * xm[2];
        pm.p13 += g1 * xm[3];
        // The first active step after a frozen one starts a new window (as without the
        // start-up flux, whose windows run on while frozen): the split filter's windows
        // hold tracked periods only, and the first after a pause is left out.
        let restarted;
        let base = if TRANSIENT && !self.s.active {
            restarted = TrackerStep::frozen(c, settled, w_lp, since_sigma);
            &restarted
        } else {
            &self.s
        };
        TrackerStep {
            x: xm,
            active,
            settled,
            w_lp,
            // Process noise, not above the ceiling (the variance stays bounded).
            c_pp: if c < k.var0_psi { c + k.q_psi } else { c },
            ..self.with_sample(base, t, (x, u), settled, w_lp, since_sigma)
        }
    }

    /// This tracker's step with one sample added to the split filter's window: the period's
    /// voltage and the current at its start in the frame of the angle at its start (the
    /// posterior the prediction starts from), and the speed estimate.
    #[inline(always)]
    fn with_sample(
        &self,
        base: &TrackerStep<T>,
        t: &TransitionTerms<T>,
        (x, u): (&Vector4<T>, [T; 2]),
        settled: u32,
        w_lp: T,
        since_sigma: u32,
    ) -> TrackerStep<T> {
        TrackerStep {
            settled,
            w_lp,
            sum_ud: base.sum_ud + (u[0] * t.cos_th + u[1] * t.sin_th),
            sum_uq: base.sum_uq + (u[1] * t.cos_th - u[0] * t.sin_th),
            sum_iq: base.sum_iq + (x[1] * t.cos_th - x[0] * t.sin_th),
            sum_w: base.sum_w + x[2],
            // The start-up flux's windows only (host builds): the M4F step carries none of it.
            sum_id: if TRANSIENT {
                base.sum_id + (x[0] * t.cos_th + x[1] * t.sin_th)
            } else {
                T::zero()
            },
            n: base.n + 1,
            contiguous: base.contiguous,
            since_sigma,
            ..self.s
        }
    }

    /// The tracker's part of the correction of the prior `prior` (this tracker's step) with
    /// the posterior `post` of the state (its gain and `S^-1`): the corrected step and flux,
    /// and a sum of the tracker's values that is finite when they all are (0 when frozen: no
    /// test); the caller tests it with the state's.
    #[inline(always)]
    pub fn correct(
        &self,
        k: &TrackerConstants<T>,
        prior: &TrackerStep<T>,
        post: &Posterior<T>,
    ) -> (TrackerStep<T>, T, T) {
        if !prior.active {
            return (*prior, self.psi, T::zero());
        }
        let (i00, i01, i11) = post.inv_s;
        let y = &post.correction.innovation;
        let xm = &prior.x;
        let (l0, l1) = (xm[0], xm[1]);
        let k4 = &post.k;
        let x = [
            xm[0] - (k4[0][0] * l0 + k4[0][1] * l1),
            xm[1] - (k4[1][0] * l0 + k4[1][1] * l1),
            xm[2] - (k4[2][0] * l0 + k4[2][1] * l1),
            xm[3] - (k4[3][0] * l0 + k4[3][1] * l1),
        ];
        let (kp0, kp1) = (l0 * i00 + l1 * i01, l0 * i01 + l1 * i11);
        let psi = clamp(self.psi + kp0 * y[0] + kp1 * y[1], k.psi_min, k.psi_max);
        let c = prior.c_pp - (kp0 * l0 + kp1 * l1);
        // Rounding must not leave the variance non-positive.
        let floor = k.var_floor_psi;
        let next = TrackerStep {
            x,
            c_pp: if c > floor { c } else { floor },
            ..*prior
        };
        (next, psi, self.check_sum(&next, psi))
    }

    /// The changing fields of this tracker as a step (for a correction without prediction).
    #[inline(always)]
    pub fn as_step(&self) -> TrackerStep<T> {
        self.s
    }

    /// Commits a step (and its flux): the tracker's other fields do not change in a step.
    /// Field by field: the whole-struct copy compiles to more instructions on the M4F.
    #[inline(always)]
    pub fn commit(&mut self, s: &TrackerStep<T>, psi: T) {
        self.psi = psi;
        self.s.x = s.x;
        self.s.c_pp = s.c_pp;
        self.s.active = s.active;
        self.s.settled = s.settled;
        self.s.w_lp = s.w_lp;
        self.s.sum_ud = s.sum_ud;
        self.s.sum_uq = s.sum_uq;
        self.s.sum_iq = s.sum_iq;
        self.s.sum_w = s.sum_w;
        if TRANSIENT {
            self.s.sum_id = s.sum_id;
        }
        self.s.n = s.n;
        self.s.contiguous = s.contiguous;
        self.s.since_sigma = s.since_sigma;
    }

    /// All values of this tracker with the step `s` and flux `psi` committed finite (one
    /// test on a sum).
    #[inline(always)]
    pub fn finite_with(&self, s: &TrackerStep<T>, psi: T) -> bool {
        self.check_sum(s, psi).is_finite()
    }

    /// The sum of this tracker's values with the step `s` and flux `psi` committed: finite
    /// when they all are (NaN and infinities propagate; conservatively, an overflow too).
    /// `Rs` is left out: a step does not change it, and it is finite whenever it is set (the
    /// split filter takes only a finite result, the other setters clamp or check it). The
    /// split filter's window sums are left out too: they add the step's finite input and
    /// finite state, so only an overflow could make them infinite, and they are read only at
    /// the window's end, where a window whose result is not finite is dropped (the filter
    /// keeps its values, [`housekeeping`](Self::housekeeping)) and the sums restart.
    #[inline(always)]
    fn check_sum(&self, s: &TrackerStep<T>, psi: T) -> T {
        let x = &s.x;
        // Any order of the terms makes the same test; this one measured fewest M4F
        // instructions for the whole inlined step (register allocation, not arithmetic).
        s.c_pp + x[3] + x[1] + x[2] + psi + x[0]
    }

    /// Whether the slow work is due (a full window, or the deviations to refresh).
    #[inline(always)]
    pub fn housekeeping_due(&self, k: &TrackerConstants<T>) -> bool {
        self.s.n >= k.window || self.s.since_sigma >= 64
    }

    /// The slow work after a committed step: the split filter's update at the end of a
    /// window (its `Rs` taken into use), the reported deviations. `troubled`: the
    /// consistency check finds the innovations out of line (module docs, "Resistance while
    /// the filter is in trouble").
    #[cold]
    #[inline(never)]
    pub fn housekeeping(&mut self, slow: &mut TrackerSlow<T>, x: &Vector4<T>, troubled: bool) {
        let k = &slow.k;
        if self.s.n >= k.window {
            let sums = Window {
                ud: self.s.sum_ud,
                uq: self.s.sum_uq,
                iq: self.s.sum_iq,
                w: self.s.sum_w,
                id: self.s.sum_id,
                n: self.s.n,
                contiguous: self.s.contiguous,
            };
            self.clear_window();
            self.s.contiguous = true;
            if let Some(s) = &mut slow.split {
                // A window of the active tracking, or (host builds) one that ends with the
                // EKF's tracking frozen after the filter has tracked and anchored: of a filter
                // in trouble (its innovations out of line or its speed state apart from its
                // angle's advance; module docs, "Resistance while the filter is in trouble"),
                // or of a consistent filter frozen through a speed change (a braking ramp's;
                // module docs, "Resistance on a braking ramp"). Either corrects `Rs` where it
                // measures `Rs`. A result that is not finite leaves the filter as it was.
                let waiting = TRANSIENT && k.transient && s.tracked && s.anchored && !self.s.active;
                let troubled = waiting && (troubled || s.speed_conflict(&sums, x, k));
                let frozen = waiting && !troubled;
                #[cfg(feature = "std")]
                if !frozen {
                    s.brake_w = T::zero();
                }
                if self.s.active || troubled || frozen {
                    let before = *s;
                    let rs = if self.s.active {
                        s.update(self.rs, self.psi, self.s.c_pp, &sums, x, k)
                    } else if troubled {
                        s.update_troubled(self.psi, &sums, x, k)
                    } else {
                        s.update_braking(self.psi, &sums, x, k)
                    };
                    match rs {
                        Some(rs) if s.finite() => self.rs = rs,
                        Some(_) => *s = before,
                        None => {}
                    }
                } else if TRANSIENT && k.transient && s.unsteady_ready() {
                    // Anchored at the start-up's end while the EKF's tracking has never run
                    // (module docs, "Resistance while the speed is never steady"): the window
                    // corrects `Rs` and the flux, which the EKF takes.
                    let before = *s;
                    match s.update_unsteady(&sums, x, k) {
                        Some((rs, psi)) if s.finite() => {
                            self.rs = rs;
                            self.psi = psi;
                        }
                        Some(_) => *s = before,
                        None => {}
                    }
                } else if TRANSIENT && k.transient {
                    if let Some((psi, c_pp)) =
                        s.transient_flux(self.rs, self.psi, self.s.c_pp, &sums, x, k)
                    {
                        // The EKF's flux is frozen (start-up): the window corrects it.
                        self.psi = psi;
                        self.s.c_pp = c_pp;
                    }
                    // The start-up's flux agrees with the windows: the split filter anchors
                    // there, at the `Rs` in use.
                    if s.unsteady_anchor_due() {
                        s.anchor_unsteady(self.psi, self.rs, self.s.c_pp, k);
                    }
                }
            }
        }
        if self.s.since_sigma >= 64 {
            self.s.since_sigma = 0;
            self.psi_sigma = self.s.c_pp.sqrt();
            self.rs_sigma = slow.split.map_or(T::zero(), |s| s.c11.sqrt());
        }
    }

    /// Restarts the split filter's window (a period other than `Ts` went into it).
    pub fn break_window(&mut self) {
        self.clear_window();
    }

    fn clear_window(&mut self) {
        self.s.sum_ud = T::zero();
        self.s.sum_uq = T::zero();
        self.s.sum_iq = T::zero();
        self.s.sum_w = T::zero();
        self.s.sum_id = T::zero();
        self.s.n = 0;
        self.s.contiguous = false;
    }

    /// After a branch flip (`w = -w`): the speed row of `X` changes sign; the window
    /// restarts.
    pub fn flip_speed(&mut self) {
        self.s.x[2] = -self.s.x[2];
        self.clear_window();
    }

    /// Reset by the health check or by [`PmsmObserver::reset`](super::PmsmObserver::reset):
    /// the estimates kept (the configured values if not finite), the cross-covariance cleared;
    /// with `covariance`, the variances back to their initial values.
    pub fn restart(&mut self, slow: &mut TrackerSlow<T>, covariance: bool) {
        let k = slow.k;
        let keep = |v: T, nominal: T, lo: T, hi: T| {
            if v.is_finite() {
                clamp(v, lo, hi)
            } else {
                nominal
            }
        };
        self.psi = keep(self.psi, k.psi0, k.psi_min, k.psi_max);
        self.rs = keep(self.rs, k.rs0, k.rs_min, k.rs_max);
        self.s.x = [T::zero(); 4];
        if covariance || !self.s.c_pp.is_finite() {
            self.s.c_pp = k.var0_psi;
        }
        if let Some(s) = &mut slow.split {
            s.psi = keep(s.psi, k.psi0, k.psi_min, k.psi_max);
            s.rs = self.rs;
            s.last_w = T::zero();
            if covariance || !(s.c00 + s.c01 + s.c11).is_finite() {
                s.c00 = k.var0_psi;
                s.c01 = T::zero();
                s.c11 = k.var0_rs;
            }
        }
        self.clear_window();
        self.s.active = false;
        self.s.settled = 0;
        self.s.since_sigma = 64;
        self.housekeeping(slow, &Vector4::zeros(), false);
    }

    /// Winding temperature from the tracked `Rs`, deg C.
    pub fn winding_temperature_c(&self, k: &TrackerConstants<T>) -> T {
        k.t_ref + (self.rs - k.rs0) * k.kelvin_per_ohm
    }
}

/// `v` limited to `[lo, hi]` by plain comparisons (`min`/`max` are libm calls on the MCU).
#[inline(always)]
pub(crate) fn clamp<T: Float>(v: T, lo: T, hi: T) -> T {
    if v < lo {
        lo
    } else if v > hi {
        hi
    } else {
        v
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A window whose sums are not finite (left out of the per-step check) is dropped at its
    /// end: `Rs`, the flux and the split filter stay finite and the next window starts empty.
    #[test]
    fn non_finite_window_is_dropped() {
        let ts = 1e-4_f32;
        let mut cfg = ParameterTracking::<f32>::default_for(ts);
        cfg.rs = RsTracking::Split {
            magnet_coefficient_per_k: -0.001,
            link_sigma_k: 5.0,
            window_samples: 16,
            measurement_sigma: 0.01,
        };
        let (mut t, mut slow) = Tracker::new(&cfg, 0.01, 0.5, (1e-3, 1e-3), ts);
        let split = slow.split.as_mut().expect("split filter configured");
        split.anchored = true;
        let before = *split;
        t.s.active = true;
        t.s.contiguous = true;
        t.s.n = 16;
        t.s.sum_uq = f32::NAN;
        t.s.sum_ud = 1.0;
        t.s.sum_iq = 16.0;
        t.s.sum_w = 16.0 * 1000.0;
        assert!(t.housekeeping_due(&slow.k));
        t.housekeeping(&mut slow, &Vector4::new(0.0, 1.0, 1000.0, 1.6), false);
        assert_eq!(t.rs, 0.5, "Rs unchanged by a non-finite window");
        assert!(t.psi.is_finite());
        let after = slow.split.expect("split filter kept");
        assert!(after.finite());
        assert_eq!(
            (after.psi, after.rs, after.c11),
            (before.psi, before.rs, before.c11)
        );
        assert_eq!(
            (t.s.n, t.s.sum_uq, t.s.sum_ud),
            (0, 0.0, 0.0),
            "window restarted"
        );
    }

    /// The start-up flux corrects on windows of an acceleration only: not the first window
    /// (no speed to compare with), not at a steady speed, not braking, not after a braking
    /// (the start-up is over); an accelerating window moves the frozen flux toward the
    /// window's.
    #[cfg(feature = "std")]
    #[test]
    fn start_up_flux_only_while_accelerating() {
        let ts = 1e-4_f64;
        let psi0 = 0.01;
        let (mut split, k) = split_told(ts, psi0, 0.5);
        let n = 100_u32;
        // A window at speed w (rad/s) whose voltage reads the flux psi_m (no current).
        let mut theta = 0.0_f64;
        let mut window = |split: &mut Split<f64>, w: f64, psi_m: f64| {
            let span = f64::from(n) * ts;
            theta += w * span;
            let sums = Window {
                ud: 0.0,
                uq: f64::from(n) * w * psi_m,
                iq: 0.0,
                w: f64::from(n) * w,
                id: 0.0,
                n,
                contiguous: true,
            };
            let x = Vector4::new(0.0, 0.0, w, crate::angle::wrap_angle(theta));
            split.transient_flux(0.5, psi0, k.var0_psi, &sums, &x, &k)
        };
        let psi_m = 1.1 * psi0;
        assert_eq!(window(&mut split, 500.0, psi_m), None, "first window");
        assert_eq!(window(&mut split, 500.0, psi_m), None, "steady speed");
        let (psi, c) = window(&mut split, 550.0, psi_m).expect("accelerating window corrects");
        assert!((psi - psi_m).abs() < 0.01 * psi0, "psi {psi}");
        assert!(c < k.var0_psi && c >= 0.99e-4 * psi0 * psi0, "variance {c}");
        assert_eq!(window(&mut split, 500.0, psi_m), None, "braking");
        assert!(split.braked, "a braking ends the start-up");
        assert_eq!(
            window(&mut split, 600.0, psi_m),
            None,
            "an acceleration after a braking"
        );
        split.braked = false;
        assert!(
            window(&mut split, 660.0, psi_m).is_some(),
            "accelerating again"
        );
        split.tracked = true;
        assert_eq!(
            window(&mut split, 730.0, psi_m),
            None,
            "after a tracked window"
        );
    }

    /// A window of `n` samples at speed `w` (rad/s el.) and `i_q` (A), `i_d = 0`, whose
    /// current rose by `diq` over it (the mean and the end are `i_q`), and whose voltage is
    /// that of a motor of flux `psi` and resistance `rs` (inductances 1 mH), ending at the
    /// angle `*theta` advanced by the window; the window's sums (in the frame of each
    /// period's start, the voltage turned forward by half a period and divided by the sinc
    /// the measurement applies) and the state at its end.
    #[cfg(feature = "std")]
    fn steady_window(
        n: u32,
        ts: f64,
        theta: &mut f64,
        (w, iq, diq): (f64, f64, f64),
        (psi, rs): (f64, f64),
    ) -> (Window<f64>, Vector4<f64>) {
        let l = 1e-3;
        let span = f64::from(n) * ts;
        let (ud, uq) = (-w * l * iq, rs * iq + w * psi + l * diq / span);
        let half = w * ts / 2.0;
        let sinc = half.sin() / half;
        let (sh, ch) = half.sin_cos();
        let (ud0, uq0) = ((ud * ch - uq * sh) / sinc, (uq * ch + ud * sh) / sinc);
        let nf = f64::from(n);
        *theta = crate::angle::wrap_angle(*theta + w * nf * ts);
        let sums = Window {
            ud: nf * ud0,
            uq: nf * uq0,
            iq: nf * iq,
            w: nf * w,
            id: 0.0,
            n,
            contiguous: true,
        };
        let (s, c) = theta.sin_cos();
        (sums, Vector4::new(-iq * s, iq * c, w, *theta))
    }

    /// The default tracking's split filter at the period `ts` for a motor of flux `psi` told
    /// the resistance `rs_told` (inductances 1 mH), and the tracking's constants.
    #[cfg(feature = "std")]
    fn split_told(ts: f64, psi: f64, rs_told: f64) -> (Split<f64>, TrackerConstants<f64>) {
        let cfg = ParameterTracking::<f64>::default_for(ts);
        let (_, slow) = Tracker::new(&cfg, psi, rs_told, (1e-3, 1e-3), ts);
        (slow.split.expect("split filter configured"), slow.k)
    }

    /// The split filter on the windows of a braking ramp (module docs, "Resistance on a
    /// braking ramp"): anchored at a wrong `Rs`, windows of a rotor slowing at a steady
    /// braking current take `Rs` to the motor's; the first window (no speed to compare with), a
    /// steady speed, an acceleration, a motoring current and a drop below 15 % of the flux are
    /// left out.
    #[cfg(feature = "std")]
    #[test]
    fn braking_ramp_windows_find_rs() {
        let ts = 1e-4_f64;
        let (psi_true, rs_true) = (0.01, 0.5);
        let rs_told = 0.65;
        let (mut split, k) = split_told(ts, psi_true, rs_told);
        split.anchor(psi_true, rs_told, 1e-4 * psi_true * psi_true, &k);
        let n = 100_u32;
        let mut theta = 0.0_f64;
        let mut window = |split: &mut Split<f64>, w: f64, iq: f64| {
            let (sums, x) = steady_window(n, ts, &mut theta, (w, iq, 0.0), (psi_true, rs_true));
            split.update_braking(psi_true, &sums, &x, &k)
        };
        // The drop `|Rs r|` at -2.5 A: 20 % of the flux at 800 rad/s, 67 % at 240.
        assert_eq!(window(&mut split, 800.0, -2.5), None, "first window");
        assert_eq!(window(&mut split, 800.0, -2.5), None, "steady speed");
        assert_eq!(window(&mut split, 840.0, -2.5), None, "accelerating");
        assert_eq!(window(&mut split, 800.0, 2.5), None, "motoring");
        assert_eq!(
            window(&mut split, 760.0, -0.5),
            None,
            "drop 4 % of the flux"
        );
        let mut w = 760.0;
        let mut rs = rs_told;
        for _ in 0..40 {
            w *= 0.97;
            if let Some(v) = window(&mut split, w, -2.5) {
                rs = v;
            }
        }
        assert!((rs - rs_true).abs() < 0.03 * rs_true, "Rs {rs}");
    }

    /// The split filter on unsteady windows (module docs, "Resistance while the speed is never
    /// steady"): start-up windows count as agreeing only once the EKF's flux has converged and
    /// while their lumped flux fits it, a window that does not fit starts the count again; once
    /// anchored at a wrong `Rs` (and the lumped flux that goes with it), windows whose
    /// `r = i_q / w` swings between them take `Rs` and the flux to the motor's.
    #[cfg(feature = "std")]
    #[test]
    fn unsteady_windows_anchor_on_agreement_and_find_rs() {
        let ts = 1e-4_f64;
        let (psi_true, rs_true) = (0.01, 0.5);
        let rs_told = 0.65;
        let (mut split, k) = split_told(ts, psi_true, rs_told);
        let n = 100_u32;
        let mut theta = 0.0_f64;
        // The lumped flux of the told `Rs` at the start-up's `r = 2.5 / 800`.
        let r0 = 2.5 / 800.0;
        let lumped = psi_true + (rs_true - rs_told) * r0;
        let converged = 1e-4 * psi_true * psi_true;
        let mut start_up = |split: &mut Split<f64>, c_pp: f64, psi: f64| {
            let (sums, x) =
                steady_window(n, ts, &mut theta, (800.0, 2.5, 0.0), (psi_true, rs_true));
            split.transient_flux(rs_told, psi, c_pp, &sums, &x, &k);
            split.unsteady.count
        };
        start_up(&mut split, converged, lumped);
        assert_eq!(
            start_up(&mut split, k.var0_psi, lumped),
            0,
            "the EKF's flux not converged"
        );
        for want in 1..=split::AGREEING_WINDOWS {
            assert_eq!(start_up(&mut split, converged, lumped), want);
        }
        assert_eq!(
            start_up(&mut split, converged, 1.05 * lumped),
            0,
            "a flux 5 % off"
        );
        split.anchor(lumped, rs_told, converged, &k);
        // The speed and the current swing: r between 2.5 / 800 and 3.5 / 700.
        let mut last = (0.0, 0.0);
        let mut iq_last = 2.5;
        for j in 0..200 {
            let (w, iq) = if j % 2 == 0 {
                (800.0, 2.5)
            } else {
                (700.0, 3.5)
            };
            let step = (w, iq, iq - iq_last);
            iq_last = iq;
            let (sums, x) = steady_window(n, ts, &mut theta, step, (psi_true, rs_true));
            if let Some(v) = split.update_unsteady(&sums, &x, &k) {
                last = v;
            }
        }
        let (rs, psi) = last;
        assert!((rs - rs_true).abs() < 0.03 * rs_true, "Rs {rs}");
        assert!((psi - psi_true).abs() < 0.005 * psi_true, "psi {psi}");
        // A current step above half the current leaves the window out.
        let step = (800.0, 1.0, 1.0 - iq_last);
        let (sums, x) = steady_window(n, ts, &mut theta, step, (psi_true, rs_true));
        assert_eq!(split.update_unsteady(&sums, &x, &k), None, "current step");
    }
}
