//! Known-answer vectors for the transforms and for SVPWM in each sector.

use core::f32::consts::{FRAC_PI_3, PI};

use foc::svpwm::{linear_limit_v, sector};
use foc::{Abc, AlphaBeta, Dq, duties_to_alpha_beta, svpwm};

const SQRT_3: f32 = 1.732_050_8;

fn close(a: f32, b: f32, tol: f32) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn clarke_park_known_answers() {
    // (input abc, expected alpha-beta)
    let cases = [
        ((1.0, -0.5, -0.5), (1.0, 0.0)),
        ((-0.5, 1.0, -0.5), (-0.5, SQRT_3 / 2.0)),
        ((-0.5, -0.5, 1.0), (-0.5, -SQRT_3 / 2.0)),
        ((0.0, SQRT_3 / 2.0, -SQRT_3 / 2.0), (0.0, 1.0)),
        ((2.0, -1.0, -1.0), (2.0, 0.0)),
    ];
    for ((a, b, c), (al, be)) in cases {
        let x = Abc { a, b, c };
        for ab in [x.to_alpha_beta(), x.to_alpha_beta_3()] {
            assert!(
                close(ab.alpha, al, 1e-6) && close(ab.beta, be, 1e-6),
                "{x:?} -> {ab:?}"
            );
        }
        let back = AlphaBeta {
            alpha: al,
            beta: be,
        }
        .to_abc();
        assert!(
            close(back.a, a, 1e-6) && close(back.b, b, 1e-6) && close(back.c, c, 1e-6),
            "{back:?}"
        );
    }
    // Park: (alpha, beta, theta) -> (d, q)
    let park = [
        (1.0, 0.0, 0.0, 1.0, 0.0),
        (1.0, 0.0, PI / 2.0, 0.0, -1.0),
        (0.0, 1.0, PI / 2.0, 1.0, 0.0),
        (0.0, 1.0, 0.0, 0.0, 1.0),
        (1.0, 0.0, PI, -1.0, 0.0),
        (0.5, SQRT_3 / 2.0, FRAC_PI_3, 1.0, 0.0),
        (0.5, SQRT_3 / 2.0, -FRAC_PI_3, -0.5, SQRT_3 / 2.0),
    ];
    for (al, be, th, d, q) in park {
        let dq = AlphaBeta {
            alpha: al,
            beta: be,
        }
        .to_dq_angle(th);
        assert!(close(dq.d, d, 1e-6) && close(dq.q, q, 1e-6), "{th}: {dq:?}");
        let ab = Dq { d, q }.to_alpha_beta_angle(th);
        assert!(
            close(ab.alpha, al, 1e-6) && close(ab.beta, be, 1e-6),
            "{th}: {ab:?}"
        );
    }
}

/// Duties of the classic sector-based SVPWM (T1, T2 on the two adjacent active vectors,
/// zero time split equally between V0 and V7): an independent reference.
fn classic_svpwm(u: AlphaBeta, u_dc: f32) -> [f32; 3] {
    // Switching states of V1..V6 (phase a, b, c).
    const V: [[f32; 3]; 6] = [
        [1.0, 0.0, 0.0],
        [1.0, 1.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 1.0, 1.0],
        [0.0, 0.0, 1.0],
        [1.0, 0.0, 1.0],
    ];
    let mag = (u.alpha * u.alpha + u.beta * u.beta).sqrt();
    let mut ang = u.beta.atan2(u.alpha);
    if ang < 0.0 {
        ang += 2.0 * PI;
    }
    let n = ((ang / FRAC_PI_3) as usize).min(5);
    let th = ang - n as f32 * FRAC_PI_3;
    let m = SQRT_3 * mag / u_dc;
    let t1 = m * (FRAC_PI_3 - th).sin();
    let t2 = m * th.sin();
    let t0 = 1.0 - t1 - t2;
    let (va, vb) = (V[n], V[(n + 1) % 6]);
    [0, 1, 2].map(|x| t0 / 2.0 + t1 * va[x] + t2 * vb[x])
}

#[test]
fn svpwm_each_sector_known_answers() {
    let u_dc = 100.0;
    for n in 0..6 {
        for frac in [0.1_f32, 0.5, 0.9] {
            let ang = (n as f32 + frac) * FRAC_PI_3;
            let u = AlphaBeta {
                alpha: 0.9 * linear_limit_v(u_dc) * ang.cos(),
                beta: 0.9 * linear_limit_v(u_dc) * ang.sin(),
            };
            assert_eq!(sector(u), n as u8 + 1, "{ang}");
            let m = svpwm(u, u_dc);
            assert!(!m.clamped);
            let reference = classic_svpwm(u, u_dc);
            for (d, r) in m.duties.iter().zip(reference) {
                assert!(
                    close(*d, r, 1e-5),
                    "sector {} {:?} vs {reference:?}",
                    n + 1,
                    m.duties
                );
                assert!((0.0..=1.0).contains(d));
            }
            // Line-to-line voltages reproduce the command's.
            let v = u.to_abc();
            let [da, db, dc] = m.duties;
            assert!(close((da - db) * u_dc, v.a - v.b, 1e-3));
            assert!(close((db - dc) * u_dc, v.b - v.c, 1e-3));
            assert!(close((dc - da) * u_dc, v.c - v.a, 1e-3));
            // Realized voltage = command.
            assert!(close(m.applied.alpha, u.alpha, 1e-3) && close(m.applied.beta, u.beta, 1e-3));
        }
    }
}

