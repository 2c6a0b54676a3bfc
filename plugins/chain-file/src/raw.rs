//! The chain file as written: serde types that mirror the text (stage one of two). Every check
//! that one value, or one joint and the joints before it, can decide is made here, while ron
//! deserializes, so that ron's error position points at the offending value: the schema
//! number, a name, a parent, an axis letter, a direction, a location-error name, a list of
//! degrees or harmonics. Checks that
//! need the whole file are in [`crate::validate`].

use std::fmt;

use ballbar_model::Axis;
use ballbar_model::chain::JointKind;
use serde::Deserialize;
use serde::de::{self, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};

/// The newest schema this plugin reads (it reads every one before it): 1, the joints and the
/// linear axes' errors with the rotary location errors; 2 adds the rotary axes' error motions
/// (`RotaryPositioning`, `RotaryRunout`, `RotaryWobble`, `Backlash` and `ServoLag` of a rotary
/// axis).
pub const SCHEMA: u32 = 2;

/// The name of the machine base, the parent of the first joint of each branch.
pub const BASE: &str = "base";

/// The whole file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, rename = "ChainFile")]
pub struct RawChainFile {
    /// Format version, [`SCHEMA`] (checked while deserializing, and first, by [`SchemaProbe`]).
    pub schema: Schema,
    /// Machine type name.
    #[serde(deserialize_with = "one_line")]
    pub name: String,
    /// Version of the description.
    #[serde(deserialize_with = "one_line")]
    pub version: String,
    /// One line for reports.
    #[serde(deserialize_with = "one_line")]
    pub description: String,
    /// The joints, each after its parent.
    pub joints: Joints,
    /// The joint that carries the spindle (end of the tool branch), or `base`.
    pub tool: String,
    /// The joint that carries the table (end of the workpiece branch), or `base`.
    pub workpiece: String,
    /// Normalisation of the linear axes' error polynomials.
    pub normalisation: Vec<RawNorm>,
    /// The errors to model.
    pub errors: Vec<RawError>,
}

/// The field names of [`RawChainFile`], in the order the docs give them.
pub const FIELDS: &[&str] = &[
    "schema",
    "name",
    "version",
    "description",
    "joints",
    "tool",
    "workpiece",
    "normalisation",
    "errors",
];

/// The schema number: at least 1, at most [`SCHEMA`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schema(pub u32);

impl<'de> Deserialize<'de> for Schema {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Schema, D::Error> {
        let n = u32::deserialize(d)?;
        if n == 0 {
            return Err(de::Error::custom(format!(
                "schema 0 does not exist: this plugin reads schema {SCHEMA}"
            )));
        }
        if n > SCHEMA {
            return Err(de::Error::custom(format!(
                "schema {n} is newer than this plugin reads (schema {SCHEMA}): use a newer chain-file plugin, or write the file in schema {SCHEMA}"
            )));
        }
        Ok(Schema(n))
    }
}

/// A non-empty string on one line (it goes into run-file headers and reports).
fn one_line<'de, D: Deserializer<'de>>(d: D) -> Result<String, D::Error> {
    let s = String::deserialize(d)?;
    check_one_line(&s).map_err(de::Error::custom)?;
    Ok(s)
}

fn check_one_line(s: &str) -> Result<(), &'static str> {
    if s.trim().is_empty() {
        return Err("must not be empty");
    }
    if s.contains(['\n', '\r']) {
        return Err("must be one line");
    }
    Ok(())
}

/// A linear direction (X, Y or Z): the error directions and the axes that are normalised.
fn linear_axis<'de, D: Deserializer<'de>>(d: D) -> Result<Axis, D::Error> {
    let a = Axis::deserialize(d)?;
    if a.is_rotary() {
        return Err(de::Error::custom(format!(
            "{a} is a rotary axis; a linear direction (X, Y or Z) is needed here"
        )));
    }
    Ok(a)
}

/// A rotary axis (A, B or C): the axis of a rotary error motion.
fn rotary_axis<'de, D: Deserializer<'de>>(d: D) -> Result<Axis, D::Error> {
    let a = Axis::deserialize(d)?;
    if !a.is_rotary() {
        return Err(de::Error::custom(format!(
            "{a} is a linear axis; a rotary axis (A, B or C) is needed here"
        )));
    }
    Ok(a)
}

