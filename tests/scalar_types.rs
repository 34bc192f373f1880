//! f64, a scalar dual (`Dual64`) and a multi-direction dual (`DualSVec64<3>`) pass through every
//! point kernel (foundation issue: "f64, num-dual's first-order dual and a multi-direction dual
//! must all pass through every kernel").
//!
//! One pipeline chains them: surface evaluation (geometry) → lamina frame → mid-step gradient →
//! Hughes–Winget increment → local strain increment → return map → frame update → global stress.
//! Three design variables enter at different stages (sphere radius, strain magnitude, Young's
//! modulus). The real parts must agree in all three scalar types (duals compute their real
//! parts with the same algorithm, to round-off), and the 3-direction dual's derivative parts must equal
//! three scalar-dual passes.

use nalgebra::{Matrix3, Vector3};
use shelldsa::geometry::{SphereZone, Surface};
use shelldsa::kinematics::{
    frame_update, global_stress, hughes_winget, local_strain_increment, mid_step_gradient,
    strain_to_vec5, stress_from_vec5,
};
use shelldsa::material::{return_map, MaterialParams, MaterialState};
use shelldsa::scalar::{dual_parts, seed, Dual, DualN, Real};

fn pipeline<T: Real>(p: [T; 3]) -> Vec<T> {
    let sphere = SphereZone::new(
        Vector3::zeros(),
        T::cst(10.0),
        [T::zero(), T::cst(72f64.to_radians())],
        [T::zero(), T::cst(90f64.to_radians())],
    )
    .unwrap();
    let surf = Surface::SphereZone(sphere);
    // Replace the radius by the first design variable.
    let names = surf.parameter_names();
    let mut params: Vec<T> = surf.parameter_values();
    let k = names.iter().position(|n| n == "radius").unwrap();
    params[k] = p[0];
    let surf = surf.with_design_parameters(&params).unwrap();
    let sd = surf.eval(T::cst(0.3), T::cst(0.6));
    let n = sd.normal().unwrap();
    let e1 = sd.xu.normalize();
    let e2 = n.cross(&e1);
    let q = Matrix3::from_rows(&[e1.transpose(), e2.transpose(), n.transpose()]);
    // A finite step: stretch scaled by the second design variable, plus a rotation.
    let s = p[1];
    let h = Matrix3::new(
        s * 2e-3,
        T::cst(0.2),
        s * 1e-3,
        T::cst(-0.2),
        s * -1e-3,
        T::cst(0.05),
        s * 5e-4,
        T::cst(-0.05),
        s * 1e-3,
    );
    let l = mid_step_gradient(&h).unwrap();
    let inc = hughes_winget(&l).unwrap();
    let deps_local = local_strain_increment(&q, &inc.r_half, &inc.deps);
    let m = MaterialParams {
        young: p[2],
        ..MaterialParams::new(210e3, 0.3, 250.0, 1000.0, 0.5)
            .unwrap()
            .lift()
    };
    let out = return_map(&m, &MaterialState::virgin(), &strain_to_vec5(&deps_local)).unwrap();
    assert!(out.plastic, "the pipeline must reach the plastic branch");
    let q1 = frame_update(&q, &inc.r);
    let sg = global_stress(&q1, &stress_from_vec5(&out.state.stress));
    sd.x.iter()
        .chain(sg.iter())
        .copied()
        .chain(std::iter::once(out.state.eps_p))
        .collect()
}

#[test]
fn f64_dual_and_multi_direction_dual_through_every_kernel() {
    let x = [10.0, 1.0, 210e3];
    let f = pipeline(x);
    let v = pipeline([seed::<3>(x[0], 0), seed::<3>(x[1], 1), seed::<3>(x[2], 2)]);
    for j in 0..3 {
        let xd: [Dual; 3] = std::array::from_fn(|i| {
            if i == j {
                Dual::from_re(x[i]).derivative()
            } else {
                Dual::from_re(x[i])
            }
        });
        let d = pipeline(xd);
        for (i, ((a, b), c)) in f.iter().zip(&d).zip(&v).enumerate() {
            // Real parts: the same algorithm in f64, but num-dual forms quotients as products with
            // a reciprocal, so they agree to round-off (1e-14 of the output's magnitude), not to
            // the last bit.
            let tol = 1e-14 * a.abs().max(1e-3);
            assert!(
                (a - b.re).abs() <= tol,
                "output {i}: f64 {a} vs Dual64 {}",
                b.re
            );
            assert!(
                (a - c.re).abs() <= tol,
                "output {i}: f64 {a} vs DualSVec64 {}",
                c.re
            );
            // One wide pass vs one narrow pass per direction: the same chain rule, evaluated
            // with the same operations per direction, so round-off-level agreement (1e-14 of the
            // largest derivative in this direction).
            let dmax = d.iter().map(|y| y.eps.abs()).fold(0.0, f64::max);
            let wide: &DualN<3> = c;
            let dw = dual_parts(wide)[j];
            assert!(
                (dw - b.eps).abs() <= 1e-14 * dmax,
                "output {i}, direction {j}: {dw} vs {}",
                b.eps
            );
        }
        // Every design variable influences the stress: a chain that lost one would pass the
        // equality above vacuously.
        assert!(
            d[3..12].iter().any(|y| y.eps.abs() > 0.0),
            "direction {j} has no effect"
        );
    }
}
