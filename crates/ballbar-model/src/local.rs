//! The error field where a test is: the volumetric error `Δ` (tool ball relative to table ball,
//! base frame) per unit of each machine parameter at one pose, and its linear part about a
//! circle's centre, the quantities a circle there determines whatever the polynomials' origin.
//!
//! # The local linear field and its signs
//! About a circle's centre `c` (machine coordinates of the pivot, with the run's tool offset),
//! `Δ(c + d) ≈ Δ(c) + J d` with `J_ab = ∂Δ_a/∂q_b` (dimensionless). For a linear field a circle
//! of radius `R` in plane `UV` reads `ΔR = R n·J n` (`n` the unit bar direction): only the
//! symmetric part of `J`'s `UV` block shows, and it shows whole. Hence, per plane `UV`:
//! - **local scale** of `U`: `J_UU` (ppm shown): a positive value stretches the circle along
//!   `U`, as a positive positional error of degree 1 does;
//! - **local squareness** `UV`: `-(J_UV + J_VU)` (µrad shown), the sign of the crate's
//!   squareness convention (`ΔY = -α X` gives `J_YX = -α`, so a local squareness of `α`): a
//!   positive value shortens the bar at 45° and 225° of the plane.
//!
//! Every error motion enters `J` with its Abbe arm at the run's tool offset (a pitch of X
//! times the tool length is a local scale of X). `J` is linear in the parameters; its columns
//! come from central differences of the exact first-order `Δ` ([`error_columns`]) with a step
//! of [`DIFFERENCE_STEP_MM`].

use nalgebra::Vector3;

use crate::axis::{Axis, Plane};
use crate::chain::{BallSetup, Branch, ChainPose, JointSensitivity};
use crate::machine::Model;
use crate::term::JointState;
use crate::{ModelError, ParamClass};

/// Step of the central differences, mm. The polynomial terms are `θ s^k` with `s = (q-q_ref)/L`,
/// `L` ≥ 100 mm on every shipped machine and `k` ≤ 4: the truncation error of a central
/// difference is `h² f'''/6`, relative to `f'` at most `(k h / L)²/6` ≈ 3e-10 at h = 0.01 mm;
/// the rounding error, `ε |f| / h` with `|f|` ≲ 16 per unit coefficient, is ≈ 2e-13 per mm
/// against slopes of ≳ 1e-3 per mm. Both are far below any uncertainty a ballbar reaches.
pub const DIFFERENCE_STEP_MM: f64 = 0.01;

/// The first-order volumetric error of the tool ball relative to the table ball (base frame,
/// mm) per unit coefficient of each machine parameter (the model's parameter order: chain
/// terms, then reading terms, whose columns are zero), at machine coordinates `q` with the
/// balls at `balls`, the machine at rest (no velocity, direction, time or feed: backlash,
/// lags and transients give nothing).
pub fn error_columns(
    model: &Model,
    q: &[f64; 6],
    balls: &BallSetup,
) -> Result<Vec<Vector3<f64>>, ModelError> {
    let mut pose = ChainPose::default();
    model.chain.pose_into(q, balls, None, None, &mut pose);
    let mut states = [JointState::default(); 6];
    for a in Axis::ALL {
        states[a.index()].q = q[a.index()];
    }
    // Δ_k for each unit direction e_k: the sensitivities of e_k·Δ.
    let mut sens: [(Vec<JointSensitivity>, Vec<JointSensitivity>); 3] = Default::default();
    for (k, (tool, work)) in sens.iter_mut().enumerate() {
        let mut u = Vector3::zeros();
        u[k] = 1.0;
        crate::chain::sensitivities_along(&pose, &u, tool, work);
    }
    let mut out = vec![Vector3::zeros(); model.terms.len() + model.reading_terms.len()];
    for (col, bt) in out.iter_mut().zip(&model.terms) {
        let e = bt.term.basis(&states[bt.axis.index()])?;
        for (k, (tool, work)) in sens.iter().enumerate() {
            let s = match bt.branch {
                Branch::Tool => &tool[bt.joint],
                Branch::Workpiece => &work[bt.joint],
            };
            col[k] = s.apply(&e);
        }
    }
    Ok(out)
}

