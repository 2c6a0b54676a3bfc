//! Pahk, Kim & Moon (1997): the 18 basis functions of eqs. (39)/(40) and the paper's 24 reported
//! quantities, computed from this crate's parameters.
//!
//! # From our parameters to the paper's quantities
//! Our error polynomials use the absolute axis position, `s = (q - q_ref)/L`; the paper's use the
//! position about the circle centre, `u = (q - q_c)/R`. The leading coefficient converts without
//! reference to the centre: a degree-`p` term `θ s^p` has the paper coefficient `θ (R/L)^p`
//! (lower-order parts land in the centring and squareness columns of a single-centre fit and are
//! not the paper's quantities). So at a report radius `R` and feed `F`:
//! - positional `dxx1 = EXX1 · R/L_X` (µm); straightness `dyx2 = EYX2 · (R/L_X)²` (µm);
//! - angular errors are the tied derivatives at distance `R`: `ε_Z(X) = +2 dyx2/R`,
//!   `ε_Y(X) = -2 dzx2/R`, `ε_Z(Y) = -2 dxy2/R`, `ε_X(Y) = +2 dzy2/R`, `ε_Y(Z) = +2 dxz2/R`,
//!   `ε_X(Z) = -2 dyz2/R` (µrad). The paper prints |ε| = 2|d|/R; for the column machine its
//!   signs agree with these, for the horizontal machine two rows (Y along X, X along Y) carry the
//!   opposite sign, which we take for the paper's own convention slip;
//! - squareness (µrad), backlash (µm) as fitted;
//! - servo mismatch `M_UV` (µm): the plane term itself, or from the per-axis lags
//!   `M_XY = V (τ_Y - τ_X)`, `M_YZ = V (τ_Z - τ_Y)`, `M_ZX = V (τ_X - τ_Z)` with `V = F/60`.
//!   These three sum to zero: per-axis lags tie the planes by one constraint, which the paper's
//!   own values (8.1 - 2.0 + 3.7 µm) do not meet.

use crate::axis::{Axis, Plane};
use crate::machine::{Model, ServoVariant};
use crate::run::Run;

/// Names of the paper's 18 basis functions, in the domain brief's order.
pub const BASIS_NAMES: [&str; 18] = [
    "u²",
    "v²",
    "w²",
    "u v²",
    "u w²",
    "v u²",
    "v w²",
    "w u²",
    "w v²",
    "u sgn(u')",
    "v sgn(v')",
    "w sgn(w')",
    "u v",
    "v w",
    "w u",
    "u v D",
    "v w D",
    "w u D",
];

/// The 18 basis functions of eqs. (39)/(40) at sample `i` of a planar run: `u, v, w` are
/// `(X, Y, Z)` less the pivot, over `R`; `D = +1` for CW.
pub fn basis(run: &Run, i: usize) -> [f64; 18] {
    let h = &run.header;
    let r = h.radius_mm;
    let pos = |a: Axis| run.axis(a).map(|c| (c[i] - h.pivot_mm[a.index()]) / r).unwrap_or(0.0);
    let sgn = |a: Axis| {
        run.axis(a).map(|c| crate::design::velocity_and_direction(&run.t_s, c, i).1).unwrap_or(0.0)
    };
    let (u, v, w) = (pos(Axis::X), pos(Axis::Y), pos(Axis::Z));
    let dd = h.direction.map(|d| d.paper_sign()).unwrap_or(0.0);
    [
        u * u,
        v * v,
        w * w,
        u * v * v,
        u * w * w,
        v * u * u,
        v * w * w,
        w * u * u,
        w * v * v,
        u * sgn(Axis::X),
        v * sgn(Axis::Y),
        w * sgn(Axis::Z),
        u * v,
        v * w,
        w * u,
        u * v * dd,
        v * w * dd,
        w * u * dd,
    ]
}

/// A reported quantity as a linear functional of the model's parameters: the value in the
/// quantity's display unit is `Σ factor · θ_id` (θ in internal units).
#[derive(Clone, Debug, PartialEq)]
pub struct Quantity {
    /// Row name as in the paper's table.
    pub name: String,
    /// Display unit.
    pub unit: &'static str,
    /// `(parameter id, factor)` pairs.
    pub terms: Vec<(String, f64)>,
}