/// Harmonic orders of a rotary error motion: a non-empty list, each from 1 to
/// [`MAX_HARMONIC`](ballbar_model::machine::MAX_HARMONIC), no repeats.
fn harmonics<'de, D: Deserializer<'de>>(d: D) -> Result<Vec<u32>, D::Error> {
    use ballbar_model::machine::MAX_HARMONIC;
    let v = Vec::<u32>::deserialize(d)?;
    if v.is_empty() {
        return Err(de::Error::custom("harmonics: give at least one harmonic"));
    }
    if v.contains(&0) {
        return Err(de::Error::custom(
            "harmonic 0: harmonics start at 1 (a constant error of a rotary axis is a location error, RotaryLocation, and the ball's set-up)",
        ));
    }
    if let Some(n) = v.iter().find(|&&n| n > MAX_HARMONIC) {
        return Err(de::Error::custom(format!(
            "harmonic {n}: at most {MAX_HARMONIC} (one wave per degree)"
        )));
    }
    if let Some((i, n)) = v.iter().enumerate().find(|(i, n)| v[..*i].contains(n)) {
        return Err(de::Error::custom(format!("harmonic {n} is listed twice (entry {})", i + 1)));
    }
    Ok(v)
}

/// Polynomial degrees: a non-empty list, each at least `MIN`, no repeats.
fn degrees<'de, D: Deserializer<'de>, const MIN: u32>(d: D) -> Result<Vec<u32>, D::Error> {
    let v = Vec::<u32>::deserialize(d)?;
    if v.is_empty() {
        return Err(de::Error::custom("degrees: give at least one degree"));
    }
    if let Some(p) = v.iter().find(|&&p| p < MIN) {
        let why =
            if MIN == 2 { " (the linear part of a straightness is a squareness)" } else { "" };
        return Err(de::Error::custom(format!("degree {p}: degrees start at {MIN} here{why}")));
    }
    if let Some((i, p)) = v.iter().enumerate().find(|(i, p)| v[..*i].contains(p)) {
        return Err(de::Error::custom(format!("degree {p} is listed twice (entry {})", i + 1)));
    }
    Ok(v)
}

/// A 3-vector of finite numbers.
fn finite3<'de, D: Deserializer<'de>>(d: D, what: &str) -> Result<[f64; 3], D::Error> {
    let v = <[f64; 3]>::deserialize(d)?;
    if v.iter().any(|x| !x.is_finite()) {
        return Err(de::Error::custom(format!(
            "{what} must be finite, found ({}, {}, {})",
            v[0], v[1], v[2]
        )));
    }
    Ok(v)
}

/// A joint's direction: finite and non-zero.
struct Direction([f64; 3]);

impl<'de> Deserialize<'de> for Direction {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Direction, D::Error> {
        let v = finite3(d, "direction")?;
        // Directions are unit-like numbers written by hand: anything this small is a zero.
        if v.iter().map(|x| x * x).sum::<f64>().sqrt() < 1e-12 {
            return Err(de::Error::custom(format!(
                "direction must be a non-zero vector, found ({}, {}, {})",
                v[0], v[1], v[2]
            )));
        }
        Ok(Direction(v))
    }
}

/// A joint's origin: finite.
struct Origin([f64; 3]);

impl<'de> Deserialize<'de> for Origin {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Origin, D::Error> {
        finite3(d, "origin_mm").map(Origin)
    }
}

/// A joint as written.
#[derive(Clone, Debug, PartialEq)]
pub struct RawJoint {
    /// Unique name.
    pub name: String,
    /// `base` or the name of a joint listed earlier.
    pub parent: String,
    /// Driving axis.
    pub axis: Axis,
    /// Linear or rotary.
    pub kind: JointKind,
    /// Direction of motion or rotation, in the parent frame.
    pub direction: [f64; 3],
    /// Origin in the parent frame at zero coordinate, mm.
    pub origin_mm: [f64; 3],
}

/// The joint list: each joint is checked against the ones before it.
#[derive(Debug)]
pub struct Joints(pub Vec<RawJoint>);

impl<'de> Deserialize<'de> for Joints {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Joints, D::Error> {
        d.deserialize_seq(JointsVisitor)
    }
}

struct JointsVisitor;

impl<'de> Visitor<'de> for JointsVisitor {
    type Value = Joints;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a list of joints")
    }

    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Joints, A::Error> {
        let mut joints: Vec<RawJoint> = Vec::new();
        while let Some(j) = seq.next_element_seed(JointSeed { earlier: &joints })? {
            joints.push(j);
        }
        Ok(Joints(joints))
    }
}

const JOINT_FIELDS: &[&str] = &["name", "parent", "axis", "kind", "direction", "origin_mm"];

#[derive(Deserialize)]
#[serde(field_identifier, rename_all = "snake_case")]
enum JointField {
    Name,
    Parent,
    Axis,
    Kind,
    Direction,
    OriginMm,
}