/// `∂Δ/∂q` at machine coordinates `q` (linear axes X, Y, Z) with the balls at `balls`: per
/// machine parameter, the 3×3 matrix `J_ab = ∂Δ_a/∂q_b`, by central differences.
pub fn jacobian_columns(
    model: &Model,
    q: &[f64; 6],
    balls: &BallSetup,
) -> Result<Vec<nalgebra::Matrix3<f64>>, ModelError> {
    let h = DIFFERENCE_STEP_MM;
    let mut out = vec![nalgebra::Matrix3::zeros(); model.terms.len() + model.reading_terms.len()];
    for b in 0..3 {
        let (mut plus, mut minus) = (*q, *q);
        plus[b] += h;
        minus[b] -= h;
        let p = error_columns(model, &plus, balls)?;
        let m = error_columns(model, &minus, balls)?;
        for (j, col) in out.iter_mut().enumerate() {
            let d = (p[j] - m[j]) / (2.0 * h);
            for a in 0..3 {
                col[(a, b)] = d[a];
            }
        }
    }
    Ok(out)
}

/// Step of the exact field's central differences, mm: the exact error is a polynomial of
/// degree ≤ 4 in positions normalised by L ≥ 100 mm composed with rigid rotations, so the
/// truncation error is ≲ (4 h/L)²/6 ≈ 3e-7 relative at h = 0.1 mm; the rounding of ball
/// positions of ≲ 1e3 mm (≈ 1e-13 mm) over 2h is ≈ 5e-13, far below any local scale's u.
pub const EXACT_DIFFERENCE_STEP_MM: f64 = 0.1;

/// Step of the second differences across the plane, mm: truncation (h/L)² ≈ 1e-5 relative at
/// 1 mm, rounding ≈ 1e-13 mm / h² against curvatures of ≳ 1e-9 per mm where they matter.
pub const CURVATURE_STEP_MM: f64 = 1.0;

/// The exact volumetric error (tool ball relative to table ball, base frame, mm) at machine
/// coordinates `q` for machine parameters `theta` (the model's order; reading terms ignored):
/// every error motion applied as a rigid transform, the machine at rest.
pub fn exact_error(
    model: &Model,
    q: &[f64; 6],
    balls: &BallSetup,
    theta: &[f64],
) -> Result<Vector3<f64>, ModelError> {
    let chain = &model.chain;
    let mut tool = vec![[0.0; 6]; chain.tool.len()];
    let mut work = vec![[0.0; 6]; chain.workpiece.len()];
    let mut states = [JointState::default(); 6];
    for a in Axis::ALL {
        states[a.index()].q = q[a.index()];
    }
    for (bt, &c) in model.terms.iter().zip(theta) {
        if c == 0.0 {
            continue;
        }
        crate::design::add_motion(bt, c, &states, &mut tool, &mut work)?;
    }
    let exact = chain.pose(q, balls, Some(&tool), Some(&work));
    let nominal = chain.pose(q, balls, None, None);
    Ok((exact.tool_ball - exact.table_ball) - (nominal.tool_ball - nominal.table_ball))
}