/// A paper row with its vendor-comparable twin.
#[derive(Clone, Debug, PartialEq)]
pub struct PaperRow {
    /// The paper's quantity.
    pub paper: Quantity,
    /// The same error in the units vendor ballbar software reports.
    pub vendor: Quantity,
}

fn has(model: &Model, id: &str) -> bool {
    model.parameters().iter().any(|p| p.id == id)
}

/// The straightness pairs `(moving axis, error direction, sign of the tied angle, angle axis)`.
const STRAIGHTNESS: [(Axis, Axis, f64, Axis); 6] = [
    (Axis::X, Axis::Y, 1.0, Axis::Z),
    (Axis::X, Axis::Z, -1.0, Axis::Y),
    (Axis::Y, Axis::X, -1.0, Axis::Z),
    (Axis::Y, Axis::Z, 1.0, Axis::X),
    (Axis::Z, Axis::X, 1.0, Axis::Y),
    (Axis::Z, Axis::Y, -1.0, Axis::X),
];

/// The paper's 24 quantities (in its table's order) at report radius `radius_mm` and feed
/// `feed_mm_per_min`, for the terms the model has. Rows whose terms the model lacks are left out.
pub fn report(model: &Model, radius_mm: f64, feed_mm_per_min: f64) -> Vec<PaperRow> {
    let mut rows = Vec::new();
    let r = radius_mm;
    let len = |id: &str| model.polynomial_length(id);
    for a in Axis::LINEAR {
        let id = format!("E{a}{a}1");
        if let Some(l) = len(&id) {
            rows.push(PaperRow {
                paper: Quantity {
                    name: format!("{a} positional"),
                    unit: "µm",
                    terms: vec![(id.clone(), 1e3 * r / l)],
                },
                vendor: Quantity {
                    name: format!("{a} scale"),
                    unit: "ppm",
                    terms: vec![(id, 1e6 / l)],
                },
            });
        }
    }
    // Straightness rows in the paper's order: Y along X, Z along X, X along Y, Z along Y, X along Z, Y along Z.
    for (axis, toward, _, _) in STRAIGHTNESS {
        let id = format!("E{toward}{axis}2");
        if let Some(l) = len(&id) {
            let f = 1e3 * (r / l).powi(2);
            rows.push(PaperRow {
                paper: Quantity {
                    name: format!("{toward} straightness along {axis}"),
                    unit: "µm",
                    terms: vec![(id.clone(), f)],
                },
                vendor: Quantity {
                    name: format!("{toward} straightness along {axis} (bow over 2R)"),
                    unit: "µm",
                    terms: vec![(id, f)],
                },
            });
        }
    }
    for (axis, toward, sign, about) in STRAIGHTNESS {
        let id = format!("E{toward}{axis}2");
        if let Some(l) = len(&id) {
            // ε = sign · 2 θ R / L² rad, shown in µrad.
            let f = sign * 2.0 * r / (l * l);
            rows.push(PaperRow {
                paper: Quantity {
                    name: format!("{about} angular along {axis}"),
                    unit: "µrad",
                    terms: vec![(id.clone(), 1e6 * f)],
                },
                vendor: Quantity {
                    name: format!("{about} angular along {axis}"),
                    unit: "arcsec",
                    terms: vec![(id, 1e6 * f * 0.206_264_806)],
                },
            });
        }
    }
    for (id, name) in [("SQXY", "XY"), ("SQYZ", "YZ"), ("SQZX", "ZX")] {
        if has(model, id) {
            rows.push(PaperRow {
                paper: Quantity {
                    name: format!("squareness {name}"),
                    unit: "µrad",
                    terms: vec![(id.into(), 1e6)],
                },
                vendor: Quantity {
                    name: format!("squareness {name}"),
                    unit: "µm/m",
                    terms: vec![(id.into(), 1e6)],
                },
            });
        }
    }
    for a in Axis::LINEAR {
        let id = format!("B{a}");
        if has(model, &id) {
            rows.push(PaperRow {
                paper: Quantity {
                    name: format!("backlash {a}"),
                    unit: "µm",
                    terms: vec![(id.clone(), 1e3)],
                },
                vendor: Quantity {
                    name: format!("backlash {a}"),
                    unit: "µm",
                    terms: vec![(id, 1e3)],
                },
            });
        }
    }
    let v = feed_mm_per_min / 60.0;
    for plane in Plane::PLANAR {
        let (ua, va, _) = plane.axes().expect("planar");
        let name = format!("servo mismatch {plane}");
        match model.options.servo {
            ServoVariant::PlaneMismatch => {
                let id = format!("M{plane}");
                if has(model, &id) {
                    rows.push(PaperRow {
                        paper: Quantity {
                            name: name.clone(),
                            unit: "µm",
                            terms: vec![(id.clone(), 1e3)],
                        },
                        vendor: Quantity {
                            name: format!("{name} (lag difference)"),
                            unit: "ms",
                            terms: vec![(id, 1e3 / v)],
                        },
                    });
                }
            }
            ServoVariant::AxisLag => {
                let (tu, tv) = (format!("T{ua}"), format!("T{va}"));
                if has(model, &tu) && has(model, &tv) {
                    rows.push(PaperRow {
                        paper: Quantity {
                            name: name.clone(),
                            unit: "µm",
                            terms: vec![(tv.clone(), 1e3 * v), (tu.clone(), -1e3 * v)],
                        },
                        vendor: Quantity {
                            name: format!("{name} (lag {va} − {ua})"),
                            unit: "ms",
                            terms: vec![(tv, 1e3), (tu, -1e3)],
                        },
                    });
                }
            }
        }
    }
    rows
}

