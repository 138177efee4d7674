#!/usr/bin/env python3
"""Independent Python reference for the "seed" PMSM EKF (forward-Euler discretisation).

Generates tests/data/seed_reference.csv: a simulated, loaded, spinning servo motor under a
sensored FOC controller, the (rounded) voltages and noisy (rounded) current measurements,
and the seed-EKF posterior state, diag(P) and NIS at every sample.

Only numpy is required. If filterpy is importable, filterpy's ExtendedKalmanFilter is run on
the same data as an independent second check (Joseph-form covariance update) and agreement
of the state is asserted.

Usage:  python3 tests/data/gen_seed_reference.py [--out PATH]
"""
import argparse
import math
import os
import sys

import numpy as np

# ---------------------------------------------------------------------------
# Motor and timing (SI)
# ---------------------------------------------------------------------------
RS = 2.875          # ohm
LS = 8.5e-3         # H
PSI = 0.175         # Wb
PP = 4              # pole pairs
J = 8e-4            # kg m^2
BV = 1e-3           # N m s (viscous)
TS = 1e-4           # s
N = 2500            # samples (0.25 s)
SUBSTEPS = 20       # RK4 substeps per Ts
NOISE_STD = 0.05    # A
SEED = 2026
U_MAX = 300.0       # V, limit on |u|

# Scenario
W_MECH0 = 100.0                 # rad/s, initial mechanical speed
TH0 = 0.5                       # rad, initial electrical angle
W_MECH_REF = 1200.0 * 2.0 * math.pi / 60.0   # 1200 rpm speed reference
T_LOAD_STEP_K = 1250            # load step at t = 0.125 s
T_LOAD_LO = 0.5                 # N m
T_LOAD_HI = 1.5                 # N m

# Filter parameters
Q = np.diag([0.01, 0.01, 10.0, 0.01])
R = np.diag([0.1, 0.1])
H = np.array([[1.0, 0.0, 0.0, 0.0],
              [0.0, 1.0, 0.0, 0.0]])
P0_DIAG = [1.0, 1.0, 100.0, 0.1]
I4 = np.eye(4)


def wrap(th):
    """Wrap to [-pi, pi): th - 2*pi*floor((th + pi)/(2*pi))."""
    return th - 2.0 * math.pi * math.floor((th + math.pi) / (2.0 * math.pi))


# ---------------------------------------------------------------------------
# Plant
# ---------------------------------------------------------------------------
def plant_deriv(s, ua, ub, tl):
    ia, ib, wm, th = s
    w = PP * wm
    st, ct = math.sin(th), math.cos(th)
    dia = (-RS * ia + w * PSI * st + ua) / LS
    dib = (-RS * ib - w * PSI * ct + ub) / LS
    te = 1.5 * PP * PSI * (ib * ct - ia * st)
    dwm = (te - BV * wm - tl) / J
    return (dia, dib, dwm, w)


def rk4_step(s, ua, ub, tl, h):
    k1 = plant_deriv(s, ua, ub, tl)
    s2 = tuple(a + 0.5 * h * b for a, b in zip(s, k1))
    k2 = plant_deriv(s2, ua, ub, tl)
    s3 = tuple(a + 0.5 * h * b for a, b in zip(s, k2))
    k3 = plant_deriv(s3, ua, ub, tl)
    s4 = tuple(a + h * b for a, b in zip(s, k3))
    k4 = plant_deriv(s4, ua, ub, tl)
    return tuple(a + h / 6.0 * (b1 + 2.0 * b2 + 2.0 * b3 + b4)
                 for a, b1, b2, b3, b4 in zip(s, k1, k2, k3, k4))