/// One joint, knowing the joints listed before it.
struct JointSeed<'a> {
    earlier: &'a [RawJoint],
}

impl JointSeed<'_> {
    fn known(&self) -> String {
        std::iter::once(BASE)
            .chain(self.earlier.iter().map(|j| j.name.as_str()))
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", ")
    }
}

impl<'de> DeserializeSeed<'de> for JointSeed<'_> {
    type Value = RawJoint;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<RawJoint, D::Error> {
        d.deserialize_struct("Joint", JOINT_FIELDS, self)
    }
}

/// The kind an axis letter drives.
fn kind_of(axis: Axis) -> JointKind {
    if axis.is_rotary() { JointKind::Rotary } else { JointKind::Linear }
}

impl<'de> Visitor<'de> for JointSeed<'_> {
    type Value = RawJoint;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a joint (name, parent, axis, kind, direction, origin_mm)")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<RawJoint, A::Error> {
        let (mut name, mut parent, mut axis, mut kind, mut direction, mut origin) =
            (None::<String>, None::<String>, None, None, None, None);
        let mismatch = |a: Axis, k: JointKind| {
            format!(
                "axis {a} is {} and drives a {:?} joint, not a {k:?} one",
                if a.is_rotary() { "rotary" } else { "linear" },
                kind_of(a)
            )
        };
        // Each check runs inside the value's own deserialization (a `Checked` seed), before ron
        // reads on, so that the error's position is the value's.
        while let Some(field) = map.next_key::<JointField>()? {
            match field {
                JointField::Name => {
                    if name.is_some() {
                        return Err(de::Error::duplicate_field("name"));
                    }
                    name = Some(map.next_value_seed(Checked::new(|n: &String| {
                        check_one_line(n).map_err(|m| format!("joint name {m}"))?;
                        if n == BASE {
                            return Err(
                                "'base' names the machine base; give the joint another name"
                                    .to_string(),
                            );
                        }
                        if let Some(k) = self.earlier.iter().position(|j| &j.name == n) {
                            return Err(format!(
                                "joint name '{n}' is already used by joint {} of the list",
                                k + 1
                            ));
                        }
                        if parent.as_ref() == Some(n) {
                            return Err(format!("joint '{n}' cannot be its own parent"));
                        }
                        Ok(())
                    }))?);
                }
                JointField::Parent => {
                    if parent.is_some() {
                        return Err(de::Error::duplicate_field("parent"));
                    }
                    parent = Some(map.next_value_seed(Checked::new(|p: &String| {
                        if name.as_ref() == Some(p) {
                            return Err(format!("joint '{p}' cannot be its own parent"));
                        }
                        if p != BASE && !self.earlier.iter().any(|j| &j.name == p) {
                            return Err(format!(
                                "parent '{p}' is not a joint listed before this one (list each joint after its parent; the parents so far: {})",
                                self.known()
                            ));
                        }
                        Ok(())
                    }))?);
                }
                JointField::Axis => {
                    if axis.is_some() {
                        return Err(de::Error::duplicate_field("axis"));
                    }
                    axis = Some(map.next_value_seed(Checked::new(|&a: &Axis| {
                        if let Some(j) = self.earlier.iter().find(|j| j.axis == a) {
                            return Err(format!(
                                "axis {a} already drives joint '{}': one joint per axis",
                                j.name
                            ));
                        }
                        match kind.filter(|&k| k != kind_of(a)) {
                            Some(k) => Err(mismatch(a, k)),
                            None => Ok(()),
                        }
                    }))?);
                }
                JointField::Kind => {
                    if kind.is_some() {
                        return Err(de::Error::duplicate_field("kind"));
                    }
                    kind = Some(map.next_value_seed(Checked::new(|&k: &JointKind| {
                        match axis.filter(|&a| k != kind_of(a)) {
                            Some(a) => Err(mismatch(a, k)),
                            None => Ok(()),
                        }
                    }))?);
                }
                JointField::Direction => {
                    if direction.is_some() {
                        return Err(de::Error::duplicate_field("direction"));
                    }
                    direction = Some(map.next_value::<Direction>()?.0);
                }
                JointField::OriginMm => {
                    if origin.is_some() {
                        return Err(de::Error::duplicate_field("origin_mm"));
                    }
                    origin = Some(map.next_value::<Origin>()?.0);
                }
            }
        }
        Ok(RawJoint {
            name: name.ok_or_else(|| de::Error::missing_field("name"))?,
            parent: parent.ok_or_else(|| de::Error::missing_field("parent"))?,
            axis: axis.ok_or_else(|| de::Error::missing_field("axis"))?,
            kind: kind.ok_or_else(|| de::Error::missing_field("kind"))?,
            direction: direction.ok_or_else(|| de::Error::missing_field("direction"))?,
            origin_mm: origin.ok_or_else(|| de::Error::missing_field("origin_mm"))?,
        })
    }
}