/// The paper's independent quantities, as its table gives them (the angular rows follow from
/// the straightness rows).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PaperValues {
    /// Radius the values refer to, mm.
    pub radius_mm: f64,
    /// Feed the values refer to, mm/min.
    pub feed_mm_per_min: f64,
    /// X, Y, Z positional, µm.
    pub positional_um: [f64; 3],
    /// Straightness, µm, in the order Y along X, Z along X, X along Y, Z along Y, X along Z,
    /// Y along Z.
    pub straightness_um: [f64; 6],
    /// Squareness XY, YZ, ZX, µrad.
    pub squareness_urad: [f64; 3],
    /// Backlash X, Y, Z, µm.
    pub backlash_um: [f64; 3],
    /// Servo mismatch XY, YZ, ZX, µm.
    pub servo_mismatch_um: [f64; 3],
}

/// Our parameter values (internal units) for a machine given in the paper's quantities. The
/// servo mismatch needs the paper's plane variant (per-axis lags cannot express three
/// independent values).
pub fn parameters_from_paper(
    model: &Model,
    p: &PaperValues,
) -> Result<Vec<(String, f64)>, crate::ModelError> {
    let missing = |id: &str| crate::ModelError::UnknownParameter { id: id.to_string() };
    let r = p.radius_mm;
    let mut out = Vec::new();
    for (k, a) in Axis::LINEAR.into_iter().enumerate() {
        let id = format!("E{a}{a}1");
        let l = model.polynomial_length(&id).ok_or_else(|| missing(&id))?;
        out.push((id, p.positional_um[k] * 1e-3 * l / r));
    }
    for (k, (axis, toward, _, _)) in STRAIGHTNESS.into_iter().enumerate() {
        let id = format!("E{toward}{axis}2");
        let l = model.polynomial_length(&id).ok_or_else(|| missing(&id))?;
        out.push((id, p.straightness_um[k] * 1e-3 * (l / r).powi(2)));
    }
    for (k, id) in ["SQXY", "SQYZ", "SQZX"].into_iter().enumerate() {
        out.push((id.to_string(), p.squareness_urad[k] * 1e-6));
    }
    for (k, a) in Axis::LINEAR.into_iter().enumerate() {
        out.push((format!("B{a}"), p.backlash_um[k] * 1e-3));
    }
    if model.options.servo != ServoVariant::PlaneMismatch {
        return Err(crate::ModelError::InvalidMachine {
            message: "the paper's servo mismatch values need the plane-mismatch servo variant"
                .into(),
        });
    }
    for (k, plane) in Plane::PLANAR.into_iter().enumerate() {
        out.push((format!("M{plane}"), p.servo_mismatch_um[k] * 1e-3));
    }
    let params = model.parameters();
    for (id, _) in &out {
        if !params.iter().any(|q| &q.id == id) {
            return Err(missing(id));
        }
    }
    Ok(out)
}