def simulate():
    """Closed-loop simulation. Returns u (N,2), z (N,2), th_true (N,), w_true (N,) (electrical)."""
    rng = np.random.default_rng(SEED)
    noise = rng.normal(0.0, NOISE_STD, size=(N, 2))

    # Sensored FOC: dq current PI (with decoupling / back-EMF feedforward) + speed PI.
    wc_i = 2000.0                       # current-loop bandwidth, rad/s
    kp_i, ki_i = LS * wc_i, RS * wc_i
    kt = 1.5 * PP * PSI                 # N m / A
    wc_w = 100.0                        # speed-loop bandwidth, rad/s
    kp_w = J * wc_w / kt
    ki_w = kp_w * wc_w / 4.0
    iq_max = 10.0

    s = (0.0, 0.0, W_MECH0, TH0)        # [i_a, i_b, w_mech, th] (th kept unwrapped)
    int_d = int_q = int_w = 0.0
    u = np.zeros((N, 2))
    z = np.zeros((N, 2))
    th_true = np.zeros(N)
    w_true = np.zeros(N)
    h = TS / SUBSTEPS
    for k in range(N):
        ia, ib, wm, th = s
        th_true[k] = wrap(th)
        w_true[k] = PP * wm
        za = round(float(ia + noise[k, 0]), 6)
        zb = round(float(ib + noise[k, 1]), 6)
        z[k] = (za, zb)

        # controller: measured currents, true angle and true speed
        c, sn = math.cos(th), math.sin(th)
        i_d = za * c + zb * sn
        i_q = -za * sn + zb * c
        e_w = W_MECH_REF - wm
        iq_ref = kp_w * e_w + int_w
        if abs(iq_ref) < iq_max:
            int_w += ki_w * TS * e_w
        iq_ref = max(-iq_max, min(iq_max, iq_ref))
        id_ref = 0.0
        w = PP * wm
        e_d, e_q = id_ref - i_d, iq_ref - i_q
        vd = kp_i * e_d + int_d - w * LS * i_q
        vq = kp_i * e_q + int_q + w * (LS * i_d + PSI)
        int_d += ki_i * TS * e_d
        int_q += ki_i * TS * e_q
        mag = math.hypot(vd, vq)
        if mag > U_MAX:
            vd, vq = vd * U_MAX / mag, vq * U_MAX / mag
        ua = round(vd * c - vq * sn, 6)
        ub = round(vd * sn + vq * c, 6)
        u[k] = (ua, ub)

        tl = T_LOAD_LO if k < T_LOAD_STEP_K else T_LOAD_HI
        for _ in range(SUBSTEPS):
            s = rk4_step(s, ua, ub, tl, h)
    return u, z, th_true, w_true


# ---------------------------------------------------------------------------
# Seed EKF (forward Euler), exactly as specified
# ---------------------------------------------------------------------------
def f_cont(x):
    ia, ib, w, th = x
    return np.array([(-RS * ia + w * PSI * math.sin(th)) / LS,
                     (-RS * ib - w * PSI * math.cos(th)) / LS,
                     0.0,
                     w])


def jac_F(x):
    ia, ib, w, th = x
    st, ct = math.sin(th), math.cos(th)
    return np.array([[-RS / LS, 0.0, PSI / LS * st, w * PSI / LS * ct],
                     [0.0, -RS / LS, -PSI / LS * ct, w * PSI / LS * st],
                     [0.0, 0.0, 0.0, 0.0],
                     [0.0, 0.0, 1.0, 0.0]])


def euler_predict_x(x, u_prev):
    return x + TS * (f_cont(x) + np.array([u_prev[0] / LS, u_prev[1] / LS, 0.0, 0.0]))


def run_seed_ekf(u, z, x0, p0_diag):
    x = np.array(x0, dtype=float)
    P = np.diag(np.array(p0_diag, dtype=float))
    xs = np.zeros((N, 4))
    pd = np.zeros((N, 4))
    nis = np.zeros(N)
    for k in range(N):
        u_prev = u[k - 1] if k > 0 else np.zeros(2)
        # predict
        Phi = I4 + TS * jac_F(x)
        x_minus = euler_predict_x(x, u_prev)
        P_minus = Phi @ P @ Phi.T + Q
        x_minus[3] = wrap(x_minus[3])
        # correct
        y = z[k] - H @ x_minus
        S = H @ P_minus @ H.T + R
        Sinv = np.linalg.inv(S)
        K = P_minus @ H.T @ Sinv
        x = x_minus + K @ y
        P = (I4 - K @ H) @ P_minus
        P = 0.5 * (P + P.T)
        x[3] = wrap(x[3])
        xs[k] = x
        pd[k] = np.diag(P)
        nis[k] = y @ Sinv @ y
    return xs, pd, nis


def run_filterpy_ekf(u, z, x0, p0_diag):
    from filterpy.kalman import ExtendedKalmanFilter

    class SeedEKF(ExtendedKalmanFilter):
        def predict_x(self, u=0):
            self.x = euler_predict_x(self.x.ravel(), u).reshape(4, 1)

    ekf = SeedEKF(dim_x=4, dim_z=2)
    ekf.x = np.array(x0, dtype=float).reshape(4, 1)
    ekf.P = np.diag(np.array(p0_diag, dtype=float))
    ekf.Q = Q.copy()
    ekf.R = R.copy()
    xs = np.zeros((N, 4))
    pd = np.zeros((N, 4))
    for k in range(N):
        u_prev = u[k - 1] if k > 0 else np.zeros(2)
        ekf.F = I4 + TS * jac_F(ekf.x.ravel())
        ekf.predict(u=u_prev)
        ekf.x[3, 0] = wrap(ekf.x[3, 0])
        ekf.update(z[k].reshape(2, 1), HJacobian=lambda x: H, Hx=lambda x: H @ x)
        ekf.x[3, 0] = wrap(ekf.x[3, 0])
        xs[k] = ekf.x.ravel()
        pd[k] = np.diag(ekf.P)
    return xs, pd