/// The value of local quantity `kind` of plane `plane` for machine parameters `theta`, from the
/// exact error field ([`exact_error`], central differences of [`EXACT_DIFFERENCE_STEP_MM`]):
/// [`local_functional`]'s value to first order, and with the field's second-order geometry
/// (an angle of the field turning the arms of the chain, an error across the plane), which a
/// circle of radius `radius_mm` reads too.
pub fn exact_local_value(
    model: &Model,
    plane: Plane,
    pivot_mm: &[f64; 3],
    tool_ball_mm: &[f64; 3],
    radius_mm: f64,
    kind: LocalKind,
    theta: &[f64],
) -> Result<f64, ModelError> {
    let (u, v, _) = plane.axes().ok_or_else(|| ModelError::InvalidMachine {
        message: "local quantities are of a planar test".into(),
    })?;
    let balls = model.chain.ball_setup(pivot_mm, tool_ball_mm);
    let h = EXACT_DIFFERENCE_STEP_MM;
    let d = |b: Axis| -> Result<Vector3<f64>, ModelError> {
        let (mut plus, mut minus) = ([0.0; 6], [0.0; 6]);
        plus[..3].copy_from_slice(pivot_mm);
        minus[..3].copy_from_slice(pivot_mm);
        plus[b.index()] += h;
        minus[b.index()] -= h;
        Ok((exact_error(model, &plus, &balls, theta)? - exact_error(model, &minus, &balls, theta)?)
            / (2.0 * h))
    };
    let (iu, iv, iw) = (u.index(), v.index(), plane.axes().expect("planar").2.index());
    let (du, dv) = (d(u)?, d(v)?);
    // What the circle reads beside the linear field's radial part, in second order: the bar
    // lengthens by |δ_⊥|²/(2R), δ_⊥ the error across the bar (the exact reading's first
    // omitted term). Its mean over the circle is a
    // constant the fit's mean radius takes, and with it the two scales' sum (a bar known, or
    // gauged at its nominal length). With J the in-plane block, ω = (J_VU - J_UV)/2 its
    // rotation, a = (J_VV - J_UU)/2 and b = (J_UV + J_VU)/2 its ellipse, δ_W(c) the error
    // across the plane at the centre and g = (J_WU, J_WV) its slope, the mean of |δ_⊥|²/(2R)
    // is R (ω² + (a² + b²)/2)/2 + (δ_W(c)² + R²|g|²/2)/(2R): each scale as the circle reads it
    // is J_UU (J_VV) plus that over R. The fit fixes what the runs cannot see (a rotation, an
    // error across the plane) by its gauges and minimum norm, which the pivot and tool length
    // given change; without this, a value of 70 µm across the plane at R = 50 mm moved both
    // scales by 1 ppm.
    let mut centre = [0.0; 6];
    centre[..3].copy_from_slice(pivot_mm);
    let across = exact_error(model, &centre, &balls, theta)?[iw];
    let omega = (du[iv] - dv[iu]) / 2.0;
    let (a, b) = ((dv[iv] - du[iu]) / 2.0, (dv[iu] + du[iv]) / 2.0);
    let g2 = du[iw] * du[iw] + dv[iw] * dv[iw];
    let r = radius_mm;
    // The error across the plane curves over the circle too, δ_W ≈ δ_W(c) + R g·n +
    // (R²/2) n·K n (K its in-plane second derivatives): its product with δ_W(c) adds
    // δ_W(c) R n·K n / 2 to the reading, a constant and an ellipse.
    let h2 = CURVATURE_STEP_MM;
    let at = |du_mm: f64, dv_mm: f64| -> Result<f64, ModelError> {
        let mut q = centre;
        q[iu] += du_mm;
        q[iv] += dv_mm;
        Ok(exact_error(model, &q, &balls, theta)?[iw])
    };
    let k_uu = (at(h2, 0.0)? - 2.0 * across + at(-h2, 0.0)?) / (h2 * h2);
    let k_vv = (at(0.0, h2)? - 2.0 * across + at(0.0, -h2)?) / (h2 * h2);
    let k_uv = (at(h2, h2)? - at(h2, -h2)? - at(-h2, h2)? + at(-h2, -h2)?) / (4.0 * h2 * h2);
    let lift = (omega * omega + (a * a + b * b) / 2.0) / 2.0
        + (across * across + r * r * g2 / 2.0) / (2.0 * r * r)
        + across * (k_uu + k_vv) / 4.0;
    // Its twice-per-revolution part reads as an ellipse, R (ω b + (g_U² - g_V²)/4) cos 2θ +
    // R (ω a + g_U g_V/2) sin 2θ, against the linear field's R (J_UU - J_VV)/2 cos 2θ +
    // R (J_UV + J_VU)/2 sin 2θ.
    let (gu, gv) = (du[iw], dv[iw]);
    let stretch = omega * b + (gu * gu - gv * gv) / 4.0 + across * (k_uu - k_vv) / 4.0;
    let shear = omega * a + gu * gv / 2.0 + across * k_uv / 2.0;
    Ok(match kind {
        LocalKind::ScaleU => du[iu] + lift + stretch,
        LocalKind::ScaleV => dv[iv] + lift - stretch,
        LocalKind::Squareness => -(dv[iu] + du[iv]) - 2.0 * shear,
    })
}

/// Which local quantity of a plane.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LocalKind {
    /// `J_UU` of the plane's first axis (dimensionless, shown in ppm).
    ScaleU,
    /// `J_VV` of the plane's second axis.
    ScaleV,
    /// `-(J_UV + J_VU)` (rad, shown in µrad).
    Squareness,
}

impl LocalKind {
    /// The three, in report order.
    pub const ALL: [LocalKind; 3] = [LocalKind::ScaleU, LocalKind::ScaleV, LocalKind::Squareness];
}