/// A value and a check of it, made inside the value's deserialization.
struct Checked<T, F> {
    check: F,
    value: std::marker::PhantomData<T>,
}

impl<T, F: FnOnce(&T) -> Result<(), String>> Checked<T, F> {
    fn new(check: F) -> Checked<T, F> {
        Checked { check, value: std::marker::PhantomData }
    }
}

impl<'de, T: Deserialize<'de>, F: FnOnce(&T) -> Result<(), String>> DeserializeSeed<'de>
    for Checked<T, F>
{
    type Value = T;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<T, D::Error> {
        let v = T::deserialize(d)?;
        (self.check)(&v).map_err(de::Error::custom)?;
        Ok(v)
    }
}

/// Normalisation of one linear axis.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename = "Normalisation")]
pub struct RawNorm {
    /// The axis.
    #[serde(deserialize_with = "linear_axis")]
    pub axis: Axis,
    /// Fixed machine reference position, mm.
    #[serde(deserialize_with = "finite")]
    pub reference_mm: f64,
    /// Fixed normalisation length, mm.
    #[serde(deserialize_with = "positive")]
    pub length_mm: f64,
}

fn finite<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let x = f64::deserialize(d)?;
    if !x.is_finite() {
        return Err(de::Error::custom(format!("must be a finite number, found {x}")));
    }
    Ok(x)
}

fn positive<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    let x = f64::deserialize(d)?;
    if !(x.is_finite() && x > 0.0) {
        return Err(de::Error::custom(format!("must be a positive finite length, found {x}")));
    }
    Ok(x)
}

fn some_id<'de, D: Deserializer<'de>>(d: D) -> Result<Option<String>, D::Error> {
    let s = String::deserialize(d)?;
    if s.is_empty() || !s.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        return Err(de::Error::custom(format!("id '{s}': use letters, digits and '_'")));
    }
    Ok(Some(s))
}

/// One entry of the error list.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(deny_unknown_fields, rename = "Error")]
pub enum RawError {
    /// The paper's set on X, Y and Z ([`ballbar_model::machine::paper_terms`]).
    Paper,
    /// Positional error `EXX<p>`.
    Positional {
        /// The axis.
        #[serde(deserialize_with = "linear_axis")]
        axis: Axis,
        /// Degrees ≥ 1.
        #[serde(deserialize_with = "degrees::<_, 1>")]
        degrees: Vec<u32>,
    },
    /// Straightness of `axis` toward `toward`, `E<toward><axis><p>`.
    Straightness {
        /// The moving axis.
        #[serde(deserialize_with = "linear_axis")]
        axis: Axis,
        /// The error direction.
        #[serde(deserialize_with = "linear_axis")]
        toward: Axis,
        /// Degrees ≥ 2.
        #[serde(deserialize_with = "degrees::<_, 2>")]
        degrees: Vec<u32>,
        /// Pitch and yaw tied to the straightness (rigid guideway).
        tie_angles: bool,
    },
    /// Angular error motion of a linear axis about X, Y or Z, `E<A|B|C><axis><p>`.
    Angular {
        /// The moving axis.
        #[serde(deserialize_with = "linear_axis")]
        axis: Axis,
        /// The direction the rotation is about.
        #[serde(deserialize_with = "linear_axis")]
        about: Axis,
        /// Degrees ≥ 1.
        #[serde(deserialize_with = "degrees::<_, 1>")]
        degrees: Vec<u32>,
    },
    /// Squareness: the error toward `toward` proportional to `axis`.
    Squareness {
        /// Identifier; by default `SQ` and the plane (`SQXY`, `SQYZ`, `SQZX`).
        #[serde(default, deserialize_with = "some_id")]
        id: Option<String>,
        /// The axis whose motion carries the error.
        #[serde(deserialize_with = "linear_axis")]
        axis: Axis,
        /// The error direction.
        #[serde(deserialize_with = "linear_axis")]
        toward: Axis,
    },
    /// Backlash `B<axis>`, of a linear or a rotary axis.
    Backlash {
        /// The axis.
        axis: Axis,
    },
    /// Servo lag `T<axis>`, of a linear or a rotary axis.
    ServoLag {
        /// The axis.
        axis: Axis,
    },
    /// ISO 230-7 location errors of rotary axes by name (`EX0C`).
    RotaryLocation(Vec<LocationName>),
    /// Angular positioning error motion of a rotary axis, `E<k><k>_S<n>`, `E<k><k>_C<n>`.
    RotaryPositioning {
        /// The rotary axis.
        #[serde(deserialize_with = "rotary_axis")]
        axis: Axis,
        /// Harmonic orders ≥ 1.
        #[serde(deserialize_with = "harmonics")]
        harmonics: Vec<u32>,
    },
    /// Radial or axial run-out of a rotary axis along X, Y or Z, `E<d><k>_S<n>`, `E<d><k>_C<n>`.
    RotaryRunout {
        /// The rotary axis.
        #[serde(deserialize_with = "rotary_axis")]
        axis: Axis,
        /// The direction of the displacement.
        #[serde(deserialize_with = "linear_axis")]
        direction: Axis,
        /// Harmonic orders ≥ 1.
        #[serde(deserialize_with = "harmonics")]
        harmonics: Vec<u32>,
    },
    /// Tilt error motion (wobble) of a rotary axis about a direction across its line, A, B or C
    /// (X, Y, Z read as them; not its own, checked in [`crate::validate`]), `E<r><k>_S<n>`.
    RotaryWobble {
        /// The rotary axis.
        #[serde(deserialize_with = "rotary_axis")]
        axis: Axis,
        /// The direction the tilt is about.
        about: Axis,
        /// Harmonic orders ≥ 1.
        #[serde(deserialize_with = "harmonics")]
        harmonics: Vec<u32>,
    },
}