#[test]
fn svpwm_literal_vectors() {
    // (alpha, beta, u_dc) -> duties
    let cases: [((f32, f32, f32), [f32; 3]); 5] = [
        ((0.0, 0.0, 100.0), [0.5, 0.5, 0.5]),
        // 30 deg on the inscribed circle (u_dc / sqrt(3)): phases +50, 0, -50 V.
        ((50.0, 28.867_513, 100.0), [1.0, 0.5, 0.0]),
        // 90 deg on the circle: phases 0, +50, -50 V.
        ((0.0, 57.735_027, 100.0), [0.5, 1.0, 0.0]),
        // 0 deg, 40 V: phases 40, -20, -20 -> mid 10 -> 0.5 + (30, -30, -30)/100.
        ((40.0, 0.0, 100.0), [0.8, 0.2, 0.2]),
        // 180 deg, 20 V on a 48 V bus: phases -20, 10, 10 -> mid -5.
        (
            (-20.0, 0.0, 48.0),
            [0.5 - 15.0 / 48.0, 0.5 + 15.0 / 48.0, 0.5 + 15.0 / 48.0],
        ),
    ];
    for ((al, be, udc), want) in cases {
        let m = svpwm(
            AlphaBeta {
                alpha: al,
                beta: be,
            },
            udc,
        );
        for (d, w) in m.duties.iter().zip(want) {
            assert!(close(*d, w, 1e-5), "{al},{be}: {:?} vs {want:?}", m.duties);
        }
    }
}

#[test]
fn overmodulation_keeps_direction_and_range() {
    let u_dc = 48.0;
    for i in 0..72 {
        let ang = i as f32 * (PI / 36.0) - PI;
        for scale in [1.2_f32, 2.0, 10.0, 1.0e6] {
            let r = scale * u_dc; // far outside the hexagon (corner radius 2/3 u_dc)
            let u = AlphaBeta {
                alpha: r * ang.cos(),
                beta: r * ang.sin(),
            };
            let m = svpwm(u, u_dc);
            assert!(m.clamped);
            assert!(
                m.duties
                    .iter()
                    .all(|d| d.is_finite() && (0.0..=1.0).contains(d))
            );
            // On the hexagon: the largest and the smallest duty at the rails.
            let max = m.duties.iter().cloned().fold(f32::MIN, f32::max);
            let min = m.duties.iter().cloned().fold(f32::MAX, f32::min);
            assert!(
                close(max, 1.0, 1e-5) && close(min, 0.0, 1e-5),
                "{:?}",
                m.duties
            );
            // Same direction as the command.
            let a = m.applied.beta.atan2(m.applied.alpha);
            let d = (a - ang + 3.0 * PI).rem_euclid(2.0 * PI) - PI;
            assert!(d.abs() < 1e-4, "{ang}: applied angle {a}");
            // The realized vector lies between the inscribed circle and the corner radius.
            let mag = (m.applied.alpha.powi(2) + m.applied.beta.powi(2)).sqrt();
            assert!(mag >= linear_limit_v(u_dc) - 1e-3 && mag <= 2.0 / 3.0 * u_dc + 1e-3);
        }
    }
}

#[test]
fn svpwm_invalid_inputs_give_safe_duties() {
    for (u, udc) in [
        (
            AlphaBeta {
                alpha: f32::NAN,
                beta: 0.0,
            },
            100.0,
        ),
        (
            AlphaBeta {
                alpha: 1.0,
                beta: f32::INFINITY,
            },
            100.0,
        ),
        (AlphaBeta::default(), 0.0),
        (AlphaBeta::default(), -5.0),
        (AlphaBeta::default(), f32::NAN),
    ] {
        let m = svpwm(u, udc);
        assert_eq!(m.duties, [0.5; 3]);
        assert!(m.clamped);
        assert_eq!(m.applied, AlphaBeta::default());
    }
    // duties_to_alpha_beta inverts the modulation.
    let u = duties_to_alpha_beta([0.8, 0.2, 0.2], 100.0);
    assert!(close(u.alpha, 40.0, 1e-4) && close(u.beta, 0.0, 1e-4));
}