/// The coefficients (per machine parameter, in the model's parameter order) of the local
/// quantity `kind` of plane `plane` at a circle centred at `pivot_mm` with the tool ball at
/// `tool_ball_mm`: the quantity is `Σ c_j θ_j`. Nuisance and reading parameters get 0.
pub fn local_functional(
    model: &Model,
    plane: Plane,
    pivot_mm: &[f64; 3],
    tool_ball_mm: &[f64; 3],
    kind: LocalKind,
) -> Result<Vec<f64>, ModelError> {
    let (u, v, _) = plane.axes().ok_or_else(|| ModelError::InvalidMachine {
        message: "local quantities are of a planar test".into(),
    })?;
    let balls = model.chain.ball_setup(pivot_mm, tool_ball_mm);
    let mut q = [0.0; 6];
    q[..3].copy_from_slice(pivot_mm);
    let jac = jacobian_columns(model, &q, &balls)?;
    let (iu, iv) = (u.index(), v.index());
    let params = model.parameters();
    Ok(jac
        .iter()
        .zip(&params)
        .map(|(j, p)| match p.class {
            ParamClass::Term(_) => match kind {
                LocalKind::ScaleU => j[(iu, iu)],
                LocalKind::ScaleV => j[(iv, iv)],
                LocalKind::Squareness => -(j[(iu, iv)] + j[(iv, iu)]),
            },
            _ => 0.0,
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::machine::ModelOptions;
    use crate::machines::{COLUMN_NORM_LENGTH_MM, column};

    fn value(model: &Model, theta: &[(&str, f64)], c: &[f64]) -> f64 {
        let ids: Vec<String> = model.parameters().into_iter().map(|p| p.id).collect();
        theta.iter().map(|(id, t)| c[ids.iter().position(|x| x == id).unwrap()] * t).sum()
    }

    #[test]
    fn local_scale_and_squareness_equal_the_hand_derivation_at_an_offset_centre() {
        // Column machine (table X on saddle Y, head Z; every joint origin at 0, L = 250 mm).
        // Field: EXX1 = a (δX = a X/L), EYY1 = b, SQXY = α (δY = -α X), straightness of X in
        // Y, EYX2 = c (δY = c X²/L², tied yaw ε_Z = 2cX/L²), and in Z, EZX2 = e (δZ = e X²/L²,
        // tied pitch ε_Y = -2eX/L²). Centre (Xc, Yc, Zc), tool ball 100 mm below the gauge
        // point. The table ball sits at (Xc, Yc, Zc - 100) in the X table's frame, whose
        // origin is the arm of the table's rotations: ε × arm gives
        //   yaw:   ΔX = -ε_Z Yc, ΔY = +ε_Z Xc,     pitch: ΔX = +ε_Y (Zc - 100).
        // So J_XX = a/L - 2cYc/L² - 2e(Zc - 100)/L², J_YY = b/L,
        //    J_YX = -α + 2cXc/L² (straightness) + 2cXc/L² (yaw), J_XY = 0,
        // local squareness -(J_XY + J_YX) = α - 4cXc/L².
        let model = Model::new(column(), ModelOptions::default()).unwrap();
        let l = COLUMN_NORM_LENGTH_MM;
        let (a, b, alpha, c, e) = (5e-3, -3e-3, 40e-6, 3e-3, 2e-3);
        let theta = [("EXX1", a), ("EYY1", b), ("SQXY", alpha), ("EYX2", c), ("EZX2", e)];
        let (xc, yc, zc) = (120.0, -80.0, 60.0);
        let pivot = [xc, yc, zc];
        let tool = [0.0, 0.0, -100.0];
        let get = |k| {
            value(&model, &theta, &local_functional(&model, Plane::XY, &pivot, &tool, k).unwrap())
        };
        let scale_x = a / l - 2.0 * c * yc / (l * l) - 2.0 * e * (zc - 100.0) / (l * l);
        let scale_y = b / l;
        let square = alpha - 4.0 * c * xc / (l * l);
        // The central differences are exact for these quadratics to rounding: 1e-12 of the
        // values (≈ 1e-5) is far below it and far below any ballbar's resolution.
        for (k, want) in [
            (LocalKind::ScaleU, scale_x),
            (LocalKind::ScaleV, scale_y),
            (LocalKind::Squareness, square),
        ] {
            let got = get(k);
            assert!((got - want).abs() < 1e-12, "{k:?}: {got} against {want}");
            // The exact field's value: the same but for second order, (≤ 1e-4 rad)² here.
            let ids: Vec<String> = model.parameters().into_iter().map(|p| p.id).collect();
            let mut th = vec![0.0; ids.len()];
            for (id, t) in theta {
                th[ids.iter().position(|x| x == id).unwrap()] = t;
            }
            let exact = exact_local_value(&model, Plane::XY, &pivot, &tool, 150.0, k, &th).unwrap();
            assert!((exact - want).abs() < 1e-8, "{k:?} exact: {exact} against {want}");
        }
    }

    #[test]
    fn an_error_across_the_plane_at_the_centre_reads_as_a_common_scale_of_its_square() {
        // A positional error of Z alone, δZ = θ Z/L, θ = 50 µm at L: at a centre Zc = 250 mm the
        // balls sit δ = 50 µm apart across the XY plane, and the bar reads |d + δ| - R =
        // √(R² + δ²) - R all round (by hand). No in-plane field: the local scales are that
        // over R, ≈ δ²/(2R²) = 5e-7 at R = 50 mm (0.5 ppm), the squareness 0.
        let model = Model::new(column(), ModelOptions::default()).unwrap();
        let ids: Vec<String> = model.parameters().into_iter().map(|p| p.id).collect();
        let mut th = vec![0.0; ids.len()];
        th[ids.iter().position(|x| x == "EZZ1").unwrap()] = 0.05;
        let (pivot, tool, r) = ([40.0, -30.0, 250.0], [0.0; 3], 50.0);
        let delta = 0.05 * 250.0 / COLUMN_NORM_LENGTH_MM;
        let want = ((r * r + delta * delta).sqrt() - r) / r;
        for (k, w) in
            [(LocalKind::ScaleU, want), (LocalKind::ScaleV, want), (LocalKind::Squareness, 0.0)]
        {
            let got = exact_local_value(&model, Plane::XY, &pivot, &tool, r, k, &th).unwrap();
            // δ⁴/(8R⁴) ≈ 1e-13 between the closed form and δ²/(2R²); differences ≈ 1e-12.
            assert!((got - w).abs() < 1e-11, "{k:?}: {got} against {w}");
        }
    }

    #[test]
    fn a_circle_of_a_linear_field_reads_r_n_j_n_with_the_documented_signs() {
        // A pure squareness α: local squareness α, no local scale; the bar is shorter at 45°
        // (ΔR = -α R/2) and longer at 135° (the crate's convention). A pure EXX1 = a: local
        // scale a/L of X, and ΔR = R a/L at 0°.
        let model = Model::new(column(), ModelOptions::default()).unwrap();
        let pivot = [30.0, 40.0, -50.0];
        let tool = [0.0, 0.0, -80.0];
        let r = 100.0;
        let balls = model.chain.ball_setup(&pivot, &tool);
        let ids: Vec<String> = model.parameters().into_iter().map(|p| p.id).collect();
        let at = |id: &str, deg: f64| {
            let n = Vector3::new(deg.to_radians().cos(), deg.to_radians().sin(), 0.0);
            let q = [pivot[0] + r * n.x, pivot[1] + r * n.y, pivot[2], 0.0, 0.0, 0.0];
            let centre = [pivot[0], pivot[1], pivot[2], 0.0, 0.0, 0.0];
            let j = ids.iter().position(|x| x == id).unwrap();
            // About the centre's own error (a displacement of the circle, a centring).
            let d = error_columns(&model, &q, &balls).unwrap()[j]
                - error_columns(&model, &centre, &balls).unwrap()[j];
            n.dot(&d)
        };
        let alpha = 1.0;
        assert!((at("SQXY", 45.0) * alpha + alpha * r / 2.0).abs() < 1e-9);
        assert!((at("SQXY", 135.0) * alpha - alpha * r / 2.0).abs() < 1e-9);
        let sq = local_functional(&model, Plane::XY, &pivot, &tool, LocalKind::Squareness).unwrap();
        let sx = local_functional(&model, Plane::XY, &pivot, &tool, LocalKind::ScaleU).unwrap();
        let j = ids.iter().position(|x| x == "SQXY").unwrap();
        assert!((sq[j] - 1.0).abs() < 1e-9 && sx[j].abs() < 1e-9, "{} {}", sq[j], sx[j]);
        let k = ids.iter().position(|x| x == "EXX1").unwrap();
        let l = COLUMN_NORM_LENGTH_MM;
        assert!((sx[k] - 1.0 / l).abs() < 1e-12 && sq[k].abs() < 1e-12);
        assert!((at("EXX1", 0.0) - r / l).abs() < 1e-12);
    }
}