def angdiff(a, b):
    return np.array([wrap(t) for t in (np.asarray(a) - np.asarray(b))])


def max_rel_diff(a, b):
    """Column-wise normwise relative difference: max_k |a-b| / max_k |b|, max over columns.
    Column 3 (angle) uses the wrapped difference."""
    worst = 0.0
    for c in range(a.shape[1]):
        d = angdiff(a[:, c], b[:, c]) if c == 3 else a[:, c] - b[:, c]
        worst = max(worst, float(np.max(np.abs(d)) / np.max(np.abs(b[:, c]))))
    return worst


def fr(v):
    return repr(float(v))


def fe(v):
    return '%.16e' % float(v)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--out', default=os.path.join(os.path.dirname(os.path.abspath(__file__)),
                                                  'seed_reference.csv'))
    args = ap.parse_args()

    u, z, th_true, w_true = simulate()
    x0 = [float(z[0, 0]), float(z[0, 1]), 0.9 * float(w_true[0]), wrap(float(th_true[0]) + 0.3)]
    xs, pd, nis = run_seed_ekf(u, z, x0, P0_DIAG)

    # --- sanity: scenario ---
    rpm = w_true / PP * 60.0 / (2.0 * math.pi)
    print('mechanical speed [rpm]: start %.1f  min %.1f  max %.1f  end %.1f'
          % (rpm[0], rpm.min(), rpm.max(), rpm[-1]))
    print('max |u| = %.2f V' % float(np.max(np.hypot(u[:, 0], u[:, 1]))))

    # --- tracking ---
    half = N // 2
    eth = angdiff(xs[half:, 3], th_true[half:])
    rms_th = math.sqrt(float(np.mean(eth ** 2)))
    rms_w = math.sqrt(float(np.mean((xs[half:, 2] - w_true[half:]) ** 2)))
    print('tracking over last half: RMS angle error = %.4f deg, RMS elec. speed error = %.3f rad/s'
          % (math.degrees(rms_th), rms_w))
    print('mean NIS = %.4f (R = 0.1 >> noise variance 0.0025, so well below 2 is expected)'
          % float(np.mean(nis)))
    assert math.degrees(rms_th) < 5.0, 'filter does not track'

    # --- robustness: perturb x0[3] by 1e-13 ---
    x0p = list(x0)
    x0p[3] = x0p[3] + 1e-13
    xs_p, pd_p, nis_p = run_seed_ekf(u, z, x0p, P0_DIAG)
    sens = max(max_rel_diff(xs_p, xs), max_rel_diff(pd_p, pd),
               float(np.max(np.abs(nis_p - nis)) / np.max(np.abs(nis))))
    print('perturbation sensitivity (x0[3] += 1e-13): max rel diff = %.3e' % sens)
    assert sens < 1e-9, 'reference is too sensitive to initial conditions'

    # --- optional independent check with filterpy ---
    try:
        import filterpy  # noqa: F401
        have_fp = True
    except ImportError:
        have_fp = False
    if have_fp:
        xs_f, pd_f = run_filterpy_ekf(u, z, x0, P0_DIAG)
        dx = max_rel_diff(xs_f, xs)
        dp = max_rel_diff(pd_f, pd)
        print('filterpy %s check: max rel diff state = %.3e, diag(P) = %.3e'
              % (filterpy.__version__, dx, dp))
        assert dx < 1e-9, 'filterpy disagrees with the reference'
    else:
        print('filterpy not importable: filterpy check skipped')

    # --- write CSV ---
    with open(args.out, 'w', newline='\n') as fh:
        fh.write('# seed_reference v1\n')
        fh.write('# rs=2.875 ls=0.0085 psi_f=0.175 pole_pairs=4 ts=0.0001\n')
        fh.write('# q=0.01,0.01,10,0.01 r=0.1,0.1\n')
        fh.write('# x0=' + ','.join(fr(v) for v in x0) + '\n')
        fh.write('# p0=' + ','.join(fr(v) for v in P0_DIAG) + '\n')
        fh.write('k,u_a,u_b,z_a,z_b,i_a,i_b,w,th,p00,p11,p22,p33,nis,th_true,w_true\n')
        for k in range(N):
            row = [str(k), fr(u[k, 0]), fr(u[k, 1]), fr(z[k, 0]), fr(z[k, 1])]
            row += [fr(v) for v in xs[k]] + [fr(v) for v in pd[k]] + [fr(nis[k])]
            row += [fr(th_true[k]), fr(w_true[k])]
            fh.write(','.join(row) + '\n')
    print('wrote %s (%d bytes)' % (args.out, os.path.getsize(args.out)))


if __name__ == '__main__':
    sys.exit(main())