/// An ISO 230-7 location error name `E<d>0<k>`: `k` the rotary axis, `d` the direction of the
/// offset (X, Y, Z) or the axis of the tilt or zero error (A, B, C).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LocationName {
    /// `d`.
    pub component: Axis,
    /// `k`.
    pub axis: Axis,
}

impl LocationName {
    /// The linear direction along a rotary axis's own line (A: X, B: Y, C: Z).
    pub fn own_line(axis: Axis) -> Axis {
        match axis {
            Axis::A => Axis::X,
            Axis::B => Axis::Y,
            _ => Axis::Z,
        }
    }

    /// The five names of a rotary axis.
    pub fn all_of(axis: Axis) -> Vec<String> {
        Axis::ALL
            .iter()
            .filter(|&&d| d != LocationName::own_line(axis))
            .map(|d| format!("E{d}0{axis}"))
            .collect()
    }
}

impl fmt::Display for LocationName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "E{}0{}", self.component, self.axis)
    }
}

impl<'de> Deserialize<'de> for LocationName {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<LocationName, D::Error> {
        let s = String::deserialize(d)?;
        let help = "ISO 230-7 names E<d>0<k>: k the rotary axis (A, B, C), d an offset (X, Y, Z) or a tilt or zero error (A, B, C), e.g. EX0C, EY0C, EA0C, EB0C, EC0C";
        let c: Vec<char> = s.chars().collect();
        let parsed = match c.as_slice() {
            ['E', d, '0', k] => {
                Axis::from_name(&d.to_string()).zip(Axis::from_name(&k.to_string()))
            }
            _ => None,
        };
        let Some((component, axis)) = parsed else {
            return Err(de::Error::custom(format!("unknown location error '{s}': {help}")));
        };
        if !axis.is_rotary() {
            return Err(de::Error::custom(format!(
                "'{s}': {axis} is a linear axis; location errors belong to rotary axes ({help})"
            )));
        }
        if component == LocationName::own_line(axis) {
            return Err(de::Error::custom(format!(
                "'{s}': an offset along the {axis} axis's own line is not a location error (ISO 230-7); the {axis} axis has {}",
                LocationName::all_of(axis).join(", ")
            )));
        }
        Ok(LocationName { component, axis })
    }
}

/// Reads only `schema`, ignoring every other field: run before the full parse, so that a file of
/// a newer schema says so whatever else in it is new.
pub struct SchemaProbe;

impl<'de> DeserializeSeed<'de> for SchemaProbe {
    type Value = Option<Schema>;

    fn deserialize<D: Deserializer<'de>>(self, d: D) -> Result<Option<Schema>, D::Error> {
        d.deserialize_struct("ChainFile", FIELDS, self)
    }
}

impl<'de> Visitor<'de> for SchemaProbe {
    type Value = Option<Schema>;

    fn expecting(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("a chain file: ( schema: 1, name: ..., ... )")
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Option<Schema>, A::Error> {
        let mut schema = None;
        while let Some(key) = map.next_key::<String>()? {
            if key == "schema" && schema.is_none() {
                schema = Some(map.next_value::<Schema>()?);
            } else {
                map.next_value::<de::IgnoredAny>()?;
            }
        }
        Ok(schema)
    }
}
