//! Machine axes, test planes and contouring directions.

use serde::{Deserialize, Serialize};

/// A machine axis, named as ISO 841 does. Linear axes move in mm, rotary axes in degrees at the
/// edges (radians inside).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Axis {
    /// Linear X.
    X,
    /// Linear Y.
    Y,
    /// Linear Z.
    Z,
    /// Rotary about X.
    A,
    /// Rotary about Y.
    B,
    /// Rotary about Z.
    C,
}

impl Axis {
    /// All axes in column order.
    pub const ALL: [Axis; 6] = [Axis::X, Axis::Y, Axis::Z, Axis::A, Axis::B, Axis::C];
    /// The three linear axes.
    pub const LINEAR: [Axis; 3] = [Axis::X, Axis::Y, Axis::Z];

    /// Index 0..6 in [`Axis::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// True for A, B and C.
    pub fn is_rotary(self) -> bool {
        matches!(self, Axis::A | Axis::B | Axis::C)
    }

    /// One-letter name.
    pub fn name(self) -> &'static str {
        ["X", "Y", "Z", "A", "B", "C"][self.index()]
    }

    /// The run-CSV column name with its unit (`X_mm`, `C_deg`).
    pub fn column_name(self) -> &'static str {
        ["X_mm", "Y_mm", "Z_mm", "A_deg", "B_deg", "C_deg"][self.index()]
    }

    /// Parse a one-letter name.
    pub fn from_name(s: &str) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.name() == s)
    }

    /// Parse a run-CSV column name.
    pub fn from_column_name(s: &str) -> Option<Axis> {
        Axis::ALL.into_iter().find(|a| a.column_name() == s)
    }

    /// The unit vector of a linear axis (or of the line a rotary axis turns about, by ISO 841).
    pub fn unit_vector(self) -> [f64; 3] {
        match self {
            Axis::X | Axis::A => [1.0, 0.0, 0.0],
            Axis::Y | Axis::B => [0.0, 1.0, 0.0],
            Axis::Z | Axis::C => [0.0, 0.0, 1.0],
        }
    }
}

impl std::fmt::Display for Axis {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The plane of a ballbar test.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Plane {
    /// X-Y plane, seen from +Z; angle from +X towards +Y.
    XY,
    /// Y-Z plane, seen from +X; angle from +Y towards +Z.
    YZ,
    /// Z-X plane, seen from +Y; angle from +Z towards +X.
    ZX,
    /// A path given by the axis columns alone (five-axis tests).
    Free,
}

impl Plane {
    /// The in-plane axes `(U, V)` and the normal `W`, so that `U × V = W`. `None` for `Free`.
    pub fn axes(self) -> Option<(Axis, Axis, Axis)> {
        match self {
            Plane::XY => Some((Axis::X, Axis::Y, Axis::Z)),
            Plane::YZ => Some((Axis::Y, Axis::Z, Axis::X)),
            Plane::ZX => Some((Axis::Z, Axis::X, Axis::Y)),
            Plane::Free => None,
        }
    }

    /// The name used in run files (`XY`, `YZ`, `ZX`, `free`).
    pub fn name(self) -> &'static str {
        match self {
            Plane::XY => "XY",
            Plane::YZ => "YZ",
            Plane::ZX => "ZX",
            Plane::Free => "free",
        }
    }

    /// Parse the run-file name.
    pub fn from_name(s: &str) -> Option<Plane> {
        match s {
            "XY" => Some(Plane::XY),
            "YZ" => Some(Plane::YZ),
            "ZX" => Some(Plane::ZX),
            "free" => Some(Plane::Free),
            _ => None,
        }
    }

    /// The three planar test planes.
    pub const PLANAR: [Plane; 3] = [Plane::XY, Plane::YZ, Plane::ZX];
}

impl std::fmt::Display for Plane {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Contouring direction, seen from the positive normal axis of the plane.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Direction {
    /// Clockwise: decreasing angle. The paper's `D = +1`.
    CW,
    /// Counter-clockwise: increasing angle. The paper's `D = -1`.
    CCW,
}

impl Direction {
    /// The paper's direction sign `D`: +1 for CW, -1 for CCW.
    pub fn paper_sign(self) -> f64 {
        match self {
            Direction::CW => 1.0,
            Direction::CCW => -1.0,
        }
    }

    /// The sign of dθ/dt: +1 for CCW, -1 for CW.
    pub fn angular_sign(self) -> f64 {
        -self.paper_sign()
    }

    /// The name used in run files.
    pub fn name(self) -> &'static str {
        match self {
            Direction::CW => "CW",
            Direction::CCW => "CCW",
        }
    }

    /// Parse the run-file name.
    pub fn from_name(s: &str) -> Option<Direction> {
        match s {
            "CW" => Some(Direction::CW),
            "CCW" => Some(Direction::CCW),
            _ => None,
        }
    }

    /// The other direction.
    pub fn reversed(self) -> Direction {
        match self {
            Direction::CW => Direction::CCW,
            Direction::CCW => Direction::CW,
        }
    }
}

impl std::fmt::Display for Direction {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}
